//! `review --summary` tells how the flight ended (issue 22 item 7): landed and disarmed (where,
//! how far from home), the log ending with the vehicle armed (altitude, mode), or taken over (by
//! which mode); `in progress` counts only commands unresolved at the end of the log; the final
//! margins are the flight's own, not the next flight's first record's. Synthetic fly logs.

use companion::decision_log::LogItem;
use companion::review::{Review, outcomes::Category, render_terminal};
use companion_core::record::{CommandRecord, DecisionRecord, GuaranteeRecord};

const HOME: (f64, f64) = (47.397742, 8.545594);
/// Degrees of latitude per metre north (mean Earth radius 6,371,008.8 m).
const DEG_PER_M: f64 = 180.0 / (std::f64::consts::PI * 6_371_008.8);

struct Rec {
    armed: bool,
    mode: &'static str,
    alt: f64,
    north_m: f64,
    operator: &'static str,
    margin: Option<f64>,
    commands: Vec<(&'static str, &'static str)>,
}

fn rec(cycle: u64, x: &Rec) -> LogItem {
    let mut r = DecisionRecord {
        cycle,
        time_s: cycle as f64,
        state: if x.armed { "wpi".into() } else { "base".into() },
        ..Default::default()
    };
    let v = &mut r.vehicle;
    v.insert("armed".into(), x.armed.into());
    v.insert("mode".into(), x.mode.into());
    v.insert("altitude_m".into(), x.alt.into());
    v.insert("lat_deg".into(), (HOME.0 + x.north_m * DEG_PER_M).into());
    v.insert("lon_deg".into(), HOME.1.into());
    v.insert("operator".into(), x.operator.into());
    if let Some(m) = x.margin {
        let mut g = GuaranteeRecord::default();
        g.margins.insert("energy_j".into(), m);
        r.guarantee = Some(g);
    }
    for (command, result) in &x.commands {
        r.commands.push(CommandRecord {
            action: "take_off".into(),
            command: (*command).into(),
            result: companion::decision_log::migration::outcome(result),
            ..Default::default()
        });
    }
    LogItem::Record(Box::new(r), Vec::new())
}

fn ground(north_m: f64, margin: f64) -> Rec {
    Rec {
        armed: false,
        mode: "GUIDED",
        alt: 0.0,
        north_m,
        operator: "waiting",
        margin: Some(margin),
        commands: vec![],
    }
}

fn air(north_m: f64, alt: f64, mode: &'static str, margin: f64) -> Rec {
    Rec {
        armed: true,
        mode,
        alt,
        north_m,
        operator: "started",
        margin: Some(margin),
        commands: vec![],
    }
}

fn review(recs: Vec<Rec>) -> Review {
    let items = recs.iter().enumerate().map(|(i, r)| rec(i as u64, r));
    let mut items: Vec<LogItem> = items.collect();
    items.push(LogItem::End);
    Review::from_items(items, None)
}

#[test]
fn a_normal_flight_landed_and_disarmed_120_m_from_home() {
    let mut recs = vec![ground(0.0, 900.0), ground(0.0, 900.0)];
    let mut first = air(0.0, 1.0, "GUIDED", 800.0);
    first.commands = vec![("MAV_CMD_NAV_TAKEOFF", "SENT")];
    recs.push(first);
    let mut second = air(40.0, 20.0, "AUTO", 600.0);
    // The take-off that was in progress completed: not "in progress" at the end.
    second.commands = vec![("MAV_CMD_NAV_TAKEOFF", "ACCEPTED")];
    recs.push(second);
    recs.push(air(120.0, 5.0, "LAND", 400.0));
    let mut landed = ground(120.0, 350.0);
    landed.mode = "LAND";
    recs.push(landed);
    // The next flight's first record on the ground: fresh guarantee, not this flight's margin.
    recs.push(ground(120.0, 5000.0));
    let rev = review(recs);
    let out = &rev.summary.outcome;
    assert!(out.starts_with("landed and disarmed at 47."), "{out}");
    assert!(out.contains("120 m from home"), "{out}");
    assert_eq!(rev.summary.final_margins["energy_j"].margin, 350.0);
    let o = &rev.summary.outcomes;
    assert_eq!(o.get(Category::InProgress), 0, "{}", o.describe());
    assert_eq!(o.get(Category::Accepted), 1);
    let text = render_terminal(&rev, false);
    assert!(text.contains("120 m from home"), "{text}");
}

#[test]
fn a_log_that_ends_armed_in_the_air_says_so_with_altitude_and_mode() {
    let mut last = air(300.0, 20.0, "AUTO", 100.0);
    // Sent and never answered before the log ended: in progress.
    last.commands = vec![("MAV_CMD_DO_SET_MODE", "SENT")];
    let rev = review(vec![
        ground(0.0, 900.0),
        air(100.0, 20.0, "AUTO", 300.0),
        last,
    ]);
    let out = &rev.summary.outcome;
    assert!(
        out.starts_with("log ended with the vehicle armed at 20.0 m in AUTO at 47."),
        "{out}"
    );
    assert!(out.contains("300 m from home"), "{out}");
    assert_eq!(rev.summary.outcomes.get(Category::InProgress), 1);
    assert_eq!(rev.summary.final_margins["energy_j"].margin, 100.0);
}

#[test]
fn a_takeover_names_the_pilots_mode() {
    let mut taken = air(50.0, 15.0, "LOITER", 200.0);
    taken.operator = "taken_over";
    let rev = review(vec![
        ground(0.0, 900.0),
        air(20.0, 15.0, "AUTO", 300.0),
        taken,
    ]);
    let out = &rev.summary.outcome;
    assert!(
        out.starts_with("taken over by the pilot (mode LOITER); log ended with the vehicle armed at 15.0 m in LOITER"),
        "{out}"
    );
}

/// A companion started next to a flight in progress (fly/restart.rs): the summary begins with
/// what it did, handed off (and why it did not resume) or resumed (and the proof's facts).
#[test]
fn a_flight_found_in_progress_says_handed_off_or_resumed() {
    let with_event = |event: &str, operator: &'static str| {
        let mut first = air(100.0, 20.0, "AUTO", 300.0);
        first.operator = operator;
        let mut items = vec![rec(0, &first)];
        if let LogItem::Record(r, _) = &mut items[0] {
            r.events
                .push(companion::decision_log::migration::event(event));
        }
        let mut landed = ground(0.0, 200.0);
        landed.mode = "RTL";
        items.push(rec(1, &air(50.0, 10.0, "RTL", 250.0)));
        items.push(rec(2, &landed));
        items.push(LogItem::End);
        Review::from_items(items, None).summary.outcome
    };
    let out = with_event(
        "started in flight: the vehicle is armed, landed state IN_AIR, altitude 20.0 m above home, mode AUTO; handed off: hand-off RTL (params/link.toml [flight] handoff); not resumed: no MISSION_START from the operator within 20 s; no start until it is landed and disarmed",
        "flight_in_progress",
    );
    assert!(
        out.starts_with(
            "started in flight, handed off (no MISSION_START from the operator within 20 s); landed and disarmed"
        ),
        "{out}"
    );
    let out = with_event(
        "started in flight: resumed on the operator's consent (MISSION_START from 255/190): the vehicle is armed, landed state IN_AIR, altitude 20.0 m above home, mode AUTO; the last run died 3 s ago; the guarantee fits",
        "started",
    );
    assert!(
        out.starts_with("started in flight, resumed on the operator's consent (the last run died 3 s ago; the guarantee fits); landed and disarmed"),
        "{out}"
    );
    let out = with_event(
        "started in flight: the vehicle is armed, ...; handed off: hand-off RTL (params/link.toml [flight] handoff); not resumed: params/link.toml [flight] restart_in_air = \"handoff\" (the default); no start until it is landed and disarmed",
        "flight_in_progress",
    );
    assert!(
        out.starts_with("started in flight, handed off (params/link.toml [flight] restart_in_air = \"handoff\" (the default)); landed"),
        "{out}"
    );
    // The proof under way says neither.
    let out = with_event(
        "started in flight: the vehicle is armed, ...; checking whether it is the companion's own flight to resume (restart_in_air = resume_with_consent)",
        "flight_in_progress",
    );
    assert!(out.starts_with("landed and disarmed"), "{out}");
}
