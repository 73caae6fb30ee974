//! Activation nodes filled from the variant catalogue (params/variants.toml).

use super::err;
use super::schema::{HmFile, Implementation, NodeSpec};
use crate::spec::SpecError;
use std::path::Path;

/// Fill the implementations of every activation node that names a `variant` (`app/version`)
/// from the variant catalogue (params/variants.toml): tiles, CPU share per fps on `cpu_cores`
/// cores, highest rate. A node naming a variant must not list implementations of its own.
pub fn fill_from_catalogue(
    file: &Path,
    spec: &mut HmFile,
    catalogue: &fpga_model::Catalogue,
    cpu_cores: u8,
) -> Result<(), SpecError> {
    for (n, node) in spec.node.iter_mut() {
        let (variant, implementations) = match node {
            NodeSpec::Activation(a) => {
                if a.variant.is_some() && !a.implementations.is_empty() {
                    return Err(err(
                        file,
                        format!("node.{n}.implementations"),
                        "a node naming a `variant` takes its implementations from params/variants.toml",
                    ));
                }
                (&a.variant, &mut a.implementations)
            }
            NodeSpec::Fit(f) => (&f.variant, &mut f.implementations),
            _ => continue,
        };
        let Some(v) = variant else { continue };
        let entry = format!("node.{n}.variant");
        let Some((app, version)) = v.split_once('/') else {
            return Err(err(file, entry, format!("`{v}` is not `app/version`")));
        };
        let impls = catalogue.implementations(app, version);
        if impls.is_empty() {
            return Err(err(
                file,
                entry,
                format!("no variant {app} {version} in params/variants.toml"),
            ));
        }
        *implementations = impls
            .iter()
            .map(|x| Implementation {
                name: x.implementation.to_string(),
                tiles: u32::from(x.tiles),
                cpu: String::new(),
                fast: false,
                cpu_per_fps: Some(x.cpu_share_at(1.0, cpu_cores)),
                max_fps: Some(x.max_fps()),
            })
            .collect();
    }
    Ok(())
}
