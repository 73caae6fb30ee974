//! `companion check`'s platform, variants and resource-policies sections.

use crate::resources::ResourceSpec;
use crate::spec::{ParamsFiles, SpecError};
use fpga_model::Platform;
use serde_json::{Value, json};

fn platform_json(p: &Platform) -> Value {
    json!({
        "board": p.board,
        "device": p.device,
        "tiles": p.tiles,
        "cpu": {
            "cores": p.cpu_cores,
            "mhz": p.cpu_mhz,
            "budget": p.cpu_budget,
            "thresholds": p.cpu_thresholds,
        },
        "reconfiguration_ms_per_tile": p.reconfiguration_ms_per_tile,
        "power": p.power,
        "performance": p.performance,
    })
}

fn variants_json(spec: &ResourceSpec) -> Value {
    let cores = spec.platform.cpu_cores;
    Value::Array(
        spec.catalogue
            .variants()
            .iter()
            .map(|v| {
                json!({
                    "app": v.app,
                    "version": v.version,
                    "description": v.description,
                    "implementation": v.implementation,
                    "support": v.support,
                    "ms_per_frame": v.ms_per_frame(),
                    "ms": v.ms,
                    "sw_ms": v.sw_ms(),
                    "hw_ms": v.hw_ms(),
                    "max_fps": v.max_fps(),
                    "tiles": v.tiles,
                    "cpu_share": v.full_duty_cpu_share(cores),
                    "u_app": v.u_app(cores),
                    "source": v.source,
                    "note": v.note,
                })
            })
            .collect(),
    )
}

/// `companion check --json` part: `{"platform": {...}, "variants": [...], "resource_policies": {...}}`.
/// A variant's `cpu_share` is its back-to-back share of the nominal CPU, `u_app` = tiles + that.
pub fn check_json_of(spec: &ResourceSpec) -> Value {
    let policies: serde_json::Map<String, Value> = spec
        .policies
        .iter()
        .map(|(name, p)| {
            (
                name.clone(),
                json!({"priority": p.priority, "degrade": p.degrade}),
            )
        })
        .collect();
    json!({
        "platform": platform_json(&spec.platform),
        "variants": variants_json(spec),
        "resource_policies": policies,
    })
}

/// Load `params_dir` and return the check JSON.
pub fn check_json(params: &ParamsFiles) -> Result<Value, SpecError> {
    Ok(check_json_of(&ResourceSpec::load(params)?))
}

/// `companion check` human part: the platform line and the Table 2 catalogue as a table.
pub fn check_text(spec: &ResourceSpec) -> String {
    use std::fmt::Write;
    let p = &spec.platform;
    let mut out = String::new();
    let pct = |x: f64| format!("{:.0} %", x * 100.0);
    let _ = writeln!(
        out,
        "Platform: {} ({}): {} tiles, {} x Cortex-A9 @ {} MHz, CPU budget {}, CPU thresholds {}, reconfiguration {} ms/tile",
        p.board,
        p.device,
        p.tiles,
        p.cpu_cores,
        p.cpu_mhz,
        pct(p.cpu_budget),
        p.cpu_thresholds
            .iter()
            .map(|&t| pct(t))
            .collect::<Vec<_>>()
            .join(" / "),
        fpga_model::fmt_ms(p.reconfiguration_ms_per_tile),
    );
    let _ = writeln!(
        out,
        "{:<20} {:<14} {:<4} {:<7} {:>12} {:>5} {:>6} {:>6}",
        "app", "version", "impl", "support", "ms/frame", "tiles", "cpu", "U_App"
    );
    for v in spec.catalogue.variants() {
        let _ = writeln!(
            out,
            "{:<20} {:<14} {:<4} {:<7} {:>12} {:>5} {:>6.3} {:>6.3}",
            v.app,
            v.version,
            v.implementation.to_string(),
            v.support.to_string(),
            v.ms_label(),
            v.tiles,
            v.full_duty_cpu_share(p.cpu_cores),
            v.u_app(p.cpu_cores),
        );
    }
    let mut names: Vec<&str> = spec.policies.keys().map(String::as_str).collect();
    names.sort_unstable();
    for name in names {
        let pol = &spec.policies[name];
        let _ = writeln!(
            out,
            "Resource policy {name}: {} (gives way last to first)",
            pol.priority.join(" > ")
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    fn real() -> ResourceSpec {
        ResourceSpec::load(&crate::shipped::params()).expect("shipped params load")
    }

    #[test]
    fn check_json_lists_platform_and_every_variant() {
        let v = check_json(&crate::shipped::params()).unwrap();
        assert_eq!(v["platform"]["tiles"], 4);
        assert_eq!(v["platform"]["cpu"]["cores"], 2);
        assert_eq!(v["platform"]["cpu"]["mhz"], 925.0);
        let variants = v["variants"].as_array().unwrap();
        assert_eq!(variants.len(), 27);
        let v3m = variants
            .iter()
            .find(|x| x["app"] == "tracking" && x["version"] == "V3" && x["implementation"] == "M")
            .unwrap();
        assert_eq!(v3m["support"], "SW-HW");
        assert_eq!(v3m["ms_per_frame"], 295.0);
        assert_eq!(v3m["tiles"], 1);
        assert!((v3m["u_app"].as_f64().unwrap() - (1.0 + 285.0 / 295.0 / 2.0)).abs() < 1e-12);
        for x in variants {
            for key in [
                "app",
                "version",
                "implementation",
                "support",
                "ms_per_frame",
                "tiles",
                "cpu_share",
                "u_app",
            ] {
                assert!(!x[key].is_null(), "{key} missing in {x}");
            }
        }
        let text = check_text(&real());
        assert_eq!(
            text.lines().filter(|l| l.starts_with("tracking ")).count(),
            18
        );
        assert!(text.contains("10 + 1"), "{text}");
    }
}
