//! What `calibrate` prints (the fit error before and after, each number's change) and the
//! overlay it writes, every fitted number with its source in place of `ASSUMPTION`.

use super::Calibration;
use super::cpt::{LearnedRow, PRIOR_PSEUDO_COUNTS};
use super::power_fit::{FitResult, PowerModel};
use super::shipped::Shipped;
use super::toml_table::{round4, round6, table_at};
pub use super::write_legs::{FittedLegs, FittedRate};
use crate::review::text::escape_controls;
use std::fmt::Write;
use std::path::Path;
use toml::{Table, Value};

fn pct(x: f64, of: f64) -> f64 {
    if of.abs() > 0.0 {
        100.0 * x / of
    } else {
        f64::NAN
    }
}

/// What a v0 at the grid's top means, for the report and the source.
fn v0_note(r: &FitResult) -> &'static str {
    if r.v0_lower_bound_only {
        "; induced_velocity_mps is a lower bound only: the induced power did not fall over the \
         speeds flown (any larger v0 fits as well)"
    } else {
        ""
    }
}

/// The fit's provenance, the text of each fitted number's `source`: made by `made_by` from
/// `runs` runs.
pub fn power_source(made_by: &str, runs: usize, r: &FitResult) -> String {
    let s = format!(
        "{made_by}: {runs} run(s), {} power samples ({} on the ground), speeds {:.1}..{:.1} m/s; \
         fit RMS {:.1} W ({:.1} % of the mean measured {:.1} W); the shipped params' RMS {:.1} W ({:.1} %)",
        r.samples,
        r.ground_samples,
        r.v_min,
        r.v_max,
        r.rms_w,
        pct(r.rms_w, r.mean_w),
        r.mean_w,
        r.shipped_rms_w,
        pct(r.shipped_rms_w, r.mean_w),
    );
    s + v0_note(r)
}

fn model_rows(m: &PowerModel) -> [(&'static str, f64); 6] {
    [
        ("base.power_w", m.base_w),
        (
            "hover power (blade_profile_w + induced_hover_w)",
            m.hover_w(),
        ),
        ("propulsion.blade_profile_w", m.blade_profile_w),
        ("propulsion.induced_hover_w", m.induced_hover_w),
        ("propulsion.induced_velocity_mps", m.induced_velocity_mps),
        ("propulsion.drag_area_m2", m.drag_area_m2),
    ]
}

/// The runs read (each once, by content), the repeats left out, each tlog's autopilot and the
/// impostors left out; every name escaped for the terminal.
fn runs_report(s: &mut String, cal: &Calibration) {
    let _ = writeln!(
        s,
        "runs (each counted once, by the SHA-256 of its decision log and flight.tlog):"
    );
    for r in &cal.runs {
        let _ = writeln!(s, "  {}", shown(r));
    }
    for (r, first) in &cal.repeats {
        let _ = writeln!(
            s,
            "  {}: the same content as {}: counted once",
            shown(r),
            shown(first)
        );
    }
    for (r, t) in &cal.tlogs {
        let how = if t.pin.is_some() {
            " (pinned)"
        } else {
            " (fly's choice: component 1 first; pin with --autopilot-sysid)"
        };
        let who = match (t.autopilot, t.pin) {
            (Some((a, c)), _) => format!("autopilot {a}/{c}{how}"),
            (None, Some((a, c))) => format!("no frame of the pinned autopilot {a}/{c}"),
            (None, None) => "no autopilot heard".to_string(),
        };
        let _ = write!(
            s,
            "  {}/flight.tlog: {} power samples from {who}",
            shown(r),
            t.samples
        );
        if !t.impostors.is_empty() {
            let others: Vec<String> = t
                .impostors
                .iter()
                .map(|((a, c), n)| format!("{a}/{c} ({n} frames)"))
                .collect();
            let _ = write!(
                s,
                "; other autopilots left out (fly would not obey them): {}",
                others.join(", ")
            );
        }
        let _ = writeln!(s);
    }
}

fn shown(p: &Path) -> String {
    crate::output_file::shown(p)
}

/// What the fit says that no airframe of this mission can be (the mission's `[power_bounds]`)
/// and durations of zero or negative length: each a reason; any refuses the whole overlay.
pub fn refusals(shipped: &Shipped, cal: &Calibration) -> Vec<String> {
    use companion_core::guarantee::power_bounds::check_power_curve;
    let mut out = Vec::new();
    let mf = &shipped.mission_file;
    if let Ok(r) = &cal.power {
        match &shipped.bounds {
            None => out.push(format!(
                "{mf}: no [power_bounds]: a fit cannot be judged against what no airframe can be                  (docs/calibrate.md)"
            )),
            Some(b) => {
                let propulsion = |v: f64| match r.polynomial_w {
                    Some(c) => c[0] + c[2] * v * v + c[3] * v * v * v,
                    None => r.fitted.power(v, true) - r.fitted.base_w,
                };
                let v_max = shipped.fastest_mps.max(r.v_max);
                if let Err(u) = check_power_curve(Some(b), propulsion, r.fitted.base_w, v_max) {
                    out.push(format!("fitted {mf} {}: {}", u.entry, u.reason));
                }
                let frac = r.rms_w / r.mean_w;
                if !(frac.is_finite() && r.mean_w > 0.0 && frac <= b.max_fit_rms_fraction) {
                    out.push(format!(
                        "fit RMS {:.2} W against a mean measured {:.2} W ({:.1} %): above                          [power_bounds] max_fit_rms_fraction {} of {mf}; the model does not                          describe these runs",
                        r.rms_w,
                        r.mean_w,
                        100.0 * frac,
                        b.max_fit_rms_fraction
                    ));
                }
            }
        }
    }
    out.extend(super::write_legs::refusals(cal));
    for (name, (n, shortest)) in cal.durations.non_positive() {
        out.push(format!(
            "activity {}: {n} completed run(s) of zero or negative length (shortest {shortest} s):              the records' clock stood or went back, no duration is fitted from them",
            escape_controls(name, false)
        ));
    }
    out
}

/// The report: runs, power fit (error before and after, each parameter), durations, CPT rows.
pub fn report(shipped: &Shipped, cal: &Calibration) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "calibrated from {} run(s), {} records",
        cal.runs.len(),
        cal.records
    );
    runs_report(&mut s, cal);
    let _ = writeln!(s, "\npower ({}):", shipped.mission_file);
    match &cal.power {
        Ok(r) => {
            let _ = writeln!(
                s,
                "  fit error before (shipped params): RMS {:.2} W ({:.1} %)\n  fit error after (fitted):          RMS {:.2} W ({:.1} %)\n  over {} samples ({} on the ground), speeds {:.1}..{:.1} m/s, mean measured power {:.1} W",
                r.shipped_rms_w,
                pct(r.shipped_rms_w, r.mean_w),
                r.rms_w,
                pct(r.rms_w, r.mean_w),
                r.samples,
                r.ground_samples,
                r.v_min,
                r.v_max,
                r.mean_w
            );
            if let Some(c) = r.polynomial_w {
                let _ = writeln!(
                    s,
                    "  base.power_w {:.4} -> {:.4}\n  propulsion: rotary_wing -> polynomial, coefficients_w [{:.4}, 0, {:.6}, {:.6}] (P = c0 + c2 v² + c3 v³)",
                    shipped.power.base_w, r.fitted.base_w, c[0], c[2], c[3]
                );
                return finish_report(s, shipped, cal);
            }
            for ((name, before), (_, after)) in
                model_rows(&shipped.power).iter().zip(model_rows(&r.fitted))
            {
                let _ = writeln!(s, "  {name:<50} {before:>10.4} -> {after:>10.4}");
            }
            if r.v0_lower_bound_only {
                let _ = writeln!(s, "  note{}", v0_note(r));
            }
            let _ = writeln!(
                s,
                "  kept as shipped: propulsion.tip_speed_mps {}, propulsion.air_density_kgm3 {}",
                shipped.power.tip_speed_mps, shipped.power.air_density_kgm3
            );
        }
        Err(e) => {
            let _ = writeln!(s, "  not fitted: {e}");
        }
    }
    finish_report(s, shipped, cal)
}

/// The report's durations and BN rows.
fn finish_report(mut s: String, shipped: &Shipped, cal: &Calibration) -> String {
    super::write_legs::report(&mut s, cal);
    let _ = writeln!(
        s,
        "\nactivity durations (completed activities; reported, not written: a route's, not the vehicle's):"
    );
    if cal.durations.stats().is_empty() {
        let _ = writeln!(s, "  none: no record says which activity was in force");
    }
    for (name, d) in cal.durations.stats() {
        let (est, ia) = shipped
            .estimate_s
            .get(name)
            .map_or((f64::NAN, "-"), |(e, ia)| (*e, ia.as_str()));
        let name = escape_controls(name, false);
        let _ = writeln!(
            s,
            "  {name:<22} flown {:>8.1} s (sd {:.1}, {} run(s)); shipped estimate {est:.1} s (allocated IA {ia})",
            d.mean(),
            d.sd(),
            d.n
        );
    }
    let _ = writeln!(
        s,
        "\nBN rows learned (Dirichlet prior: the shipped row worth {PRIOR_PSEUDO_COUNTS} trials):"
    );
    if cal.rows.is_empty() {
        let _ = writeln!(
            s,
            "  none: no countable trial in the records (docs/calibrate.md)"
        );
    }
    for r in &cal.rows {
        let _ = writeln!(
            s,
            "  {}[{}]: P({}) {:.4} -> {:.4} ({:+.4}) from {}/{} successes",
            r.node,
            when_text(r),
            r.success_state,
            r.shipped,
            r.learned,
            r.learned - r.shipped,
            r.successes,
            r.trials
        );
    }
    s
}

fn when_text(r: &LearnedRow) -> String {
    r.when
        .iter()
        .map(|(p, st)| format!("{p}={st}"))
        .collect::<Vec<_>>()
        .join(",")
}

/// What an overlay is made of: the fits, not the runs' data, so that `companion-fleet
/// calibrate`, which has the same fits from SQL sums over its dataset, writes the same overlay
/// (docs/fleet.md).
pub struct OverlayParts<'a> {
    /// What made it (`companion calibrate`): the start of every `source`.
    pub made_by: &'a str,
    /// The runs' content ids (`runs::content_id`).
    pub run_ids: Vec<String>,
    pub power: Option<&'a FitResult>,
    pub legs: FittedLegs<'a>,
    pub rows: &'a [LearnedRow],
}

/// The overlay text of `cal`: `[calibration]` (what made it, the sources of entries that have
/// no `source` key of their own), then the fitted entries per params file.
pub fn overlay(shipped: &Shipped, cal: &Calibration, out: &Path) -> anyhow::Result<String> {
    // A run by its content, never by a path on the machine that made the overlay.
    let mut run_ids = Vec::new();
    for r in &cal.runs {
        run_ids.push(super::runs::content_id(r)?);
    }
    let parts = OverlayParts {
        made_by: "companion calibrate",
        run_ids,
        power: cal.power.as_ref().ok(),
        legs: FittedLegs::of(cal),
        rows: &cal.rows,
    };
    overlay_of(shipped, &parts, out)
}

/// The overlay text of `parts` (see [`overlay`]).
pub fn overlay_of(
    shipped: &Shipped,
    parts: &OverlayParts<'_>,
    out: &Path,
) -> anyhow::Result<String> {
    let made_by = parts.made_by;
    let runs = parts.run_ids.len();
    let mut t = Table::new();
    let mut sources = Table::new();
    let cal_t = table_at(&mut t, &["calibration"]);
    cal_t.insert("made_by".into(), Value::String(made_by.into()));
    let canon = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let base = canon(&shipped.dir);
    let out_dir = canon(
        out.parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new(".")),
    );
    let rel = relative(&out_dir, &base);
    cal_t.insert("params".into(), Value::String(rel));
    let ids = (parts.run_ids.iter()).map(|id| Value::String(id.clone()));
    cal_t.insert("runs".into(), Value::Array(ids.collect()));
    cal_t.insert(
        "prior_pseudo_counts".into(),
        Value::Float(PRIOR_PSEUDO_COUNTS),
    );
    let mf = shipped.mission_file.clone();
    if let Some(r) = parts.power {
        power_overlay(
            &mut t,
            &mf,
            r,
            Value::String(power_source(made_by, runs, r)),
        );
    }
    super::write_legs::overlay(&mut t, &mut sources, &mf, (&parts.legs, runs, made_by));
    let file = super::cpt::APPLICATIONS_FILE;
    let mut nodes: Vec<&str> = parts.rows.iter().map(|r| r.node.as_str()).collect();
    nodes.dedup();
    for node in nodes {
        let learned: Vec<&LearnedRow> = parts.rows.iter().filter(|r| r.node == node).collect();
        table_at(&mut t, &[file, "node", node]).insert(
            "override".into(),
            shipped.rows.overrides_with(node, &learned),
        );
        for r in learned {
            sources.insert(
                format!("{file}:node.{node}.override[{}]", when_text(r)),
                Value::String(format!(
                    "{made_by}: {}/{} successes in {runs} run(s), prior: the shipped row \
                     P({}) {:.4} worth {PRIOR_PSEUDO_COUNTS} trials",
                    r.successes, r.trials, r.success_state, r.shipped
                )),
            );
        }
    }
    table_at(&mut t, &["calibration"]).insert("sources".into(), Value::Table(sources));
    let body = toml::to_string(&t)?;
    // The name as a TOML string (escaped by the serializer): data, never TOML text.
    let name = Value::String(out.display().to_string()).to_string();
    Ok(format!(
        "# Params overlay written by `{made_by}` (docs/calibrate.md). Use it with\n\
         # `companion check|simulate|fly --params {name}`.\n\n{body}"
    ))
}

/// The power model's entries: `[<mission>.propulsion]` and `[<mission>.base]`, each with `src`.
fn power_overlay(t: &mut Table, mf: &str, r: &FitResult, src: Value) {
    let p = table_at(t, &[mf, "propulsion"]);
    if let Some(c) = r.polynomial_w {
        // A different model: the overlay's table replaces the shipped one whole.
        p.insert("model".into(), Value::String("polynomial".into()));
        let c: Vec<Value> = [round4(c[0]), Value::Float(0.0), round6(c[2]), round6(c[3])].to_vec();
        p.insert("coefficients_w".into(), Value::Array(c));
    } else {
        p.insert("blade_profile_w".into(), round4(r.fitted.blade_profile_w));
        p.insert("induced_hover_w".into(), round4(r.fitted.induced_hover_w));
        p.insert(
            "induced_velocity_mps".into(),
            round4(r.fitted.induced_velocity_mps),
        );
        p.insert("drag_area_m2".into(), round4(r.fitted.drag_area_m2));
    }
    p.insert("source".into(), src.clone());
    let b = table_at(t, &[mf, "base"]);
    b.insert("power_w".into(), round4(r.fitted.base_w));
    b.insert("source".into(), src);
}

/// `to` relative to `from` when it lies below it, else `to` as is (both absolute).
fn relative(from: &Path, to: &Path) -> String {
    let common = from
        .components()
        .zip(to.components())
        .take_while(|(a, b)| a == b)
        .count();
    // Sharing only the root: the absolute path survives moving the overlay better.
    if common <= 1 {
        return to.display().to_string();
    }
    let ups = from.components().count() - common;
    let mut p = std::path::PathBuf::new();
    for _ in 0..ups {
        p.push("..");
    }
    for c in to.components().skip(common) {
        p.push(c);
    }
    p.display().to_string().replace('\\', "/")
}
