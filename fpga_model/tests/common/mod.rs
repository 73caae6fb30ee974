//! The project's params files, parsed with toml (the companion's loader is tested in companion).
#![allow(dead_code)]

use fpga_model::*;
use std::sync::OnceLock;

pub(crate) struct Params {
    pub platform: Platform,
    pub catalogue: Catalogue,
    pub safety: ResourcePolicy,
    pub mission: ResourcePolicy,
}

/// Parsed once per test binary.
pub(crate) fn params() -> &'static Params {
    static P: OnceLock<Params> = OnceLock::new();
    P.get_or_init(load)
}

fn load() -> Params {
    let platform: Platform = toml::from_str(include_str!("../../../params/platform.toml")).unwrap();
    platform.validate().unwrap();
    let file: VariantsFile = toml::from_str(include_str!("../../../params/variants.toml")).unwrap();
    let catalogue = Catalogue::new(file.variant, &platform).unwrap();
    let mut policies: PoliciesFile =
        toml::from_str(include_str!("../../../params/resource_policies.toml")).unwrap();
    for (name, p) in policies.iter_mut() {
        p.name = name.clone();
        // The shipped policies carry no degradation paths (the companion's decision core lets
        // the tracking MDP choose again). The scheduler still supports them; these tests exercise
        // that mechanism with the paths the paper's Tables 4 and 6 show.
        assert!(
            p.degrade.is_empty(),
            "params/resource_policies.toml has degrade paths"
        );
        p.degrade.insert(
            "tracking".into(),
            [
                ("V3".to_string(), vec!["V1".to_string()]),
                ("V2".to_string(), vec!["V5".to_string()]),
            ]
            .into_iter()
            .collect(),
        );
        p.validate(name, &catalogue).unwrap();
    }
    Params {
        safety: policies["safety"].clone(),
        mission: policies["mission"].clone(),
        platform,
        catalogue,
    }
}

pub(crate) fn placed<'a>(s: &'a Schedule, app: &str) -> Option<&'a Placement> {
    s.placements.iter().find(|p| p.app == app)
}
pub(crate) mod reference;
