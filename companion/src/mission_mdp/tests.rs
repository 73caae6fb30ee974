use super::*;

pub(super) const KNOWN: &[&str] = &[
    "P_sys", "P_battery", "P_obs", "P_SI", "P_SF", "P_appT", "P_appZ", "P_crash", "P_detect", "P_track", "P_V0",
    "P_V1", "P_V2", "P_V3", "P_V4", "P_V5",
];

#[test]
fn explore() {
    let dir = crate::spec::default_params_dir();
    let mut all = MissionMdps::load(&dir, KNOWN).unwrap();
    let point = all.check_point().clone();
    for name in ["reference", "navigation", "landing", "tracking", "monolithic"] {
        for pol in ["safety", "mission"] {
            let m = all.get_mut(name).unwrap();
            m.instantiate(&point, pol).unwrap();
            let mut ws = mdp_engine::Workspace::new();
            let mdp = m.mdp().clone();
            let fh = ws.finite_horizon(&mdp, 100);
            let line: Vec<String> = (0..m.n_states())
                .map(|s| format!("{}:{}({:.1})", m.state_name(s), fh.decision(s).map(|a| m.action_name(a)).unwrap_or("-"), fh.value(0, s)))
                .collect();
            eprintln!("{name}/{pol}: {}", line.join(" "));
        }
    }
}
