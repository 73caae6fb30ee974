//! The default CPT rules, checked against hand computation on small FMEA files.

use companion_core::fmea::{compile_hm, read_hm};
use companion_core::spec::ParamsFiles;
use std::path::Path;

fn compile(text: &str) -> companion_core::fmea::CompiledHm {
    let mut params = ParamsFiles::new("p");
    params.insert("p/t.toml", text);
    let f = read_hm(&params, Path::new("p/t.toml")).unwrap();
    compile_hm(Path::new("t.toml"), &f).unwrap()
}

fn cpt(h: &companion_core::fmea::CompiledHm, n: &str) -> Vec<f64> {
    h.network.node(h.network.id(n).unwrap()).cpt.clone()
}

fn close(a: &[f64], b: &[f64]) {
    assert_eq!(a.len(), b.len(), "{a:?} vs {b:?}");
    for (x, y) in a.iter().zip(b) {
        assert!((x - y).abs() < 1e-12, "{a:?} vs {b:?}");
    }
}

#[test]
fn fmea_row_roles_and_noisy_or() {
    let h = compile(
        r#"
name = "t"
[[fmea]]
error = "U_e"
monitors = ["S_m"]
contexts = ["A_a", "A_b"]
solutions = ["C_s"]
[node.A_a]
states = ["no", "yes"]
[node.A_b]
states = ["x", "y", "z"]
prior = [0.5, 0.3, 0.2]
[node.U_e]
leak = 0.1
strength = { A_a = [0.0, 0.5], A_b = [0.0, 0.2, 0.4] }
[node.S_m]
health = "H_S_m"
sensitivity = 0.9
false_alarm = 0.1
[node.H_S_m]
role = "monitor_health"
[publish]
P_e = "1 - P(U_e = present)"
"#,
    );
    let roles: Vec<(&str, &str)> = h
        .nodes
        .iter()
        .map(|n| (n.name.as_str(), n.role.as_str()))
        .collect();
    for want in [
        ("U_e", "error"),
        ("S_m", "monitor"),
        ("A_a", "context"),
        ("C_s", "solution"),
        ("H_S_m", "monitor_health"),
    ] {
        assert!(roles.contains(&want), "{roles:?}");
    }
    // Default context prior: nominal 0.9.
    close(&cpt(&h, "A_a"), &[0.9, 0.1]);
    close(&cpt(&h, "C_s"), &[0.9, 0.1]);
    // Noisy-OR by hand: P(absent) = (1 - leak) * prod(1 - strength).
    let mut want = Vec::new();
    for a in [0.0, 0.5] {
        for b in [0.0, 0.2, 0.4] {
            let off = 0.9 * (1.0 - a) * (1.0 - b);
            want.extend([off, 1.0 - off]);
        }
    }
    close(&cpt(&h, "U_e"), &want);
    // Monitor rows: (error, health) = (absent, ok), (absent, faulty), (present, ok), (present, faulty).
    close(
        &cpt(&h, "S_m"),
        &[0.9, 0.1, 0.5, 0.5, 0.9 * 0.1, 1.0 - 0.09, 0.5, 0.5],
    );
    assert_eq!(h.publish[0].expr(), "1 - P(U_e = present)");
}

#[test]
fn qos_version_and_activation_rules() {
    let h = compile(
        r#"
name = "t"
[[fmea]]
error = "U_x"
contexts = ["A_c"]
solutions = ["C_x"]
[[fmea]]
error = "U_y"
contexts = ["A_c"]
solutions = ["C_y"]
[node.A_c]
states = ["no", "yes"]
[node.Q]
role = "qos"
errors = ["U_x", "U_y"]
by_uncorrected = [[0.9, 0.1], [0.4, 0.6], [0.1, 0.9]]
states = ["good", "bad"]
[node.V]
role = "version"
errors = ["U_x", "U_y"]
solutions = ["C_x"]
override = [{ when = { U_x = "present", U_y = "present" }, p = [0.3, 0.7] }]
[node.T]
role = "resource"
states = ["0", "1", "2"]
[node.L]
role = "resource"
states = ["low", "high"]
[node.R]
role = "activation"
version = "V"
tiles = "T"
cpu = "L"
implementations = [{ name = "S", tiles = 0, cpu = "low" }, { name = "F", tiles = 2, cpu = "high" }]
"#,
    );
    // QoS parents: U_x, U_y, C_x, C_y. Uncorrected = present errors whose solution is off.
    let q = cpt(&h, "Q");
    let mut want = Vec::new();
    for ux in 0..2 {
        for uy in 0..2 {
            for cx in 0..2 {
                for cy in 0..2 {
                    let k = (ux == 1 && cx == 0) as usize + (uy == 1 && cy == 0) as usize;
                    want.extend(match k {
                        0 => [0.9, 0.1],
                        1 => [0.4, 0.6],
                        _ => [0.1, 0.9],
                    });
                }
            }
        }
    }
    close(&q, &want);
    // Version: p = 0.95 * 0.1^(unfixed present) * 0.5^(own solutions whose error is absent).
    // Rows (U_x, U_y): (a,a): extra 1 -> 0.475; (a,p): miss 1, extra 1 -> 0.0475;
    // (p,a): 0.95; (p,p): overridden 0.7.
    close(
        &cpt(&h, "V"),
        &[0.525, 0.475, 0.9525, 0.0475, 0.05, 0.95, 0.3, 0.7],
    );
    // Activation rows (V, T, L): off -> 0; on: fits if (T>=0 and L<=low) or (T>=2).
    let r = cpt(&h, "R");
    let mut want = Vec::new();
    for v in 0..2 {
        for t in 0..3 {
            for l in 0..2 {
                let p = if v == 0 {
                    0.0
                } else if l == 0 || t >= 2 {
                    1.0
                } else {
                    0.05
                };
                want.extend([1.0 - p, p]);
            }
        }
    }
    close(&r, &want);
}

#[test]
fn state_transition_rule() {
    let h = compile(
        r#"
name = "t"
[node.E0]
role = "state"
states = ["h", "m", "l"]
prior = [0.5, 0.3, 0.2]
[node.W]
role = "context"
states = ["calm", "strong"]
[node.E1]
role = "state"
states = ["h", "m", "l"]
previous = "E0"
parents = ["W"]
stay = 0.8
drain = { W = [1.0, 0.5] }
"#,
    );
    close(
        &cpt(&h, "E1"),
        &[
            0.8, 0.2, 0.0, 0.4, 0.6, 0.0, 0.0, 0.8, 0.2, 0.0, 0.4, 0.6, 0.0, 0.0, 1.0, 0.0, 0.0,
            1.0,
        ],
    );
}
