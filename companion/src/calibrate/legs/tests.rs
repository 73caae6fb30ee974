use super::*;
use companion_link::dialect::*;

/// A vehicle flown by hand at 5 Hz on the autopilot's clock: what it sends, in order.
struct Sim {
    t: f64,
    north: f64,
    east: f64,
    alt: f64,
    armed: bool,
    mode: u32,
    out: Vec<Msg>,
}

const HOME: (f64, f64) = (-35.363261, 149.165230);

impl Sim {
    fn new() -> Self {
        let mut s = Sim {
            t: 100.0,
            north: 0.0,
            east: 0.0,
            alt: 0.0,
            armed: false,
            mode: 4,
            out: vec![],
        };
        s.heartbeat();
        s.position();
        s
    }

    fn position(&mut self) {
        let p = Position::offset(HOME, self.north, self.east, self.alt);
        self.out
            .push(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                time_boot_ms: (self.t * 1000.0).round() as u32,
                lat: (p.lat_deg * 1e7).round() as i32,
                lon: (p.lon_deg * 1e7).round() as i32,
                relative_alt: (self.alt * 1000.0).round() as i32,
                ..GLOBAL_POSITION_INT_DATA::DEFAULT
            }));
    }

    fn heartbeat(&mut self) {
        let mut base = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
        if self.armed {
            base |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        self.out.push(Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: self.mode,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: base,
            ..HEARTBEAT_DATA::DEFAULT
        }));
    }

    /// Hold still for `s` seconds.
    fn wait(&mut self, s: f64) {
        self.go(0.0, 0.0, 0.0, s);
    }

    /// Move by (dn, de, dalt) at a constant rate over `s` seconds, sampled at 5 Hz.
    fn go(&mut self, dn: f64, de: f64, dalt: f64, s: f64) {
        let steps = (s * 5.0).round().max(1.0) as usize;
        for _ in 0..steps {
            self.t += s / steps as f64;
            self.north += dn / steps as f64;
            self.east += de / steps as f64;
            self.alt += dalt / steps as f64;
            self.position();
        }
        self.heartbeat();
    }

    fn arm(&mut self, armed: bool) {
        self.armed = armed;
        self.heartbeat();
    }

    fn send(&mut self, m: Msg) {
        self.out.push(m);
    }
}

fn item(seq: u16, command: MavCmd, param2: f32) -> Msg {
    Msg::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
        seq,
        command,
        param2,
        ..MISSION_ITEM_INT_DATA::DEFAULT
    })
}

fn reached(seq: u16) -> Msg {
    Msg::MISSION_ITEM_REACHED(MISSION_ITEM_REACHED_DATA { seq })
}

fn current(seq: u16) -> Msg {
    Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
        seq,
        ..MISSION_CURRENT_DATA::DEFAULT
    })
}

/// The default route's shape (50, 150, 100, 150 m legs at 20 m) flown by a vehicle that climbs at
/// 2 m/s, flies legs at `v` m/s with `overhead` s per waypoint, and lands at 1 m/s; the mission
/// as the autopilot holds it (`items`). PX4 repeats MISSION_ITEM_REACHED: `repeat` times.
fn flight(v: f64, overhead: f64, items: &[Msg], repeat: usize) -> Vec<Msg> {
    flight_held(v, overhead, items, repeat, 0.0)
}

/// [`flight`], holding `hold` s at each waypoint after its MISSION_ITEM_REACHED before the next
/// becomes current.
fn flight_held(v: f64, overhead: f64, items: &[Msg], repeat: usize, hold: f64) -> Vec<Msg> {
    let mut s = Sim::new();
    s.send(Msg::MISSION_COUNT(MISSION_COUNT_DATA::DEFAULT));
    for i in items {
        s.send(i.clone());
    }
    s.wait(30.0); // on the ground, disarmed: not the climb
    s.arm(true);
    s.wait(2.0); // spin-up
    s.go(0.0, 0.0, 20.0, 10.0);
    s.wait(1.0);
    s.send(reached(1)); // take-off item, at altitude
    let legs = [(50.0, 0.0), (150.0, 0.0), (0.0, 100.0), (-150.0, 0.0)];
    for (k, (dn, de)) in legs.iter().enumerate() {
        let seq = 2 + k as u16;
        if k > 0 {
            s.wait(hold);
        }
        s.send(current(seq));
        s.go(*dn, *de, 0.0, f64::hypot(*dn, *de) / v);
        s.wait(overhead);
        for _ in 0..repeat {
            s.send(reached(seq));
        }
    }
    s.send(current(6));
    s.wait(60.0); // the search held at the last waypoint
    s.send(reached(6)); // a loiter at its waypoint: not a leg
    s.go(0.0, 0.0, -20.0, 20.0);
    s.wait(2.0);
    s.arm(false);
    s.out
}

fn mission(speed_item: Option<f32>) -> Vec<Msg> {
    let mut v = vec![
        item(0, MavCmd::MAV_CMD_NAV_WAYPOINT, 0.0),
        item(1, MavCmd::MAV_CMD_NAV_TAKEOFF, 0.0),
    ];
    for seq in 2..6 {
        v.push(item(seq, MavCmd::MAV_CMD_NAV_WAYPOINT, 0.0));
    }
    v.push(item(6, MavCmd::MAV_CMD_NAV_LOITER_TIME, 0.0));
    if let Some(s) = speed_item {
        // In front: a DO_CHANGE_SPEED at seq 1 would be the take-off's slot, so shift it in.
        v[1] = item(1, MavCmd::MAV_CMD_DO_CHANGE_SPEED, s);
    }
    v
}

fn read(msgs: &[Msg], fallback: f64) -> LegFlights {
    let mut f = LegFlights::new(Some((fallback, "params".into())));
    f.start_run();
    for m in msgs {
        f.on_message(m);
    }
    f
}

#[test]
fn legs_climb_and_descent_of_a_flight_are_measured_on_the_autopilots_clock() {
    let f = read(&flight(10.0, 3.0, &mission(None), 1), 10.0);
    let lengths: Vec<f64> = f.legs.iter().map(|l| l.length_m).collect();
    assert_eq!(lengths.len(), 4, "{:?}", f.legs);
    for (l, want) in lengths.iter().zip([50.0, 150.0, 100.0, 150.0]) {
        assert!((l - want).abs() < 0.5, "{lengths:?}");
    }
    for (l, want) in f.legs.iter().zip([8.0, 18.0, 13.0, 18.0]) {
        assert!((l.duration_s - want).abs() < 0.25, "{:?}", f.legs);
        assert_eq!(l.source, SpeedSource::Fallback);
    }
    // Arming to 95 % of 20 m: 2 s of spin-up and 9.5 s of the 10 s climb.
    assert_eq!(f.climbs.len(), 1);
    assert!(
        (f.climbs[0].duration_s - 11.5).abs() < 0.25,
        "{:?}",
        f.climbs
    );
    // Leaving the search altitude (below it by the tolerance: 19 m, 1 s into the descent) to the
    // disarm: 19 s down and 2 s on the ground; planned for 20 m at that rate, 22 s as flown.
    assert_eq!(f.descents.len(), 1);
    let d = f.descents[0];
    assert!((d.duration_s - 21.0).abs() < 0.3, "{d:?}");
    assert!(
        (20.0 / (d.height_m / d.duration_s) - 22.0).abs() < 0.5,
        "{d:?}"
    );
    let m = fit_legs(&f.legs).unwrap();
    assert!((m.overhead_s - 3.0).abs() < 0.2, "{m:?}");
    assert_eq!(m.speed_fraction, None, "{m:?}");
    assert!(m.rms_s < 0.2 && m.rms_before_s > 2.5, "{m:?}");
}

#[test]
fn a_vehicle_slower_than_commanded_gets_a_speed_fraction() {
    // Commanded 10 m/s (the fallback), flown at 5: the legs' time doubles with their length.
    let f = read(&flight(5.0, 2.0, &mission(None), 11), 10.0);
    assert_eq!(
        f.legs.len(),
        4,
        "PX4's repeated REACHED count once: {:?}",
        f.legs
    );
    let m = fit_legs(&f.legs).unwrap();
    let fr = m.speed_fraction.expect("not reached");
    assert!((fr - 0.5).abs() < 0.02, "{m:?}");
    assert!((m.overhead_s - 2.0).abs() < 0.3, "{m:?}");
}

#[test]
fn the_missions_speed_item_and_the_autopilots_cruise_parameter_come_before_the_fallback() {
    // The mission says 5 m/s and the vehicle flies 5: reached, whatever the fallback says.
    let f = read(&flight(5.0, 2.0, &mission(Some(5.0)), 1), 10.0);
    assert!(
        f.legs
            .iter()
            .all(|l| l.commanded_mps == 5.0 && l.source == SpeedSource::MissionItem),
        "{:?}",
        f.legs
    );
    assert_eq!(fit_legs(&f.legs).unwrap().speed_fraction, None);
    let mut msgs = vec![Msg::PARAM_VALUE(PARAM_VALUE_DATA {
        param_id: "MPC_XY_CRUISE".into(),
        param_value: 5.0,
        ..PARAM_VALUE_DATA::DEFAULT
    })];
    msgs.extend(flight(5.0, 2.0, &mission(None), 1));
    let f = read(&msgs, 10.0);
    assert!(
        f.legs
            .iter()
            .all(|l| l.commanded_mps == 5.0 && l.source == SpeedSource::AutopilotParam)
    );
}

#[test]
fn a_leg_flown_across_a_mode_change_or_without_the_mission_is_not_counted() {
    let mut msgs = flight(10.0, 3.0, &mission(None), 1);
    // The operator switches mode during the second leg: find its MISSION_CURRENT and put a
    // heartbeat of another mode after the next position.
    let at = msgs
        .iter()
        .position(|m| matches!(m, Msg::MISSION_CURRENT(c) if c.seq == 3))
        .unwrap();
    let mut hb = HEARTBEAT_DATA {
        custom_mode: 5,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
        ..HEARTBEAT_DATA::DEFAULT
    };
    msgs.insert(at + 3, Msg::HEARTBEAT(hb.clone()));
    hb.custom_mode = 4;
    msgs.insert(at + 5, Msg::HEARTBEAT(hb));
    let f = read(&msgs, 10.0);
    assert_eq!(f.legs.len(), 3, "{:?}", f.legs);
    // No mission items in the tlog: nothing says which reached item is a waypoint.
    let f = read(&flight(10.0, 3.0, &[], 1), 10.0);
    assert!(f.legs.is_empty());
    assert_eq!(
        fit_legs(&f.legs),
        Err(LegFitError::TooFew(0)),
        "refused, not fitted from nothing"
    );
}

#[test]
fn rates_weigh_each_flight_by_its_time() {
    let v = [
        Vertical {
            height_m: 20.0,
            duration_s: 10.0,
        },
        Vertical {
            height_m: 20.0,
            duration_s: 30.0,
        },
    ];
    let (r, rms) = rate(&v).unwrap();
    assert!((r - 1.0).abs() < 1e-12);
    assert!((rms - 10.0).abs() < 1e-9);
    assert_eq!(rate(&[]), None);
}

#[test]
fn the_streams_late_mission_current_does_not_shorten_a_leg_and_a_hold_is_no_leg_time() {
    // ArduCopter's MISSION_CURRENT comes up to a second after the MISSION_ITEM_REACHED: move each
    // four positions (0.8 s) later; the legs keep their time.
    let mut msgs = flight(10.0, 3.0, &mission(None), 1);
    let mut i = 0;
    while i < msgs.len() {
        if matches!(msgs[i], Msg::MISSION_CURRENT(_)) {
            let m = msgs.remove(i);
            let mut at = i;
            let mut seen = 0;
            while at < msgs.len() && seen < 4 {
                if matches!(msgs[at], Msg::GLOBAL_POSITION_INT(_)) {
                    seen += 1;
                }
                at += 1;
            }
            msgs.insert(at, m);
            i = at + 1;
        } else {
            i += 1;
        }
    }
    let f = read(&msgs, 10.0);
    for (l, want) in f.legs.iter().zip([8.0, 18.0, 13.0, 18.0]) {
        assert!((l.duration_s - want).abs() < 0.25, "{:?}", f.legs);
    }
    // A 10 s hold at each waypoint before the next leg: the leg starts when it becomes current.
    let f = read(&flight_held(10.0, 3.0, &mission(None), 1, 10.0), 10.0);
    assert_eq!(f.legs.len(), 4);
    for (l, want) in f.legs.iter().zip([8.0, 18.0, 13.0, 18.0]) {
        assert!((l.duration_s - want).abs() < 0.25, "{:?}", f.legs);
    }
}

#[test]
fn a_landing_whose_altitude_estimate_drifted_counts_and_a_disarm_in_the_air_does_not() {
    // Landed with the estimate at 1.3 m (PX4 SIH after one landing): a descent.
    let mut s = Sim::new();
    s.out.extend(mission(None));
    s.arm(true);
    s.go(0.0, 0.0, 20.0, 10.0);
    s.send(reached(1));
    s.send(current(2));
    s.go(100.0, 0.0, 0.0, 10.0);
    s.send(reached(2));
    s.go(0.0, 0.0, -18.7, 20.0);
    s.arm(false);
    let f = read(&s.out, 10.0);
    assert_eq!(f.descents.len(), 1, "{f:?}");
    // Disarmed at 10 m (a failsafe): no landing.
    let mut s = Sim::new();
    s.out.extend(mission(None));
    s.arm(true);
    s.go(0.0, 0.0, 20.0, 10.0);
    s.send(reached(1));
    s.send(current(2));
    s.go(100.0, 0.0, 0.0, 10.0);
    s.send(reached(2));
    s.go(0.0, 0.0, -10.0, 10.0);
    s.arm(false);
    assert!(read(&s.out, 10.0).descents.is_empty());
}

/// The MAV_CMD numbers the planner and calibrate share (companion-core has no `mavlink`) are
/// mavlink's.
#[test]
fn the_shared_mav_cmd_numbers_are_mavlinks() {
    use companion_core::route_plan::mav_cmd as n;
    use companion_link::dialect::MavCmd as C;
    for (k, c) in [
        (n::NAV_WAYPOINT, C::MAV_CMD_NAV_WAYPOINT),
        (n::NAV_LOITER_UNLIM, C::MAV_CMD_NAV_LOITER_UNLIM),
        (n::NAV_LOITER_TURNS, C::MAV_CMD_NAV_LOITER_TURNS),
        (n::NAV_LOITER_TIME, C::MAV_CMD_NAV_LOITER_TIME),
        (n::NAV_RETURN_TO_LAUNCH, C::MAV_CMD_NAV_RETURN_TO_LAUNCH),
        (n::NAV_LAND, C::MAV_CMD_NAV_LAND),
        (n::NAV_TAKEOFF, C::MAV_CMD_NAV_TAKEOFF),
        (n::DO_CHANGE_SPEED, C::MAV_CMD_DO_CHANGE_SPEED),
    ] {
        assert_eq!(k, c as u16, "{c:?}");
    }
}
