//! The shipped numbers calibration starts from and reports against: the mission's power model
//! and activities, the countable BN rows, the mission states.

use super::cpt::ShippedRows;
use super::power_fit::PowerModel;
use companion_core::guarantee::Guarantee;
use companion_core::mission::MissionStates;
use companion_core::spec::SpecError;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml::{Table, Value};

pub struct Shipped {
    /// The params directory (an overlay's base when `--params` named an overlay).
    pub dir: PathBuf,
    /// The mission file, relative to `dir` (the overlay's table name).
    pub mission_file: String,
    pub power: PowerModel,
    /// Per activity: the duration estimate (s) of the IA these params plan it with (the
    /// pre-flight allocation's), and that IA's name.
    pub estimate_s: BTreeMap<String, (f64, String)>,
    pub rows: ShippedRows,
    pub states: MissionStates,
    /// The mission's `[power_bounds]` and the fastest it flies (m/s): what a fit is judged by.
    pub bounds: Option<companion_core::guarantee::power_bounds::PowerBounds>,
    pub fastest_mps: f64,
    /// The mission's `[derive] cruise_speed_mps` (the commanded speed of legs whose run does not
    /// say it), when it has a `[derive]`.
    pub cruise_mps: Option<f64>,
    /// The params files read (inputs an output may not replace).
    pub inputs: Vec<PathBuf>,
}

impl Shipped {
    pub fn load(params: &Path) -> Result<Self, SpecError> {
        let loaded = crate::params::Params::load(params, None)?;
        let files = &loaded.files;
        let dir = files.dir().to_path_buf();
        let spec = &loaded.model.guarantee;
        let path = &spec.file;
        let t: Table = files
            .text(path)?
            .parse()
            .map_err(|e| SpecError::new(path, "-", format!("not TOML: {e}")))?;
        let power = power_model(path, &t)?;
        let dur = spec
            .problem
            .goals
            .iter()
            .position(|g| g.name == "duration_s");
        // The IA each activity is planned with: the pre-flight allocation of these params (the
        // lifted one when their goals cannot be met, as `fly` starts), else the fastest IA.
        let allocation = Guarantee::start_or_unbounded(spec.clone()).map(|g| g.choice().to_vec());
        let estimate_s = spec
            .problem
            .activities
            .iter()
            .enumerate()
            .filter_map(|(j, a)| {
                let d = dur?;
                let planned = allocation
                    .as_ref()
                    .and_then(|c| a.ias.get(c[j]))
                    .and_then(|ia| Some((ia.cost.get(d).copied()?, ia.name.clone())));
                let fastest = || {
                    a.ias
                        .iter()
                        .filter_map(|ia| Some((ia.cost.get(d).copied()?, ia.name.clone())))
                        .reduce(|x, y| if y.0 < x.0 { y } else { x })
                };
                Some((a.name.clone(), planned.or_else(fastest)?))
            })
            .collect();
        let mission_file = path
            .strip_prefix(&dir)
            .unwrap_or(path)
            .to_string_lossy()
            .replace('\\', "/");
        let cruise_mps = companion_core::guarantee::derive_settings(files, &path.to_string_lossy())
            .ok()
            .map(|d| d.cruise_speed_mps);
        Ok(Shipped {
            cruise_mps,
            bounds: spec.power_bounds,
            fastest_mps: spec.fastest_mps,
            inputs: files.iter().map(|(p, _)| p.to_path_buf()).collect(),
            rows: ShippedRows::load(files)?,
            states: MissionStates::load(files)?,
            dir,
            mission_file,
            power,
            estimate_s,
        })
    }
}

fn number(v: &Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
}

/// The mission's `[propulsion]` (rotary_wing) and `[base]`.
fn power_model(path: &Path, t: &Table) -> Result<PowerModel, SpecError> {
    let p = t.get("propulsion").and_then(Value::as_table);
    let model = p.and_then(|p| p.get("model")).and_then(Value::as_str);
    if model != Some("rotary_wing") {
        return Err(SpecError::new(
            path,
            "propulsion.model",
            format!(
                "calibrate fits the rotary_wing model; this mission's is {}",
                model.unwrap_or("missing")
            ),
        ));
    }
    let get = |k: &str| -> Result<f64, SpecError> {
        p.and_then(|p| p.get(k))
            .and_then(number)
            .ok_or_else(|| SpecError::new(path, format!("propulsion.{k}"), "missing number"))
    };
    Ok(PowerModel {
        base_w: t
            .get("base")
            .and_then(|b| b.get("power_w"))
            .and_then(number)
            .unwrap_or(0.0),
        blade_profile_w: get("blade_profile_w")?,
        induced_hover_w: get("induced_hover_w")?,
        induced_velocity_mps: get("induced_velocity_mps")?,
        tip_speed_mps: get("tip_speed_mps")?,
        drag_area_m2: get("drag_area_m2")?,
        air_density_kgm3: get("air_density_kgm3")?,
    })
}
