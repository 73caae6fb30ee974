//! Node entries parsed by role: each role's keys, the role from the FMEA rows, and keys a role
//! does not take refused with the file, the node and the key.

use super::schema::{NodeCommon, NodeSpec};
use super::{CptSpec, HmFile, compile_hm, read_hm};
use crate::spec::{ParamsFiles, SpecError};
use std::collections::BTreeSet;
use std::path::Path;

const FILE: &str = "p/health/t.toml";

fn read(text: &str) -> Result<HmFile, SpecError> {
    let mut params = ParamsFiles::new("p");
    params.insert(FILE, text);
    read_hm(&params, Path::new(FILE))
}

fn node<'a>(f: &'a HmFile, name: &str) -> &'a NodeSpec {
    f.node.get(name).unwrap_or_else(|| panic!("no node {name}"))
}

/// The entry `node.NAME` of `text` sets every key its role takes, so a per-role test below
/// reads them all (and a key added to a role without its list, or the reverse, shows up here).
fn sets_every_key(text: &str, name: &str, spec: &NodeSpec) {
    let doc: toml::Table = toml::from_str(text).unwrap();
    let written: BTreeSet<&str> = doc["node"][name]
        .as_table()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    let takes: BTreeSet<&str> = NodeCommon::KEYS
        .iter()
        .chain(NodeSpec::role_keys(spec.role()))
        .copied()
        .collect();
    assert_eq!(written, takes, "node.{name}");
}

/// The common keys, as every per-role test writes them (`role` is set by each test).
const COMMON: &str = r#"description = "d"
states = ["s0", "s1"]
parents = ["P"]
cpt = [[0.5, 0.5], [0.25, 0.75]]
override = [{ when = { P = "p1" }, p = [0.125, 0.875] }]
"#;

fn assert_common(spec: &NodeSpec) {
    let c = spec.common();
    assert_eq!(c.description, "d");
    assert_eq!(c.states.as_deref(), Some(&["s0".into(), "s1".into()][..]));
    assert_eq!(c.parents.as_deref(), Some(&["P".into()][..]));
    assert!(matches!(&c.cpt, Some(CptSpec::Rows(r)) if r == &[vec![0.5, 0.5], vec![0.25, 0.75]]));
    assert_eq!(c.overrides.len(), 1);
    assert_eq!(c.overrides[0].when["P"], "p1");
    assert_eq!(c.overrides[0].p, [0.125, 0.875]);
}

/// A file with one node `X` of role `role`: its common keys and `keys`.
fn one_node(role: &str, keys: &str) -> String {
    format!("name = \"t\"\n[node.X]\nrole = \"{role}\"\n{COMMON}{keys}")
}

fn parsed(role: &str, keys: &str) -> NodeSpec {
    let text = one_node(role, keys);
    let f = read(&text).unwrap_or_else(|e| panic!("{e}"));
    let spec = node(&f, "X").clone();
    assert_eq!(spec.role_name(), role);
    sets_every_key(&text, "X", &spec);
    assert_common(&spec);
    spec
}

#[test]
fn qos_node_parses_its_keys() {
    let NodeSpec::Qos(q) = parsed(
        "qos",
        "errors = [\"U_a\"]\nby_uncorrected = [[0.5, 0.5], [0.0, 1.0]]\n",
    ) else {
        panic!("not qos")
    };
    assert_eq!(q.errors, Some(vec!["U_a".to_string()]));
    assert_eq!(q.by_uncorrected, Some(vec![vec![0.5, 0.5], vec![0.0, 1.0]]));
}

#[test]
fn error_node_parses_its_keys() {
    let NodeSpec::Error(e) = parsed("error", "leak = 0.02\nstrength = { P = [0.0, 0.7] }\n") else {
        panic!("not error")
    };
    assert_eq!(e.leak, Some(0.02));
    assert_eq!(e.strength["P"], [0.0, 0.7]);
}

#[test]
fn monitor_health_node_parses_its_keys() {
    let NodeSpec::MonitorHealth(e) = parsed(
        "monitor_health",
        "leak = 0.03\nstrength = { P = [0.0, 0.6] }\n",
    ) else {
        panic!("not monitor_health")
    };
    assert_eq!(e.leak, Some(0.03));
    assert_eq!(e.strength["P"], [0.0, 0.6]);
}

#[test]
fn monitor_node_parses_its_keys() {
    let NodeSpec::Monitor(m) = parsed(
        "monitor",
        "sensitivity = 0.9\nfalse_alarm = 0.1\nfaulty_alarm = 0.4\nhealth = \"H_S_x\"\n",
    ) else {
        panic!("not monitor")
    };
    assert_eq!(m.sensitivity, Some(0.9));
    assert_eq!(m.false_alarm, Some(0.1));
    assert_eq!(m.faulty_alarm, Some(0.4));
    assert_eq!(m.health.as_deref(), Some("H_S_x"));
}

#[test]
fn context_resource_and_solution_nodes_parse_their_prior() {
    for role in ["context", "resource", "solution"] {
        let spec = parsed(role, "prior = [0.75, 0.25]\n");
        let (NodeSpec::Context(r) | NodeSpec::Resource(r) | NodeSpec::Solution(r)) = spec else {
            panic!("{role}: not a root variant")
        };
        assert_eq!(r.prior, Some(vec![0.75, 0.25]), "{role}");
    }
}

#[test]
fn version_node_parses_its_keys() {
    let NodeSpec::Version(v) = parsed(
        "version",
        "errors = [\"U_a\"]\nsolutions = [\"C_a\"]\np_ok = 0.9\nmiss = 0.2\nextra = 0.4\n",
    ) else {
        panic!("not version")
    };
    assert_eq!(v.errors, Some(vec!["U_a".to_string()]));
    assert_eq!(v.solutions, Some(vec!["C_a".to_string()]));
    assert_eq!((v.p_ok, v.miss, v.extra), (Some(0.9), Some(0.2), Some(0.4)));
}

#[test]
fn performance_node_parses_the_common_keys_only() {
    let spec = parsed("performance", "");
    assert!(matches!(spec, NodeSpec::Performance(_)));
    let e = read(&one_node("performance", "prior = [0.5, 0.5]\n")).unwrap_err();
    assert_eq!(e.entry, "node.X.prior", "{e}");
}

#[test]
fn fit_node_parses_its_keys() {
    let NodeSpec::Fit(f) = parsed(
        "fit",
        r#"variant = "track/V3"
tiles = "A_free_tiles"
cpu = "A_cpu_headroom"
performance = "A_rate"
p_unsure = 0.25
"#,
    ) else {
        panic!("not fit")
    };
    assert_eq!(f.variant.as_deref(), Some("track/V3"));
    assert_eq!(
        (
            f.tiles.as_deref(),
            f.cpu.as_deref(),
            f.performance.as_deref()
        ),
        (Some("A_free_tiles"), Some("A_cpu_headroom"), Some("A_rate"))
    );
    assert_eq!(f.p_unsure, Some(0.25));
}

#[test]
fn activation_node_parses_its_keys() {
    let NodeSpec::Activation(a) = parsed(
        "activation",
        r#"variant = "track/V3"
version = "C_V3"
tiles = "A_free_tiles"
cpu = "A_cpu_load"
performance = "A_speed"
implementations = [{ name = "HW", tiles = 2, cpu = "high", fast = true }, { name = "SW", cpu_per_fps = 0.25, max_fps = 4 }]
p_fit = 0.99
p_nofit = 0.01
fit = "F_V3"
"#,
    ) else {
        panic!("not activation")
    };
    assert_eq!(a.fit.as_deref(), Some("F_V3"));
    assert_eq!(a.variant.as_deref(), Some("track/V3"));
    assert_eq!(a.version.as_deref(), Some("C_V3"));
    assert_eq!(a.tiles.as_deref(), Some("A_free_tiles"));
    assert_eq!(a.cpu.as_deref(), Some("A_cpu_load"));
    assert_eq!(a.performance.as_deref(), Some("A_speed"));
    assert_eq!((a.p_fit, a.p_nofit), (Some(0.99), Some(0.01)));
    let [hw, sw] = &a.implementations[..] else {
        panic!("{:?}", a.implementations)
    };
    assert_eq!(
        (hw.name.as_str(), hw.tiles, hw.cpu.as_str(), hw.fast),
        ("HW", 2, "high", true)
    );
    assert_eq!((hw.cpu_per_fps, hw.max_fps), (None, None));
    assert_eq!(
        (sw.name.as_str(), sw.tiles, sw.cpu.as_str(), sw.fast),
        ("SW", 0, "", false)
    );
    // An integer in the file reads as a float, as before the entries were parsed by role.
    assert_eq!((sw.cpu_per_fps, sw.max_fps), (Some(0.25), Some(4.0)));
}

#[test]
fn import_node_parses_its_keys() {
    let NodeSpec::Import(i) = parsed("import", "prior = [0.5, 0.5]\nfrom = \"sensors.U_gps\"\n")
    else {
        panic!("not import")
    };
    assert_eq!(i.prior, Some(vec![0.5, 0.5]));
    assert_eq!(i.from.as_deref(), Some("sensors.U_gps"));
}

#[test]
fn state_node_parses_its_keys() {
    let NodeSpec::State(s) = parsed(
        "state",
        "prior = [0.5, 0.5]\nprevious = \"E_t\"\nstay = 0.8\ndrain = { P = [1.0, 0.9] }\n",
    ) else {
        panic!("not state")
    };
    assert_eq!(s.prior, Some(vec![0.5, 0.5]));
    assert_eq!(s.previous.as_deref(), Some("E_t"));
    assert_eq!(s.stay, Some(0.8));
    assert_eq!(s.drain["P"], [1.0, 0.9]);
}

/// A node with only the keys it needs reads every other key at its default.
#[test]
fn absent_keys_read_as_defaults() {
    let f = read("name = \"t\"\n[node.X]\nrole = \"monitor\"\n").unwrap();
    let NodeSpec::Monitor(m) = node(&f, "X") else {
        panic!("not monitor")
    };
    assert!(m.sensitivity.is_none() && m.false_alarm.is_none() && m.health.is_none());
    let c = &m.common;
    assert!(c.states.is_none() && c.parents.is_none() && c.cpt.is_none());
    assert!(c.description.is_empty() && c.overrides.is_empty());
}

const FMEA_ROW: &str = r#"name = "t"
[[fmea]]
error = "U_e"
monitors = ["S_m"]
contexts = ["A_a"]
solutions = ["C_s"]
"#;

/// Entries without `role` take it from the FMEA rows, and are parsed as that role.
#[test]
fn role_derived_from_fmea_rows() {
    let text = format!(
        "{FMEA_ROW}[node.U_e]\nleak = 0.2\n[node.S_m]\nsensitivity = 0.8\n\
         [node.A_a]\nstates = [\"no\", \"yes\"]\nprior = [0.6, 0.4]\n[node.C_s]\nprior = [0.7, 0.3]\n"
    );
    let f = read(&text).unwrap();
    assert!(matches!(node(&f, "U_e"), NodeSpec::Error(e) if e.leak == Some(0.2)));
    assert!(matches!(node(&f, "S_m"), NodeSpec::Monitor(m) if m.sensitivity == Some(0.8)));
    assert!(matches!(node(&f, "A_a"), NodeSpec::Context(c) if c.prior == Some(vec![0.6, 0.4])));
    assert!(matches!(node(&f, "C_s"), NodeSpec::Solution(c) if c.prior == Some(vec![0.7, 0.3])));
    // And they compile with those settings: U_e = noisy-OR with leak 0.2 over A_a.
    let h = compile_hm(Path::new(FILE), &f).unwrap();
    let roles: Vec<(&str, &str)> = h
        .nodes
        .iter()
        .map(|n| (n.name.as_str(), n.role.as_str()))
        .collect();
    assert_eq!(
        roles,
        [
            ("U_e", "error"),
            ("S_m", "monitor"),
            ("A_a", "context"),
            ("C_s", "solution")
        ]
    );
    let u = h.network.id("U_e").unwrap();
    let cpt = &h.network.node(u).cpt;
    // A_a = no: P(absent) = 1 - leak; A_a = yes: (1 - leak)(1 - 0.8).
    let want = [0.8, 0.2, 0.8 * 0.2, 1.0 - 0.8 * 0.2];
    for (a, b) in cpt.iter().zip(want) {
        assert!((a - b).abs() < 1e-12, "{cpt:?}");
    }
}

/// A `role` key agreeing with the FMEA rows is accepted; one disagreeing is the error it was.
#[test]
fn role_key_must_agree_with_fmea_rows() {
    let f = read(&format!("{FMEA_ROW}[node.S_m]\nrole = \"monitor\"\n")).unwrap();
    assert!(matches!(node(&f, "S_m"), NodeSpec::Monitor(_)));
    let e = read(&format!("{FMEA_ROW}[node.S_m]\nrole = \"error\"\n")).unwrap_err();
    assert_eq!(e.file, Path::new(FILE));
    assert_eq!(e.entry, "node.S_m.role", "{e}");
    assert!(
        e.reason.contains("is used as error but already as monitor"),
        "{e}"
    );
}

/// The role errors: none at all, an unknown one, one that is not a string.
#[test]
fn missing_unknown_or_mistyped_role_is_refused() {
    for (entry, reason) in [
        ("", "node is in no FMEA row and has no `role`"),
        (
            "role = \"sensor\"",
            "unknown role `sensor` (one of qos, error",
        ),
        ("role = 3", "`role` must be a string, found integer"),
    ] {
        let e = read(&format!("name = \"t\"\n[node.N]\n{entry}\n")).unwrap_err();
        assert_eq!(e.file, Path::new(FILE));
        assert_eq!(e.entry, "node.N.role", "{e}");
        assert!(e.reason.contains(reason), "{e}");
    }
}

/// A key of another role (`strength` on a monitor) was silently ignored: it is refused, naming
/// the file, the node, the key and the roles that take it.
#[test]
fn stray_field_of_another_role_is_refused() {
    let e = read(&format!(
        "{FMEA_ROW}[node.S_m]\nsensitivity = 0.9\nstrength = {{ U_e = [0.0, 0.5] }}\n"
    ))
    .unwrap_err();
    assert_eq!(e.file, Path::new(FILE));
    assert_eq!(e.entry, "node.S_m.strength", "{e}");
    assert!(
        e.reason
            .contains("unknown field `strength` for a monitor node"),
        "{e}"
    );
    assert!(
        e.reason
            .contains("it belongs to error, monitor_health nodes"),
        "{e}"
    );
    // The same with the role given by the entry, and for each role a key of another one.
    for (role, key) in [
        ("context", "leak = 0.1"),
        ("error", "prior = [0.5, 0.5]"),
        ("qos", "solutions = []"),
        ("version", "by_uncorrected = [[1.0]]"),
        ("import", "stay = 0.5"),
        ("state", "from = \"a.b\""),
        ("activation", "health = \"H\""),
        ("monitor_health", "sensitivity = 0.5"),
    ] {
        let e = read(&format!(
            "name = \"t\"\n[node.N]\nrole = \"{role}\"\n{key}\n"
        ))
        .unwrap_err();
        let k = key.split(' ').next().unwrap();
        assert_eq!(e.entry, format!("node.N.{k}"), "{e}");
        assert!(
            e.reason
                .contains(&format!("unknown field `{k}` for a {role} node")),
            "{e}"
        );
    }
}

/// A key no role takes (a typo) is refused the same way.
#[test]
fn typo_field_is_refused() {
    let e = read("name = \"t\"\n[node.E]\nrole = \"state\"\nstai = 0.9\n").unwrap_err();
    assert_eq!(e.file, Path::new(FILE));
    assert_eq!(e.entry, "node.E.stai", "{e}");
    assert!(
        e.reason
            .contains("unknown field `stai` for a state node (no role takes it)"),
        "{e}"
    );
    assert!(e.reason.contains("stay"), "lists the keys it takes: {e}");
}

/// A key of the role with a value of the wrong type names the node and the key.
#[test]
fn mistyped_value_names_the_node_and_key() {
    let e = read(&format!(
        "{FMEA_ROW}[node.U_e]\ndescription = \"d\"\nleak = \"high\"\nstates = [\"a\", \"b\"]\n"
    ))
    .unwrap_err();
    assert_eq!(e.file, Path::new(FILE));
    assert_eq!(e.entry, "node.U_e.leak", "{e}");
    assert!(
        e.reason
            .contains("invalid type: string \"high\", expected f64"),
        "{e}"
    );
    // Inside a common key too, and a required key missing in an implementation.
    let e = read(&format!(
        "{FMEA_ROW}[node.U_e]\noverride = [{{ when = {{}}, p = 1 }}]\n"
    ))
    .unwrap_err();
    assert_eq!(e.entry, "node.U_e.override", "{e}");
    let e =
        read("name = \"t\"\n[node.R]\nrole = \"activation\"\nimplementations = [{ tiles = 1 }]\n")
            .unwrap_err();
    assert_eq!(e.entry, "node.R.implementations", "{e}");
    assert!(e.reason.contains("missing field `name`"), "{e}");
}

/// `parents` stays a common key, so a root role keeps the error saying why it takes none.
#[test]
fn parents_on_a_root_is_refused_at_compile() {
    let f = read(&format!(
        "{FMEA_ROW}[node.A_a]\nstates = [\"no\", \"yes\"]\nparents = [\"U_e\"]\n"
    ))
    .unwrap();
    let e = compile_hm(Path::new(FILE), &f).unwrap_err();
    assert_eq!(e.entry, "node.A_a.parents", "{e}");
    assert!(e.reason.contains("a context node is a root"), "{e}");
}
