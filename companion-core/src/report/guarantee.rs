//! PANORAMA views: the allocation table (Tables 6 and 7) and `companion check`'s guarantee
//! section.

use crate::guarantee::{Guarantee, MissionSpec, RasRow, judge, load_mission, named};
use crate::record::Verdict;
use crate::spec::{ParamsFiles, SpecError};
use panorama::Infeasible;
use std::collections::BTreeMap;

/// Render RAS rows in the shape of PANORAMA Tables 6 and 7: one column per activity with its
/// objective, tasks and speed, then one line per RAS.
pub fn render_ras_table(spec: &MissionSpec, rows: &[RasRow]) -> String {
    let n = spec.activities.len();
    let ras0 = rows.first();
    let mut lines: Vec<(String, Vec<String>)> = vec![
        (
            "Objective".into(),
            spec.activities
                .iter()
                .map(|a| a.objective.clone())
                .collect(),
        ),
        (
            "Tasks".into(),
            spec.activities.iter().map(|a| a.tasks.join(" ")).collect(),
        ),
        (
            "Constraints".into(),
            spec.activities
                .iter()
                .map(|a| {
                    if a.constraints.is_empty() {
                        "ALL".into()
                    } else {
                        a.constraints.join("/")
                    }
                })
                .collect(),
        ),
        (
            "Activity".into(),
            spec.activities.iter().map(|a| a.name.clone()).collect(),
        ),
    ];
    if let Some(r0) = ras0 {
        lines.push((
            "v (m/s)".into(),
            (0..n)
                .map(|j| {
                    let i = r0.cells[j].as_ref().and_then(|c| {
                        spec.problem.activities[j]
                            .ias
                            .iter()
                            .position(|x| &x.name == c)
                    });
                    match i.and_then(|i| spec.activities[j].ia_speed[i]) {
                        Some(v) => format!("{v:.2}"),
                        None => "-".into(),
                    }
                })
                .collect(),
        ));
    }
    for r in rows {
        lines.push((
            r.label.clone(),
            r.cells
                .iter()
                .map(|c| c.clone().unwrap_or_default())
                .collect(),
        ));
    }
    let head = lines.iter().map(|(h, _)| h.len()).max().unwrap_or(0);
    let width: Vec<usize> = (0..n)
        .map(|j| lines.iter().map(|(_, c)| c[j].len()).max().unwrap_or(0))
        .collect();
    let mut out = String::new();
    for (h, cells) in &lines {
        out.push_str(&format!("{h:<head$}"));
        for (j, c) in cells.iter().enumerate() {
            out.push_str(&format!(" | {c:<w$}", w = width[j]));
        }
        out.push('\n');
    }
    for r in rows.iter().skip(1) {
        out.push_str(&format!("{}: {}\n", r.label, r.reason));
    }
    out
}

/// `companion check --mission NAME` as JSON:
/// `{"guarantee": {"mission", "activities": [...], "ras0": {...}|null, "infeasible": {...}|null,
/// "nga": <integer>, "margins": {...}, "goals": {...}}}`.
pub fn check_json(params: &ParamsFiles, mission: &str) -> Result<serde_json::Value, SpecError> {
    let spec = load_mission(params, mission)?;
    Ok(check_json_spec(&spec))
}

fn nga_json(n: Option<u128>) -> serde_json::Value {
    match n {
        Some(x) => u64::try_from(x)
            .map(serde_json::Value::from)
            .unwrap_or_else(|_| serde_json::Value::String(x.to_string())),
        None => serde_json::Value::String("overflow".into()),
    }
}

/// [`check_json`] for an already loaded mission.
pub fn check_json_spec(spec: &MissionSpec) -> serde_json::Value {
    use serde_json::json;
    let p = &spec.problem;
    let pre = Guarantee::pre_flight(spec);
    let activities: Vec<_> = spec
        .activities
        .iter()
        .zip(&p.activities)
        .enumerate()
        .map(|(j, (info, a))| {
            let chosen = pre.as_ref().ok().map(|r| r.choice[j]);
            json!({
                "name": info.name,
                "objective": info.objective,
                "env": info.env,
                "tasks": info.tasks,
                "constraints": info.constraints,
                "n_ia": a.ias.len(),
                "n_ia_unconstrained": info.n_ia_unconstrained,
                "ras0": chosen.map(|i| json!({
                    "ia": a.ias[i].name,
                    "speed_mps": info.ia_speed[i],
                    "estimate": named(&p.goals, &a.ias[i].cost),
                })),
            })
        })
        .collect();
    let goals: BTreeMap<_, _> = p.goals.iter().map(|g| (g.name.clone(), g.bound)).collect();
    let order: Vec<_> = p.goals.iter().map(|g| g.name.clone()).collect();
    let (ras0, margins, infeasible) = match &pre {
        Ok(r) => (
            json!({
                "allocation": r.choice.iter().enumerate().map(|(j, &i)| p.activities[j].ias[i].name.clone()).collect::<Vec<_>>(),
                "totals": r.totals,
            }),
            json!(r.margins),
            serde_json::Value::Null,
        ),
        Err(e) => (
            serde_json::Value::Null,
            json!({}),
            match e {
                Infeasible::Goal {
                    goal,
                    minimum,
                    bound,
                    excess,
                } => {
                    json!({"constraint": goal, "minimum": minimum, "bound": bound, "excess": excess, "message": e.to_string()})
                }
                Infeasible::NoAlternative { activity } => {
                    json!({"constraint": "resources", "activity": activity, "message": e.to_string()})
                }
            },
        ),
    };
    json!({"guarantee": {
        "mission": spec.name,
        "file": spec.file.display().to_string(),
        "goal_order": order,
        "goals": goals,
        "activities": activities,
        "ras0": ras0,
        "infeasible": infeasible,
        "nga": nga_json(panorama::nga(p)),
        "margins": margins,
        "verdict": check_verdict(spec),
    }})
}

/// The verdict `check` gives: the whole mission on a full pack (the params' `[battery]`), no
/// time spent.
fn check_verdict(spec: &MissionSpec) -> Verdict {
    let spent = vec![0.0; spec.problem.goals.len()];
    judge(spec, &spent, spec.battery_capacity_j.map(|_| 100.0))
}

/// `companion check --mission NAME` for people: activities, RAS0 as PANORAMA Table 6, NGA and the
/// initial margins (or the failing goal and its excess).
pub fn check_text(params: &ParamsFiles, mission: &str) -> Result<String, SpecError> {
    let spec = load_mission(params, mission)?;
    Ok(check_text_spec(&spec))
}

/// [`check_text`] for an already loaded mission.
pub fn check_text_spec(spec: &MissionSpec) -> String {
    let p = &spec.problem;
    let mut out = format!("mission {} ({})\n", spec.name, spec.file.display());
    if !spec.description.is_empty() {
        out.push_str(&format!("  {}\n", spec.description));
    }
    out.push_str(&format!("{} activities:\n", p.activities.len()));
    for (info, a) in spec.activities.iter().zip(&p.activities) {
        out.push_str(&format!(
            "  {:<22} {:<10} tasks {:<28} constraints {:<14} IAs {} of {}\n",
            info.name,
            info.objective,
            info.tasks.join(" "),
            if info.constraints.is_empty() {
                "ALL".to_string()
            } else {
                info.constraints.join("/")
            },
            a.ias.len(),
            info.n_ia_unconstrained
        ));
    }
    let nga = panorama::nga(p).map_or("overflow".to_string(), |x| {
        format!("{x} ({:.2e})", x as f64)
    });
    out.push_str(&format!("NGA = {nga}\n"));
    let order: Vec<String> = p
        .goals
        .iter()
        .map(|g| format!("{} <= {:.1}", g.name, g.bound))
        .collect();
    out.push_str(&format!("goals in order: {}\n", order.join(", ")));
    match Guarantee::pre_flight(spec) {
        Ok(r) => {
            let row = RasRow {
                label: "RAS0".into(),
                reason: String::new(),
                from_activity: 0,
                cells: r
                    .choice
                    .iter()
                    .enumerate()
                    .map(|(j, &i)| Some(p.activities[j].ias[i].name.clone()))
                    .collect(),
            };
            out.push_str("\nRAS0 (PANORAMA Table 6 shape):\n");
            out.push_str(&render_ras_table(spec, &[row]));
            out.push_str("\ninitial margins:\n");
            for g in &p.goals {
                out.push_str(&format!(
                    "  {:<12} estimate {:>12.1}  goal {:>12.1}  margin {:>10.1}\n",
                    g.name, r.totals[&g.name], g.bound, r.margins[&g.name]
                ));
            }
        }
        Err(e) => out.push_str(&format!("\nINFEASIBLE: {e}\n")),
    }
    let v = check_verdict(spec);
    let [plan, fit] = v.words();
    out.push_str(&format!(
        "\nverdict: {}: {plan}; {fit}\n",
        if v.fits { "fits" } else { "does not fit" }
    ));
    out
}
