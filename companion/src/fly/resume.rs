//! The proof that a flight found in progress is the companion's own and that its plan still
//! holds (params/link.toml `[flight] restart_in_air = "resume_with_consent"`, docs/mavlink.md
//! "Started in flight"). Each check is pure: facts in, the facts said in the record (proved) or
//! the reason it is not (a short one for the ground station, a full one for the record).
//!
//! The proof, in order: the latest run folder in `--log-dir` (read before this run's own
//! folder is made) has no clean end (the process died), its last record says the companion was
//! commanding ("started"), flying this same autopilot (`vehicle.autopilot`), with a verified
//! upload of the route, and is at most [`LOG_MAX_AGE`] old; the mission on the autopilot now,
//! downloaded, is item for item the route this run would upload; and the guarantee, judged on
//! the remaining activities with the battery now (a decision cycle after the flight was found),
//! fits.

use companion_core::record::{CommandOutcome, Event, GuaranteeRecord};
use companion_link::actions::Route;
use companion_link::mission::{MissionItem, compare_from};
use companion_link::modes::Flavor;
use std::path::Path;
use std::time::Duration;

/// The previous run's last record may be at most this old (a systemd restart takes seconds; an
/// older log belongs to a flight the companion has not watched for minutes).
pub(super) const LOG_MAX_AGE: Duration = Duration::from_secs(120);

/// How long the operator has to consent (MISSION_START) before the companion hands off.
pub(super) const CONSENT_WINDOW: Duration = Duration::from_secs(20);

/// How long the mission download and a judged guarantee may take before the companion gives up
/// on the proof and hands off.
pub(super) const PROOF_WAIT: Duration = Duration::from_secs(15);

/// Why a flight found in progress is not resumed.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct NotProved {
    /// A few words for the ground station (`not resumed: <short>`).
    pub(super) short: &'static str,
    /// The full reason, for the record and the journal.
    pub(super) why: String,
}

fn not(short: &'static str, why: impl Into<String>) -> NotProved {
    NotProved {
        short,
        why: why.into(),
    }
}

/// The previous run's decision log, as the proof reads it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PreviousRun {
    /// The run folder (escaped for display).
    pub folder: String,
    /// The log ended with its end line: the process stopped on its own.
    pub ended_cleanly: bool,
    /// The last record's wall clock (µs since the epoch).
    pub last_utc_us: Option<u64>,
    /// The autopilot it flew (`vehicle.autopilot`, `"1/1"`) in its last record that says.
    pub autopilot: Option<String>,
    /// The last record's `vehicle.operator` (`started` when it commanded).
    pub operator: Option<String>,
    /// A MISSION_UPLOAD of its route was verified.
    pub uploaded: bool,
    /// The last record's mission state.
    pub state: String,
}

/// The previous run in `log_dir`: the latest run folder by name (run folders are named by their
/// UTC start, `2026-11-28T13-08-32Z`, `-1` for a second in the same second). Read before this
/// run makes its own folder. An error says why there is none to read.
pub(super) fn read_previous_run(log_dir: &Path) -> Result<PreviousRun, String> {
    let shown = |p: &Path| crate::review::text::escape_controls(&p.display().to_string(), false);
    let entries =
        std::fs::read_dir(log_dir).map_err(|e| format!("cannot list {}: {e}", shown(log_dir)))?;
    let latest = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.join("decisions.jsonl").is_file())
        .max_by(|a, b| a.file_name().cmp(&b.file_name()))
        .ok_or_else(|| format!("no run folder in {}", shown(log_dir)))?;
    let log = crate::decision_log::read_log(&latest)
        .map_err(|e| format!("cannot read {}: {e}", shown(&latest)))?;
    let mut run = PreviousRun {
        folder: shown(&latest),
        ended_cleanly: log.ended_cleanly,
        ..Default::default()
    };
    let text = |r: &companion_core::record::DecisionRecord, key: &str| {
        r.vehicle
            .get(key)
            .and_then(|v| v.as_str())
            .map(str::to_string)
    };
    for r in &log.records {
        run.uploaded |= r.commands.iter().any(|c| {
            c.command == "MISSION_UPLOAD"
                && matches!(c.result, CommandOutcome::AcceptedVerified { .. })
        });
        // A run that resumed the flight flies the route its predecessor uploaded.
        run.uploaded |= r
            .events
            .iter()
            .any(|e| matches!(e, Event::ResumedInFlight { .. }));
        if let Some(a) = text(r, "autopilot") {
            run.autopilot = Some(a);
        }
    }
    if let Some(last) = log.records.last() {
        run.last_utc_us = last.utc_us;
        run.operator = text(last, "operator");
        run.state = last.state.clone();
    }
    Ok(run)
}

/// The log's part of the proof: the facts said when it holds.
pub(super) fn check_log(
    previous: Option<&Result<PreviousRun, String>>,
    autopilot: (u8, u8),
    now_utc_us: u64,
) -> Result<String, NotProved> {
    let run = match previous {
        None => return Err(not("no run log", "no run log was read (no --log-dir)")),
        Some(Err(e)) => return Err(not("no run log", format!("no run log to prove it: {e}"))),
        Some(Ok(run)) => run,
    };
    let f = &run.folder;
    if run.ended_cleanly {
        return Err(not(
            "last run ended",
            format!("the last run ({f}) ended cleanly: no companion died in this flight"),
        ));
    }
    let Some(last_us) = run.last_utc_us else {
        return Err(not(
            "empty log",
            format!("the last run ({f}) has no record"),
        ));
    };
    let age_s = now_utc_us.saturating_sub(last_us) as f64 / 1e6;
    if age_s > LOG_MAX_AGE.as_secs_f64() {
        return Err(not(
            "log too old",
            format!(
                "the last run's ({f}) last record is {age_s:.0} s old (more than {} s)",
                LOG_MAX_AGE.as_secs()
            ),
        ));
    }
    let ours = format!("{}/{}", autopilot.0, autopilot.1);
    match run.autopilot.as_deref() {
        Some(a) if a == ours => {}
        other => {
            return Err(not(
                "other autopilot",
                format!(
                    "the last run ({f}) flew autopilot {}, this is {ours}",
                    other.unwrap_or("unknown")
                ),
            ));
        }
    }
    if run.operator.as_deref() != Some("started") {
        return Err(not(
            "not commanding",
            format!(
                "the last run ({f}) was not commanding the vehicle when it ended (operator {})",
                run.operator.as_deref().unwrap_or("unknown")
            ),
        ));
    }
    if !run.uploaded {
        return Err(not(
            "no route uploaded",
            format!("the last run ({f}) uploaded no route"),
        ));
    }
    Ok(format!(
        "the last run ({f}) died {age_s:.0} s ago commanding autopilot {ours} with its route uploaded, in state {}",
        run.state
    ))
}

/// The mission on the autopilot against the route this run would upload. ArduPilot keeps home
/// at seq 0 (it moves when the vehicle arms, so it is not compared, and the route's relative
/// waypoints are placed from it); PX4 keeps none, and the home position placed them.
pub(super) fn check_mission(
    route: &Route,
    flavor: Flavor,
    home_at_seq0: bool,
    home: Option<(i32, i32)>,
    got: &[MissionItem],
) -> Result<String, NotProved> {
    let home = if home_at_seq0 {
        got.first().map(|h| (h.x, h.y))
    } else {
        home
    };
    let Some(home) = home else {
        return Err(not(
            "no home",
            "the mission cannot be compared: no home position",
        ));
    };
    let expected = route.mission_items(flavor, home);
    compare_from(&expected, got, usize::from(home_at_seq0))
        .map(|()| format!("the autopilot's mission is the route ({} items)", got.len()))
        .map_err(|e| {
            not(
                "mission changed",
                format!("the autopilot's mission is not the route: {e}"),
            )
        })
}

/// The guarantee of a decision cycle run after the flight was found, on the remaining
/// activities with the battery now: it must fit.
pub(super) fn check_plan(
    g: Option<&GuaranteeRecord>,
    battery_pct: Option<f64>,
) -> Result<String, NotProved> {
    let Some(g) = g else {
        return Err(not("no guarantee", "no guarantee was judged"));
    };
    let battery = battery_pct.map_or_else(|| "unknown".into(), |b| format!("{b:.0} %"));
    if g.infeasible {
        return Err(not(
            "plan does not fit",
            format!(
                "the guarantee does not fit the remaining activities with the battery at {battery}: {}",
                g.infeasible_reason.as_deref().unwrap_or("no allocation")
            ),
        ));
    }
    if let Some((goal, m)) = g.margins.iter().find(|(_, m)| **m < 0.0) {
        return Err(not(
            "plan does not fit",
            format!("the guarantee's {goal} margin is {m:.0} with the battery at {battery}"),
        ));
    }
    let margins: Vec<String> = g
        .margins
        .iter()
        .map(|(k, v)| format!("{k} {v:.0}"))
        .collect();
    Ok(format!(
        "the guarantee fits the remaining activities from {} with the battery at {battery} (margins {})",
        g.activity_name,
        margins.join(", ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run() -> PreviousRun {
        PreviousRun {
            folder: "runs/a".into(),
            ended_cleanly: false,
            last_utc_us: Some(1_000_000_000),
            autopilot: Some("1/1".into()),
            operator: Some("started".into()),
            uploaded: true,
            state: "wpi".into(),
        }
    }

    fn short(r: Result<String, NotProved>) -> &'static str {
        r.unwrap_err().short
    }

    #[test]
    fn the_log_proves_the_flight_only_when_every_fact_holds() {
        let now = 1_000_000_000 + 5_000_000;
        let ok = check_log(Some(&Ok(run())), (1, 1), now).unwrap();
        assert!(ok.contains("died 5 s ago") && ok.contains("1/1"), "{ok}");
        let with = |f: fn(&mut PreviousRun)| {
            let mut r = run();
            f(&mut r);
            check_log(Some(&Ok(r)), (1, 1), now)
        };
        assert_eq!(short(with(|r| r.ended_cleanly = true)), "last run ended");
        assert_eq!(
            short(with(|r| r.autopilot = Some("7/1".into()))),
            "other autopilot"
        );
        assert_eq!(
            short(with(|r| r.operator = Some("taken_over".into()))),
            "not commanding"
        );
        assert_eq!(short(with(|r| r.uploaded = false)), "no route uploaded");
        assert_eq!(short(with(|r| r.last_utc_us = None)), "empty log");
        let old = check_log(Some(&Ok(run())), (1, 1), 1_000_000_000 + 121_000_000);
        assert!(
            old.clone().unwrap_err().why.contains("121 s old"),
            "{old:?}"
        );
        assert_eq!(
            short(check_log(Some(&Ok(run())), (2, 1), now)),
            "other autopilot"
        );
        assert_eq!(short(check_log(None, (1, 1), now)), "no run log");
        assert_eq!(
            short(check_log(Some(&Err("x".into())), (1, 1), now)),
            "no run log"
        );
    }

    #[test]
    fn the_plan_must_fit_with_every_margin_non_negative() {
        let mut g = GuaranteeRecord {
            activity_name: "search".into(),
            ..Default::default()
        };
        g.margins.insert("energy_j".into(), 5000.0);
        assert!(check_plan(Some(&g), Some(60.0)).unwrap().contains("60 %"));
        g.margins.insert("duration_s".into(), -3.0);
        assert_eq!(short(check_plan(Some(&g), Some(60.0))), "plan does not fit");
        g.margins.clear();
        g.infeasible = true;
        assert_eq!(short(check_plan(Some(&g), None)), "plan does not fit");
        assert_eq!(short(check_plan(None, None)), "no guarantee");
    }

    /// The latest run folder by name is read; a killed one has no clean end; the facts are
    /// the last record's (operator, state, time) and any record's autopilot and verified upload.
    #[test]
    fn the_previous_run_is_the_latest_folder_read_as_it_ended() {
        use crate::decision_log::{DecisionLog, Header, WriterOptions};
        use companion_core::record::{CommandRecord, DecisionRecord};
        let base = std::env::temp_dir().join(format!("h8-previous-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        assert!(
            read_previous_run(&base)
                .unwrap_err()
                .contains("cannot list")
        );
        std::fs::create_dir_all(&base).unwrap();
        assert!(
            read_previous_run(&base)
                .unwrap_err()
                .contains("no run folder")
        );
        let write = |name: &str, killed: bool| {
            let dir = base.join(name);
            std::fs::create_dir_all(&dir).unwrap();
            let header = Header::new("fly", std::time::SystemTime::now());
            let log = DecisionLog::start(&dir, header, WriterOptions::default()).unwrap();
            let mut first = DecisionRecord::default();
            first.vehicle.insert("autopilot".into(), "1/1".into());
            first.commands.push(CommandRecord {
                action: "follow_trajectory".into(),
                command: "MISSION_UPLOAD".into(),
                result: CommandOutcome::AcceptedVerified { items: 8 },
                attempts: 1,
                latency_ms: None,
            });
            log.record(first);
            let mut last = DecisionRecord {
                cycle: 2,
                state: "wpi".into(),
                utc_us: Some(42),
                ..Default::default()
            };
            last.vehicle.insert("operator".into(), "started".into());
            log.record(last);
            log.close();
            if killed {
                let path = dir.join("decisions.jsonl");
                let text = std::fs::read_to_string(&path).unwrap();
                let kept: Vec<&str> = text
                    .lines()
                    .filter(|l| l.contains("\"cycle\"") || l.contains("schema"))
                    .collect();
                std::fs::write(&path, kept.join("\n") + "\n").unwrap();
            }
        };
        write("2026-11-28T13-00-00Z", false);
        write("2026-11-28T13-05-00Z", true);
        let run = read_previous_run(&base).unwrap();
        assert!(run.folder.ends_with("2026-11-28T13-05-00Z"), "{run:?}");
        assert!(!run.ended_cleanly);
        assert_eq!(run.autopilot.as_deref(), Some("1/1"));
        assert_eq!(run.operator.as_deref(), Some("started"));
        assert!(run.uploaded);
        assert_eq!((run.last_utc_us, run.state.as_str()), (Some(42), "wpi"));
        write("2026-11-28T13-05-00Z-1", false);
        assert!(read_previous_run(&base).unwrap().ended_cleanly);
        let _ = std::fs::remove_dir_all(&base);
    }

    /// The autopilot's mission is the route only item for item (ArduPilot's home at seq 0
    /// placing it); another mission, or no home to place it (PX4), is no proof.
    #[test]
    fn the_mission_is_compared_item_for_item_with_the_route() {
        let args = crate::fly::FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550"]).unwrap();
        let setup = crate::fly::FlySetup::load(&args).unwrap();
        let home = (-353_632_610, 1_491_652_300);
        let items = setup.route.mission_items(Flavor::ArduPilot, home);
        let ok = check_mission(&setup.route, Flavor::ArduPilot, true, None, &items).unwrap();
        assert!(ok.contains("is the route"), "{ok}");
        let mut moved = items.clone();
        moved[2].x += 1000;
        assert_eq!(
            check_mission(&setup.route, Flavor::ArduPilot, true, None, &moved)
                .unwrap_err()
                .short,
            "mission changed"
        );
        let shorter = &items[..items.len() - 1];
        assert_eq!(
            check_mission(&setup.route, Flavor::ArduPilot, true, None, shorter)
                .unwrap_err()
                .short,
            "mission changed"
        );
        let px4 = setup.route.mission_items(Flavor::Px4, home);
        assert_eq!(
            check_mission(&setup.route, Flavor::Px4, false, None, &px4)
                .unwrap_err()
                .short,
            "no home"
        );
        assert!(check_mission(&setup.route, Flavor::Px4, false, Some(home), &px4).is_ok());
    }
}
