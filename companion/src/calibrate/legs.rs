//! How the vehicle flies a leg, climbs and descends (docs/calibrate.md, "How the vehicle flies"),
//! from the autopilot's own messages in a run's `flight.tlog`: never a route's length or an
//! activity's hold, which belong to the route flown, not to the vehicle.
//!
//! Read, all of them sent by ArduCopter and PX4 alike: GLOBAL_POSITION_INT (position, altitude
//! above home, and its `time_boot_ms`: the autopilot's clock, which a SITL's speed-up does not
//! bend as it does the tlog's wall-clock stamps), HEARTBEAT (armed, mode), MISSION_COUNT and
//! MISSION_ITEM_INT (the mission on the autopilot, as the companion's check downloads it),
//! MISSION_CURRENT, MISSION_ITEM_REACHED and PARAM_VALUE (`WPNAV_SPEED`, `MPC_XY_CRUISE`).
//!
//! - **A leg**: from one MISSION_ITEM_REACHED (or the MISSION_CURRENT naming the leg's waypoint,
//!   when it comes more than the stream's lag later: a hold at the last waypoint) to the MISSION_ITEM_REACHED of a NAV_WAYPOINT at least [`MIN_LEG_M`] away, armed,
//!   in one flight mode throughout. Its length is measured as the derivation counts it
//!   (`route_plan::leg_length_m`: geodesic plus climb) between the positions at the two events; its
//!   commanded speed is the mission's last DO_CHANGE_SPEED before it, else the autopilot's cruise
//!   parameter in the tlog, else the fallback calibrate is given (its source said).
//! - **The climb**: from arming to reaching 95 % of the altitude the first leg starts at.
//! - **The descent**: from the last time the vehicle was within [`ALT_TOLERANCE_M`] of the
//!   altitude of its last waypoint (a search held there, the return at that altitude) to the
//!   disarm after landing.
//!
//! The leg model: `t = a L / v_cmd + c`, least squares over the legs (closed form); `c` is the
//! time a waypoint costs besides its length (accelerating, braking, turning) and `1 / a` the
//! fraction of the commanded speed reached.

use companion_core::route_plan::{Position, leg_length_m};
use companion_link::Msg;
use std::collections::BTreeMap;

/// Shorter moves between two reached items are not legs (a loiter at its waypoint, a take-off
/// item reached over home).
pub const MIN_LEG_M: f64 = 10.0;
/// Fewest legs for the leg model; with fewer, nothing about legs is written.
pub const MIN_LEGS: usize = 3;
/// Altitude within this of the last waypoint's is still at cruise altitude (m).
pub const ALT_TOLERANCE_M: f64 = 1.0;
/// A MISSION_CURRENT this long (s) after the last MISSION_ITEM_REACHED says the vehicle held
/// there; sooner, it is the stream's lag (ArduCopter: up to 1 s).
const CURRENT_STREAM_SLACK_S: f64 = 2.0;
/// Disarmed below this altitude above home is landed (m): PX4 SIH's estimate read 1.3 m after one
/// landing (baro drift); a disarm higher up (a failsafe) is no descent.
const LANDED_ALT_M: f64 = 2.5;
/// A climb or descent of less than this is no take-off or landing (m).
const MIN_VERTICAL_M: f64 = 2.0;
use companion_core::route_plan::mav_cmd::{DO_CHANGE_SPEED, NAV_WAYPOINT};
/// Take-off samples kept per flight (about 30 min at 5 Hz): the climb is found in them.
const MAX_CLIMB_SAMPLES: usize = 10_000;

/// Where a leg's commanded speed came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum SpeedSource {
    /// A DO_CHANGE_SPEED item of the mission.
    MissionItem,
    /// The autopilot's cruise parameter (PARAM_VALUE in the tlog).
    AutopilotParam,
    /// The fallback calibrate was given (`--cruise-speed-mps`, else the params' `[derive]`).
    Fallback,
}

/// One leg flown.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Leg {
    pub length_m: f64,
    pub duration_s: f64,
    pub commanded_mps: f64,
    pub source: SpeedSource,
}

/// A climb or a descent: height (m) over time (s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vertical {
    pub height_m: f64,
    pub duration_s: f64,
}

/// Legs, climbs and descents of every run, read one autopilot message at a time.
#[derive(Debug, Default)]
pub struct LegFlights {
    pub legs: Vec<Leg>,
    pub climbs: Vec<Vertical>,
    pub descents: Vec<Vertical>,
    /// The fallback commanded speed and its words (`params [derive].cruise_speed_mps`).
    fallback: Option<(f64, String)>,
    run: RunState,
}

#[derive(Debug, Default)]
struct RunState {
    t_s: Option<f64>,
    pos: Option<Position>,
    armed: bool,
    /// HEARTBEAT base mode (armed flag left out) and custom mode, and when it last changed.
    mode: Option<(u8, u32)>,
    mode_since: f64,
    items: BTreeMap<u16, (u16, f32)>,
    cruise_param: Option<f64>,
    current: Option<(u16, f64, Option<Position>)>,
    last_reached: Option<u16>,
    /// The previous event a leg starts from: time, position.
    from: Option<(f64, Position)>,
    flight: Option<Flight>,
}

/// One flight: arming to disarming.
#[derive(Debug, Default)]
struct Flight {
    armed_at: f64,
    climb: Vec<(f64, f64)>,
    climbed: bool,
    /// Altitude of the last waypoint reached, and the last time (and altitude) the vehicle was
    /// within the tolerance of it.
    cruise_alt: Option<f64>,
    at_cruise: Option<(f64, f64)>,
}

impl LegFlights {
    /// `fallback`: the commanded speed of legs whose run gives none (m/s) and where it is from.
    pub fn new(fallback: Option<(f64, String)>) -> Self {
        Self {
            fallback,
            ..Default::default()
        }
    }

    /// The fallback's words, for the report and the sources.
    pub fn fallback(&self) -> Option<&(f64, String)> {
        self.fallback.as_ref()
    }

    /// A new run (tlog) begins: nothing of the last carries over.
    pub fn start_run(&mut self) {
        self.run = RunState::default();
    }

    /// One message of the autopilot (only the autopilot's: the tlog reader filters).
    pub fn on_message(&mut self, msg: &Msg) {
        match msg {
            Msg::GLOBAL_POSITION_INT(p) => self.on_position(
                p.time_boot_ms as f64 / 1000.0,
                Position {
                    lat_deg: p.lat as f64 / 1e7,
                    lon_deg: p.lon as f64 / 1e7,
                    alt_m: p.relative_alt as f64 / 1000.0,
                },
            ),
            Msg::HEARTBEAT(h) => {
                let flag = companion_link::dialect::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
                let armed = h.base_mode.contains(flag);
                let base = h.base_mode.bits() & !flag.bits();
                self.on_heartbeat(armed, (base, h.custom_mode));
            }
            Msg::MISSION_COUNT(_) => self.run.items.clear(),
            Msg::MISSION_ITEM_INT(m) => {
                self.run.items.insert(m.seq, (m.command as u16, m.param2));
            }
            // The legacy answer to a download (ArduPilot's mission.rs accepts it too).
            #[allow(deprecated)]
            Msg::MISSION_ITEM(m) => {
                self.run.items.insert(m.seq, (m.command as u16, m.param2));
            }
            Msg::PARAM_VALUE(p) => {
                let id = p.param_id.to_str().unwrap_or("").trim_end_matches('\0');
                let v = p.param_value as f64;
                match id {
                    "WPNAV_SPEED" if v > 0.0 => self.run.cruise_param = Some(v / 100.0),
                    "MPC_XY_CRUISE" if v > 0.0 => self.run.cruise_param = Some(v),
                    _ => {}
                }
            }
            Msg::MISSION_CURRENT(m) => {
                if self.run.current.map(|c| c.0) != Some(m.seq) {
                    let t = self.run.t_s.unwrap_or(0.0);
                    self.run.current = Some((m.seq, t, self.run.pos));
                }
            }
            Msg::MISSION_ITEM_REACHED(m) => self.on_reached(m.seq),
            _ => {}
        }
    }

    fn on_position(&mut self, t: f64, p: Position) {
        if !(t.is_finite() && p.lat_deg.is_finite() && p.lon_deg.is_finite()) {
            return;
        }
        self.run.t_s = Some(t);
        self.run.pos = Some(p);
        let Some(f) = &mut self.run.flight else {
            return;
        };
        if !f.climbed && f.climb.len() < MAX_CLIMB_SAMPLES {
            f.climb.push((t, p.alt_m));
        }
        if let Some(c) = &mut f.cruise_alt {
            *c = c.max(p.alt_m);
            if p.alt_m >= *c - ALT_TOLERANCE_M {
                f.at_cruise = Some((t, p.alt_m));
            }
        }
    }

    fn on_heartbeat(&mut self, armed: bool, mode: (u8, u32)) {
        let t = self.run.t_s.unwrap_or(0.0);
        if self.run.mode != Some(mode) {
            self.run.mode = Some(mode);
            self.run.mode_since = t;
        }
        match (self.run.armed, armed) {
            (false, true) => {
                self.run.flight = Some(Flight {
                    armed_at: t,
                    ..Default::default()
                });
                self.run.from = None;
                self.run.last_reached = None;
            }
            (true, false) => {
                if let (Some(f), Some(p)) = (self.run.flight.take(), self.run.pos)
                    && let Some((t0, h)) = f.at_cruise
                    && h >= MIN_VERTICAL_M
                    && p.alt_m < LANDED_ALT_M
                    && t > t0
                {
                    self.descents.push(Vertical {
                        height_m: h,
                        duration_s: t - t0,
                    });
                }
                self.run.from = None;
            }
            _ => {}
        }
        self.run.armed = armed;
    }

    fn on_reached(&mut self, seq: u16) {
        // PX4 repeats each MISSION_ITEM_REACHED for a while.
        if self.run.last_reached == Some(seq) || !self.run.armed {
            return;
        }
        self.run.last_reached = Some(seq);
        let (Some(t), Some(here)) = (self.run.t_s, self.run.pos) else {
            return;
        };
        let from = self.run.from.replace((t, here));
        let Some((mut t0, mut start)) = from else {
            return;
        };
        // The leg began when its waypoint became current, if that was well after the last event
        // (a hold there). MISSION_CURRENT is a ~1 Hz stream: ArduCopter's reports the next item up
        // to a second after the last one's MISSION_ITEM_REACHED, which must not shorten the leg.
        if let Some((s, since, Some(p))) = self.run.current
            && s == seq
            && since > t0 + CURRENT_STREAM_SLACK_S
        {
            (t0, start) = (since, p);
        }
        let is_waypoint = self.run.items.get(&seq).map(|i| i.0) == Some(NAV_WAYPOINT);
        let ground = leg_length_m(
            Position {
                alt_m: 0.0,
                ..start
            },
            Position { alt_m: 0.0, ..here },
        );
        if !is_waypoint || ground < MIN_LEG_M || self.run.mode_since > t0 || t <= t0 {
            return;
        }
        let Some((commanded_mps, source)) = self.commanded(seq) else {
            return;
        };
        if let Some(f) = &mut self.run.flight {
            if !f.climbed {
                f.climbed = true;
                if let Some(c) = climb_of(f.armed_at, &f.climb, start.alt_m) {
                    self.climbs.push(c);
                }
                f.climb = Vec::new();
            }
            f.cruise_alt = Some(here.alt_m);
            f.at_cruise = Some((t, here.alt_m));
        }
        self.legs.push(Leg {
            length_m: leg_length_m(start, here),
            duration_s: t - t0,
            commanded_mps,
            source,
        });
    }

    /// The speed commanded on the leg to `seq`: the mission's last DO_CHANGE_SPEED before it,
    /// else the autopilot's cruise parameter, else the fallback.
    fn commanded(&self, seq: u16) -> Option<(f64, SpeedSource)> {
        let item = self
            .run
            .items
            .range(..seq)
            .rev()
            .find(|(_, (cmd, speed))| *cmd == DO_CHANGE_SPEED && *speed > 0.0)
            .map(|(_, (_, speed))| (*speed as f64, SpeedSource::MissionItem));
        item.or(self
            .run
            .cruise_param
            .map(|v| (v, SpeedSource::AutopilotParam)))
            .or(self.fallback.as_ref().map(|f| (f.0, SpeedSource::Fallback)))
    }
}

/// The climb: from arming to the first sample at 95 % of `top` (the altitude the first leg
/// starts at).
fn climb_of(armed_at: f64, samples: &[(f64, f64)], top: f64) -> Option<Vertical> {
    if top < MIN_VERTICAL_M {
        return None;
    }
    let (t, _) = samples.iter().find(|(_, a)| *a >= 0.95 * top)?;
    (*t > armed_at).then(|| Vertical {
        height_m: top,
        duration_s: t - armed_at,
    })
}

/// The leg model fitted: `t = L / (f v_cmd) + c`.
#[derive(Debug, Clone, PartialEq)]
pub struct LegModel {
    pub legs: usize,
    /// Time per waypoint besides the leg at its speed (s).
    pub overhead_s: f64,
    /// Fraction of the commanded speed reached: `None` when the legs show the commanded speed
    /// reached (the fit's fraction at least [`REACHED_FRACTION`]) or cannot tell (one length).
    pub speed_fraction: Option<f64>,
    /// The two-parameter fit's fraction, when the legs' lengths tell it.
    pub fitted_fraction: Option<f64>,
    /// RMS of flown minus modelled leg time (s), and the model's before (no overhead, the
    /// commanded speed: what the derivation plans without a profile).
    pub rms_s: f64,
    pub rms_before_s: f64,
    pub commanded: (f64, f64),
    pub lengths: (f64, f64),
    pub sources: Vec<SpeedSource>,
}

/// Above this fraction of the commanded speed the vehicle is taken to reach it.
pub const REACHED_FRACTION: f64 = 0.95;

/// Why no leg model was fitted.
#[derive(Debug, Clone, PartialEq)]
pub enum LegFitError {
    TooFew(usize),
}

impl std::fmt::Display for LegFitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LegFitError::TooFew(n) => write!(
                f,
                "{n} leg(s) flown (MISSION_ITEM_REACHED of a waypoint at least {MIN_LEG_M} m from \
                 the last, armed, in one mode, with a commanded speed): at least {MIN_LEGS} needed"
            ),
        }
    }
}

/// The leg fit's inputs in the three passes [`fit_legs`] makes, each needing the last's result:
/// the legs' sums and ranges ([`LegSums`]), the sums about their means ([`LegCentred`]), then
/// the two-parameter fit's squared residuals. `companion-fleet calibrate` sums the same as SQL
/// aggregates over its `legs` table and gets the same model ([`LegSums::model`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LegSums {
    pub n: usize,
    /// Σ x, x = L / v_cmd (s).
    pub sum_x: f64,
    /// Σ t (s).
    pub sum_t: f64,
    /// The least and greatest x.
    pub x_range: (f64, f64),
    pub commanded: (f64, f64),
    pub lengths: (f64, f64),
    /// Distinct, sorted.
    pub sources: Vec<SpeedSource>,
}

/// The second pass: sums about the means `LegSums::means` gives, and the squared residuals of
/// the one-parameter fit (`c1 = mean t - mean x`) and of the commanded speed alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegCentred {
    /// Σ (x - mean x)².
    pub sxx: f64,
    /// Σ (x - mean x)(t - mean t).
    pub sxt: f64,
    /// Σ (t - x - c1)².
    pub ss_one: f64,
    /// Σ (t - x)².
    pub ss_before: f64,
}

fn rms(res: impl Iterator<Item = f64>) -> f64 {
    let (n, ss) = res.fold((0usize, 0.0), |(n, s), r| (n + 1, s + r * r));
    (ss / n.max(1) as f64).sqrt()
}

fn range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    v.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    })
}

impl LegSums {
    /// (mean x, mean t).
    pub fn means(&self) -> (f64, f64) {
        let n = self.n as f64;
        (self.sum_x / n, self.sum_t / n)
    }

    /// The one-parameter fit's overhead: `t = x + c1`.
    pub fn overhead_one(&self) -> f64 {
        let (mx, mt) = self.means();
        mt - mx
    }

    /// `t = a x + c` when the legs' x spread enough to tell `a` and `c` apart (the longest at
    /// least twice the shortest).
    pub fn two(&self, c: &LegCentred) -> Option<(f64, f64)> {
        let (lo, hi) = self.x_range;
        let (mx, mt) = self.means();
        (hi >= 2.0 * lo && c.sxx > 0.0).then(|| {
            let a = c.sxt / c.sxx;
            (a, mt - a * mx)
        })
    }

    /// The model, given the second pass and the two-parameter fit's Σ residual² (when
    /// [`LegSums::two`] gave one).
    pub fn model(&self, c: &LegCentred, ss_two: Option<f64>) -> Result<LegModel, LegFitError> {
        if self.n < MIN_LEGS {
            return Err(LegFitError::TooFew(self.n));
        }
        let n = self.n as f64;
        let rms_of = |ss: f64| (ss / n).sqrt();
        let two = self
            .two(c)
            .zip(ss_two)
            .map(|((a, k), ss)| (a, k, rms_of(ss)));
        let (overhead_s, speed_fraction, rms_s) = match two {
            Some((a, k, r)) if a > 0.0 && 1.0 / a < REACHED_FRACTION => (k, Some(1.0 / a), r),
            _ => (self.overhead_one(), None, rms_of(c.ss_one)),
        };
        Ok(LegModel {
            legs: self.n,
            overhead_s,
            speed_fraction,
            fitted_fraction: two.map(|(a, _, _)| 1.0 / a),
            rms_s,
            rms_before_s: rms_of(c.ss_before),
            commanded: self.commanded,
            lengths: self.lengths,
            sources: self.sources.clone(),
        })
    }
}

/// Least squares over the legs: first with the commanded speed (`a = 1`: the overhead alone);
/// then `a` and `c` both when the legs' `L / v_cmd` spread enough to tell them apart (the longest
/// at least twice the shortest); the speed fraction is kept only when below [`REACHED_FRACTION`].
pub fn fit_legs(legs: &[Leg]) -> Result<LegModel, LegFitError> {
    if legs.len() < MIN_LEGS {
        return Err(LegFitError::TooFew(legs.len()));
    }
    let x: Vec<f64> = legs.iter().map(|l| l.length_m / l.commanded_mps).collect();
    let t: Vec<f64> = legs.iter().map(|l| l.duration_s).collect();
    let mut sources: Vec<SpeedSource> = legs.iter().map(|l| l.source).collect();
    sources.sort();
    sources.dedup();
    let sums = LegSums {
        n: legs.len(),
        sum_x: x.iter().sum(),
        sum_t: t.iter().sum(),
        x_range: range(x.iter().copied()),
        commanded: range(legs.iter().map(|l| l.commanded_mps)),
        lengths: range(legs.iter().map(|l| l.length_m)),
        sources,
    };
    let (mx, mt) = sums.means();
    let c1 = sums.overhead_one();
    let sq = |r: f64| r * r;
    let centred = LegCentred {
        sxx: x.iter().map(|v| sq(v - mx)).sum(),
        sxt: x.iter().zip(&t).map(|(x, t)| (x - mx) * (t - mt)).sum(),
        ss_one: x.iter().zip(&t).map(|(x, t)| sq(t - x - c1)).sum(),
        ss_before: x.iter().zip(&t).map(|(x, t)| sq(t - x)).sum(),
    };
    let ss_two =
        (sums.two(&centred)).map(|(a, c)| x.iter().zip(&t).map(|(x, t)| sq(t - a * x - c)).sum());
    sums.model(&centred, ss_two)
}

/// A vertical rate over flights: total height over total time (so the time planned for them
/// all is the time flown), and the RMS of each flight's time against it (s).
pub fn rate(v: &[Vertical]) -> Option<(f64, f64)> {
    let h: f64 = v.iter().map(|x| x.height_m).sum();
    let t: f64 = v.iter().map(|x| x.duration_s).sum();
    if v.is_empty() || t <= 0.0 {
        return None;
    }
    let r = h / t;
    Some((r, rms(v.iter().map(|x| x.duration_s - x.height_m / r))))
}

#[cfg(test)]
mod tests;
