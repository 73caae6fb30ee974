//! How the fitted numbers in params/health were found (docs/params/health.md): solves for the
//! paper's worked examples and prints the values, then the versions under a few hazards.
//! Run from the workspace root: `cargo run -p companion-testkit --example fit_health`.
use companion_core::evidence::ObservationMap;
use companion_core::fmea::{CptSpec, HmFile, NodeSpec, NoisyOrNode, compile_hm};
use companion_core::health::HealthModel;
use companion_core::observations::Observations;
use std::collections::BTreeMap;
use std::path::Path;

fn params() -> companion_core::spec::ParamsFiles {
    companion::params::read_params_dir(Path::new("params")).unwrap()
}
/// A health manager file as `HealthModel::load` reads it: activation nodes naming a `variant`
/// take their implementations from params/variants.toml.
fn load(name: &str) -> HmFile {
    let files = params();
    let p = Path::new("params/health").join(format!("{name}.toml"));
    let mut spec = companion_core::fmea::read_hm(&files, &p).unwrap();
    let platform = companion_core::resources::load_platform(
        &files,
        &Path::new("params").join(companion_core::resources::PLATFORM_FILE),
    )
    .unwrap();
    let catalogue = companion_core::resources::load_variants(
        &files,
        &Path::new("params").join(companion_core::resources::VARIANTS_FILE),
        &platform,
    )
    .unwrap();
    companion_core::fmea::fill_from_catalogue(&p, &mut spec, &catalogue, platform.cpu_cores)
        .unwrap();
    spec
}
/// The noisy-OR settings of an error node.
fn noisy_or<'a>(f: &'a mut HmFile, node: &str) -> &'a mut NoisyOrNode {
    match f.node.get_mut(node) {
        Some(NodeSpec::Error(e)) => e,
        _ => panic!("{node} is not an error node"),
    }
}
fn model(files: &BTreeMap<&str, HmFile>) -> HealthModel {
    let hms = files
        .iter()
        .map(|(n, f)| compile_hm(Path::new(n), f).unwrap())
        .collect();
    HealthModel::from_parts(
        hms,
        ObservationMap::load(&params(), Path::new("params/observations.toml")).unwrap(),
    )
    .unwrap()
}
fn post(m: &mut HealthModel, ev: &[(&str, &str)], hm: &str, node: &str, s: usize) -> f64 {
    let ev: BTreeMap<String, String> = ev
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    m.reset();
    m.evaluate(&ev).unwrap();
    m.manager(hm).unwrap().marginal(node).unwrap()[s]
}
fn reference() -> Observations {
    let mut o = Observations::default();
    for (k, v) in [
        ("vibration_mps2", 6.0),
        ("wind_mps", 3.0),
        ("battery_pct", 45.0),
        ("gps_fix", 3.0),
        ("gps_sats", 10.0),
        ("luminosity_lux", 400.0),
        ("target_speed_rel", 0.5),
        ("drone_speed_mps", 3.0),
        ("cpu_load", 0.2),
        ("free_tiles", 4.0),
        ("temperature_c", 20.0),
        ("waypoints_remaining", 3.0),
    ] {
        o.set(k, v);
    }
    o
}

fn main() {
    let mut files: BTreeMap<&str, HmFile> = ["applications", "sensors", "system", "resources"]
        .iter()
        .map(|n| (*n, load(n)))
        .collect();
    // (a)+(b): params h1, sv (wind->vib), sm (ts->motion). Newton with numeric Jacobian.
    let mut x = [0.01f64, 0.93, 0.96];
    let f = |x: &[f64; 3], files: &mut BTreeMap<&str, HmFile>| -> [f64; 3] {
        let a = files.get_mut("applications").unwrap();
        let Some(NodeSpec::Qos(qos)) = a.node.get_mut("QoS") else {
            panic!("QoS is not a qos node")
        };
        qos.by_uncorrected = Some(vec![
            vec![0.90, 0.08, 0.02],
            vec![x[0], 0.5 - x[0], 0.5],
            vec![0.0, 0.2, 0.8],
        ]);
        noisy_or(a, "U_vibration")
            .strength
            .insert("A_wind".into(), vec![0.0, x[1]]);
        noisy_or(a, "U_motion_lost")
            .strength
            .insert("A_target_speed".into(), vec![0.0, x[2]]);
        let mut m = model(files);
        let fa = post(&mut m, &[("A_luminosity", "low")], "applications", "QoS", 0);
        let ev = [
            ("A_wind", "strong"),
            ("A_target_speed", "high"),
            ("QoS", "high"),
        ];
        let fs = post(&mut m, &ev, "applications", "C_stabilization", 1);
        let fr = post(&mut m, &ev, "applications", "C_roi_resize", 1);
        [fa - 0.10, fs - 0.60, fr - 0.72]
    };
    for _ in 0..14 {
        let y = f(&x, &mut files);
        let mut j = [[0.0; 3]; 3];
        for c in 0..3 {
            let mut x2 = x;
            x2[c] += 1e-5;
            let y2 = f(&x2, &mut files);
            for r in 0..3 {
                j[r][c] = (y2[r] - y[r]) / 1e-5;
            }
        }
        // Solve j d = -y (Cramer).
        let det = |m: [[f64; 3]; 3]| {
            m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
        };
        let d0 = det(j);
        for c in 0..3 {
            let mut m = j;
            for r in 0..3 {
                m[r][c] = -y[r];
            }
            x[c] = (x[c] + 0.7 * det(m) / d0).clamp(0.0, 0.9999);
        }
        println!("x = {x:?} residual {y:?}");
    }
    f(&x, &mut files);
    // (c) version rows: linear in the overridden row value.
    let m = model(&files);
    let ev = m.evidence(&reference());
    println!("reference evidence {ev:?}");
    let targets = [
        ("C_V1", 0.37),
        ("C_V2", 0.05),
        ("C_V3", 0.96),
        ("C_V4", 0.31),
        ("C_V5", 0.47),
    ];
    for (v, t) in targets {
        let val = |r: f64, files: &mut BTreeMap<&str, HmFile>| {
            let a = files.get_mut("applications").unwrap();
            a.node.get_mut(v).unwrap().common_mut().overrides[0].p = vec![1.0 - r, r];
            let mut m = model(files);
            let e: Vec<(&str, &str)> = ev.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect();
            post(&mut m, &e, "applications", v, 1)
        };
        let (p0, p1) = (val(0.0, &mut files), val(1.0, &mut files));
        let r = ((t - p0) / (p1 - p0)).clamp(0.0, 1.0);
        val(r, &mut files);
        println!("{v}: p0 {p0:.4} p1 {p1:.4} -> r = {r:.4}");
    }
    // Scalars by bisection on the reference.
    let bis = |name: &str,
               files: &mut BTreeMap<&str, HmFile>,
               set: &dyn Fn(&mut BTreeMap<&str, HmFile>, f64),
               target: f64,
               lo: f64,
               hi: f64| {
        let (mut lo, mut hi) = (lo, hi);
        let g = |x: f64, files: &mut BTreeMap<&str, HmFile>| {
            set(files, x);
            let mut m = model(files);
            m.evaluate(&ev).unwrap()[name] - target
        };
        let glo = g(lo, files);
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            if (g(mid, files) > 0.0) == (glo > 0.0) {
                lo = mid
            } else {
                hi = mid
            }
        }
        set(files, 0.5 * (lo + hi));
        println!("{name}: {:.4}", 0.5 * (lo + hi));
    };
    bis(
        "P_obs",
        &mut files,
        &|f, x| {
            noisy_or(f.get_mut("applications").unwrap(), "U_obstacle_missed")
                .strength
                .insert("A_vibration".into(), vec![0.0, x]);
        },
        0.5,
        0.0,
        0.9,
    );
    bis(
        "P_SI",
        &mut files,
        &|f, x| {
            f.get_mut("sensors")
                .unwrap()
                .node
                .get_mut("N_next")
                .unwrap()
                .common_mut()
                .cpt = Some(CptSpec::Rows(vec![
                vec![0.1, 0.9],
                vec![0.5, 0.5],
                vec![x, 1.0 - x],
                vec![0.5, 0.5],
                vec![0.9, 0.1],
                vec![0.5, 0.5],
            ]));
        },
        0.6,
        0.3,
        0.9,
    );
    bis(
        "P_battery",
        &mut files,
        &|f, x| {
            let Some(NodeSpec::State(e)) = f.get_mut("system").unwrap().node.get_mut("E_t1") else {
                panic!("E_t1 is not a state node")
            };
            e.stay = Some(x);
        },
        0.8,
        0.5,
        1.0,
    );
    bis(
        "P_sys",
        &mut files,
        &|f, x| {
            noisy_or(f.get_mut("system").unwrap(), "U_system_fault")
                .strength
                .insert("A_vibration".into(), vec![0.0, x]);
        },
        0.9,
        0.0,
        0.5,
    );
    let mut m = model(&files);
    println!("reference: {:?}", m.evaluate(&ev).unwrap());
    // Hazards past the thresholds of params/observations.toml (vibration 15 m/s^2, relative
    // target speed 5 m/s, wind 8 m/s, luminosity 50 lx) from the reference observations.
    for (name, obs) in [
        ("nominal", vec![]),
        ("vibration", vec![("vibration_mps2", 25.0)]),
        ("high speed", vec![("target_speed_rel", 8.0)]),
        (
            "wind+speed",
            vec![("target_speed_rel", 8.0), ("wind_mps", 12.0)],
        ),
        ("no resources", vec![("free_tiles", 0.0), ("cpu_load", 0.9)]),
        ("dark", vec![("luminosity_lux", 10.0)]),
    ] {
        let mut o = reference();
        for (k, v) in obs {
            o.set(k, v);
        }
        m.reset();
        let r = m.evaluate(&m.evidence(&o)).unwrap();
        let pv: Vec<String> = (0..6)
            .map(|i| format!("V{i} {:.3}", r[&format!("P_V{i}")]))
            .collect();
        println!("{name:>12}: {}  track {:.3}", pv.join(" "), r["P_track"]);
    }
}
