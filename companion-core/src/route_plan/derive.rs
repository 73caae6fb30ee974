//! Activities from a route and zones (PANORAMA P1): every leg split where it enters or leaves a
//! zone; length geodesic (WGS84) plus climb; holds from loiters and the route's time limits.

use super::{ItemKind, PlannedRoute, Position, Zone};
use geo::{Contains, Coord, Distance, Geodesic, Line, Point};

/// Speeds the route does not give. Today from the PANORAMA mission's `[derive]` table (params);
/// the autopilot's own (WPNAV_SPEED / MPC_XY_CRUISE, read over MAVLink) replace them later.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeriveSettings {
    /// Horizontal speed until a DO_CHANGE_SPEED item (m/s).
    pub cruise_speed_mps: f64,
    /// Take-off climb speed (m/s).
    pub climb_speed_mps: f64,
    /// Landing descent speed (m/s).
    pub descent_speed_mps: f64,
    /// Time a waypoint costs besides its length at the leg's speed (s): accelerating, braking
    /// and turning; the vehicle profile's, fitted by `calibrate` (0: none). Each leg (and the
    /// return) holds it once, on its last piece.
    pub waypoint_overhead_s: f64,
    /// Fraction of the commanded horizontal speed the vehicle reaches on a leg (1: it flies the
    /// commanded speed); the vehicle profile's, fitted by `calibrate`.
    pub speed_fraction: f64,
    /// The autopilot's hover over home before an RTL descends (s): ArduCopter's RTL_LOIT_TIME
    /// (default 5 s), PX4's RTL_LAND_DELAY; held by the return's last piece.
    pub rtl_loiter_s: f64,
}

/// What part of the flight an activity is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActivityKind {
    /// The take-off climb.
    TakeOff,
    /// A leg (or the part of one inside or outside zones).
    Leg,
    /// A loiter item's hold.
    Loiter,
    /// Searching at the last waypoint for the route's search time limit.
    Search,
    /// Tracking the target for the route's tracking time limit.
    Tracking,
    /// The return to home (RTL), split at zones like any leg.
    Return,
    /// The landing descent.
    Land,
}

/// One derived activity.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DerivedActivity {
    /// Unique in the mission (`leg3-4.2`, `take_off`, `search`, ...).
    pub name: String,
    /// What part of the flight it is.
    pub kind: ActivityKind,
    /// Distance flown (m): geodesic plus the altitude change.
    pub length_m: f64,
    /// Time spent besides moving along `length_m` (s).
    pub hold_s: f64,
    /// Speed it is flown at (m/s).
    pub speed_mps: f64,
    /// Constraint classes in force (sorted, no repeats).
    pub constraints: Vec<String>,
    /// Where it comes from: the leg, the zones, the limit.
    pub source: String,
}

/// Below this (m) a leg or a piece of one is not an activity.
const MIN_LENGTH_M: f64 = 0.01;

struct Walk<'a> {
    zones: &'a [&'a Zone],
    out: Vec<DerivedActivity>,
    here: Position,
    here_label: String,
    speed: f64,
    /// The vehicle profile's leg numbers (`DeriveSettings`).
    overhead_s: f64,
    speed_fraction: f64,
}

/// Derive the activities of `route` across `zones` (the zones file's and the route's own).
/// `home_fallback` places a route with no home of its own (its first position otherwise).
pub fn derive_activities(
    route: &PlannedRoute,
    zones: &[Zone],
    s: &DeriveSettings,
) -> Vec<DerivedActivity> {
    derive_activities_from(route, zones, s, None)
}

/// [`derive_activities`] of a route flown from `start` (the point reached in flight, labelled
/// `here`; a mission changed in flight is re-planned from it) instead of home on the ground.
pub fn derive_activities_from(
    route: &PlannedRoute,
    zones: &[Zone],
    s: &DeriveSettings,
    start: Option<Position>,
) -> Vec<DerivedActivity> {
    let all: Vec<&Zone> = zones.iter().chain(&route.zones).collect();
    let home = route
        .home
        .or_else(|| first_position(route))
        .unwrap_or((0.0, 0.0));
    let home = Position {
        lat_deg: home.0,
        lon_deg: home.1,
        alt_m: 0.0,
    };
    let mut w = Walk {
        zones: &all,
        out: Vec::new(),
        here: start.unwrap_or(home),
        here_label: if start.is_some() { "here" } else { "home" }.into(),
        speed: s.cruise_speed_mps,
        overhead_s: s.waypoint_overhead_s,
        speed_fraction: s.speed_fraction,
    };
    let mut landed = false;
    for item in &route.items {
        let i = item.index;
        match item.kind {
            ItemKind::TakeOff { alt_m } => {
                let climb = (alt_m - w.here.alt_m).max(0.0);
                let c = w.constraints_at(w.here);
                w.push(
                    "take_off".into(),
                    ActivityKind::TakeOff,
                    climb,
                    0.0,
                    s.climb_speed_mps,
                    c.0,
                    format!("item {i}: take-off to {alt_m} m{}", c.1),
                );
                w.here.alt_m = alt_m;
            }
            ItemKind::ChangeSpeed { mps } => w.speed = mps,
            ItemKind::Waypoint(p) => w.legs(p, i.to_string(), ActivityKind::Leg),
            ItemKind::Loiter { at, hold_s } => {
                w.legs(at, i.to_string(), ActivityKind::Leg);
                let c = w.constraints_at(at);
                w.push(
                    format!("loiter{i}"),
                    ActivityKind::Loiter,
                    0.0,
                    hold_s,
                    w.speed,
                    c.0,
                    format!("item {i}: loiter {hold_s:.0} s{}", c.1),
                );
            }
            ItemKind::ReturnToLaunch => {
                w.limits(route, s);
                // RTL flies at the autopilot's own return speed, not the mission's last
                // DO_CHANGE_SPEED: ArduCopter's RTL starts its waypoint navigation afresh at
                // RTL_SPEED (0: WPNAV_SPEED), PX4's at MPC_XY_CRUISE.
                w.speed = s.cruise_speed_mps;
                w.legs(
                    Position {
                        alt_m: w.here.alt_m,
                        ..home
                    },
                    "home".into(),
                    ActivityKind::Return,
                );
                if let Some(a) = (w.out.last_mut()).filter(|a| a.kind == ActivityKind::Return) {
                    a.hold_s += s.rtl_loiter_s;
                }
                w.land(&format!("item {i}: RTL, land at home"), s);
                landed = true;
                break;
            }
            ItemKind::Land { at } => {
                w.limits(route, s);
                if let Some(at) = at {
                    w.legs(
                        Position {
                            alt_m: w.here.alt_m,
                            ..at
                        },
                        i.to_string(),
                        ActivityKind::Leg,
                    );
                }
                w.land(&format!("item {i}: land"), s);
                landed = true;
                break;
            }
        }
    }
    if !landed {
        // The route TOML's end: the fly shell searches and tracks at the last waypoint, then
        // lands where the vehicle is (LAND mode, params/commands.toml's land).
        w.limits(route, s);
        w.land("route end: land where the vehicle is", s);
    }
    w.out
}

fn first_position(route: &PlannedRoute) -> Option<(f64, f64)> {
    route.items.iter().find_map(|it| match it.kind {
        ItemKind::Waypoint(p) | ItemKind::Loiter { at: p, .. } => Some((p.lat_deg, p.lon_deg)),
        ItemKind::Land { at: Some(p) } => Some((p.lat_deg, p.lon_deg)),
        _ => None,
    })
}

impl Walk<'_> {
    #[allow(clippy::too_many_arguments)]
    fn push(
        &mut self,
        name: String,
        kind: ActivityKind,
        length_m: f64,
        hold_s: f64,
        speed_mps: f64,
        constraints: Vec<String>,
        source: String,
    ) {
        self.out.push(DerivedActivity {
            name,
            kind,
            length_m,
            hold_s,
            speed_mps,
            constraints,
            source,
        });
    }

    /// Constraint classes at a point and the source's words for the zones.
    fn constraints_at(&self, p: Position) -> (Vec<String>, String) {
        let pt = Point::new(p.lon_deg, p.lat_deg);
        let inside: Vec<&Zone> = self
            .zones
            .iter()
            .copied()
            .filter(|z| z.area.contains(&pt))
            .collect();
        zone_words(&inside)
    }

    /// The search and tracking holds at the current position, worst case both in turn (the target
    /// found just as the search limit ends).
    fn limits(&mut self, route: &PlannedRoute, s: &DeriveSettings) {
        let _ = s;
        let c = self.constraints_at(self.here);
        if let Some(t) = route.search_time_limit_s {
            self.push(
                "search".into(),
                ActivityKind::Search,
                0.0,
                t,
                0.0,
                c.0.clone(),
                format!("search time limit {t} s at {}{}", self.here_label, c.1),
            );
        }
        if let Some(t) = route.tracking_time_limit_s {
            self.push(
                "tracking".into(),
                ActivityKind::Tracking,
                0.0,
                t,
                0.0,
                c.0,
                format!("tracking time limit {t} s at {}{}", self.here_label, c.1),
            );
        }
    }

    fn land(&mut self, why: &str, s: &DeriveSettings) {
        let c = self.constraints_at(self.here);
        self.push(
            "land".into(),
            ActivityKind::Land,
            self.here.alt_m.max(0.0),
            0.0,
            s.descent_speed_mps,
            c.0,
            format!("{why}: descent {:.1} m{}", self.here.alt_m, c.1),
        );
        self.here.alt_m = 0.0;
    }

    /// The leg from here to `to`, split where it crosses a zone's boundary.
    fn legs(&mut self, to: Position, to_label: String, kind: ActivityKind) {
        let from = self.here;
        let full = leg_length_m(from, to);
        let pieces = split_leg(from, to, self.zones);
        let kept: Vec<_> = pieces
            .iter()
            .filter(|p| full * (p.1 - p.0) >= MIN_LENGTH_M)
            .collect();
        let base = match kind {
            ActivityKind::Return => "return".to_string(),
            _ => format!("leg{}-{}", self.here_label, to_label),
        };
        let n = kept.len();
        let speed = self.speed * self.speed_fraction;
        let lengths: Vec<f64> = kept.iter().map(|p| full * (p.1 - p.0)).collect();
        let speeds = piece_speeds(&lengths, self.speed, speed);
        for (k, (t0, t1, inside)) in kept.into_iter().enumerate() {
            let (constraints, words) = zone_words(inside);
            let (name, part) = if n > 1 {
                (
                    format!("{base}.{}", k + 1),
                    format!(" (part {} of {n})", k + 1),
                )
            } else {
                (base.clone(), String::new())
            };
            let length = full * (t1 - t0);
            let source = format!("leg {}->{}{part}{words}", self.here_label, to_label);
            // The waypoint's overhead is speeding up out of one waypoint and braking into the
            // next: a leg split by zones holds half in its first piece and half in its last
            // (assumed symmetric: ArduCopter's WPNAV_ACCEL serves both).
            let hold = match (n, k) {
                (1, _) => self.overhead_s,
                (_, 0) => self.overhead_s / 2.0,
                _ if k + 1 == n => self.overhead_s / 2.0,
                _ => 0.0,
            };
            self.push(name, kind, length, hold, speeds[k], constraints, source);
        }
        self.here = to;
        self.here_label = to_label;
    }
}

/// The speeds of one leg's pieces (split at zone boundaries). The leg model's speed (commanded
/// times the fitted fraction) is a whole leg's average: the vehicle accelerates in its first
/// piece and brakes in its last, and crosses a zone boundary at the commanded speed. So a middle
/// piece flies at `commanded`, and the two end pieces share what is left of the leg's time
/// (a leg's total time is unchanged). One or two pieces: all at the average.
fn piece_speeds(lengths: &[f64], commanded: f64, average: f64) -> Vec<f64> {
    let n = lengths.len();
    if n < 3 || commanded <= average {
        return vec![average; n];
    }
    let total_s: f64 = lengths.iter().sum::<f64>() / average;
    let middle_s: f64 = lengths[1..n - 1].iter().sum::<f64>() / commanded;
    let ends_m = lengths[0] + lengths[n - 1];
    let ends = ends_m / (total_s - middle_s);
    let mut v = vec![commanded; n];
    v[0] = ends;
    v[n - 1] = ends;
    v
}

/// A leg's length as the derivation counts it: the geodesic distance (WGS84) plus the altitude
/// change. `calibrate` measures the legs flown with it too.
pub fn leg_length_m(from: Position, to: Position) -> f64 {
    let ground = Geodesic.distance(
        Point::new(from.lon_deg, from.lat_deg),
        Point::new(to.lon_deg, to.lat_deg),
    );
    ground + (to.alt_m - from.alt_m).abs()
}

/// Sorted, unique constraint names of the zones and the source's words (`, zones a, b`).
fn zone_words(inside: &[&Zone]) -> (Vec<String>, String) {
    let mut c: Vec<String> = inside
        .iter()
        .flat_map(|z| z.constraints.iter().cloned())
        .collect();
    c.sort();
    c.dedup();
    let words = if inside.is_empty() {
        String::new()
    } else {
        let names: Vec<&str> = inside.iter().map(|z| z.name.as_str()).collect();
        format!(", in zone {}", names.join(", "))
    };
    (c, words)
}

/// The leg `a -> b` cut where it crosses a zone boundary: (start, end) fractions of the leg and
/// the zones each piece is in. Crossings are found on the lon/lat plane (a leg is short against
/// the Earth's curvature: the fractions, not the lengths, come from the plane).
fn split_leg<'z>(a: Position, b: Position, zones: &[&'z Zone]) -> Vec<(f64, f64, Vec<&'z Zone>)> {
    let leg = Line::new(
        Coord {
            x: a.lon_deg,
            y: a.lat_deg,
        },
        Coord {
            x: b.lon_deg,
            y: b.lat_deg,
        },
    );
    let (lo_x, hi_x) = (leg.start.x.min(leg.end.x), leg.start.x.max(leg.end.x));
    let (lo_y, hi_y) = (leg.start.y.min(leg.end.y), leg.start.y.max(leg.end.y));
    let d = leg.delta();
    let frac = |c: Coord<f64>| {
        if d.x.abs() >= d.y.abs() {
            (c.x - leg.start.x) / d.x
        } else {
            (c.y - leg.start.y) / d.y
        }
    };
    let mut cuts = vec![0.0, 1.0];
    let near: Vec<&Zone> = zones
        .iter()
        .copied()
        .filter(|z| {
            z.bbox.min().x <= hi_x
                && z.bbox.max().x >= lo_x
                && z.bbox.min().y <= hi_y
                && z.bbox.max().y >= lo_y
        })
        .collect();
    if d.x != 0.0 || d.y != 0.0 {
        for z in &near {
            for poly in &z.area.0 {
                for ring in std::iter::once(poly.exterior()).chain(poly.interiors()) {
                    for edge in ring.lines() {
                        use geo::line_intersection::{LineIntersection, line_intersection};
                        match line_intersection(leg, edge) {
                            Some(LineIntersection::SinglePoint { intersection, .. }) => {
                                cuts.push(frac(intersection))
                            }
                            Some(LineIntersection::Collinear { intersection }) => {
                                cuts.push(frac(intersection.start));
                                cuts.push(frac(intersection.end));
                            }
                            None => {}
                        }
                    }
                }
            }
        }
    }
    cuts.retain(|t| t.is_finite());
    cuts.iter_mut().for_each(|t| *t = t.clamp(0.0, 1.0));
    cuts.sort_by(f64::total_cmp);
    cuts.dedup_by(|x, y| (*x - *y).abs() < 1e-12);
    let mut pieces: Vec<(f64, f64, Vec<&Zone>)> = Vec::new();
    for w in cuts.windows(2) {
        let mid = (w[0] + w[1]) / 2.0;
        let pt = Point::new(leg.start.x + d.x * mid, leg.start.y + d.y * mid);
        let inside: Vec<&Zone> = near
            .iter()
            .copied()
            .filter(|z| z.area.contains(&pt))
            .collect();
        match pieces.last_mut() {
            Some(last) if same_zones(&last.2, &inside) => last.1 = w[1],
            _ => pieces.push((w[0], w[1], inside)),
        }
    }
    pieces
}

fn same_zones(a: &[&Zone], b: &[&Zone]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| std::ptr::eq(*x, *y))
}
