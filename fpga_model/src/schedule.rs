//! The "just enough" scheduler (section 4.3.2, 6.3): for each requested application version,
//! the slowest implementation that meets its frame rate; HW parts on free healthy tiles (reusing
//! tiles that already hold the bitstream); the CPU budget checked; and, when the set does not
//! fit, the policy's degradation paths and priority order applied, least important first.

use crate::{Catalogue, EPS, FmtMs, Implementation, Platform, ResourcePolicy, Support, Variant};
use serde::{Deserialize, Serialize};
use std::fmt::{self, Write as _};

/// What the decision layer asks to run this cycle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Request {
    /// Application to run.
    pub app: String,
    /// Version of it to run.
    pub version: String,
    /// Frames per second the application must process (1000 / max ms per frame).
    pub required_fps: f64,
    /// Overrides the policy rank of the app (0 = most important, same scale as the position in
    /// the policy's `priority` list). `None`: the policy decides.
    #[serde(default)]
    pub priority: Option<u32>,
    /// Implementation (`S`, `M`, `F`) a plan asks for (PANORAMA's allocation: `V4.F`): tried
    /// first when it meets the rate, the just-enough order after it. `None`: just enough.
    #[serde(default)]
    pub implementation: Option<Implementation>,
}

impl Request {
    /// A request at rate `required_fps`, ranked by the policy.
    pub fn new(app: &str, version: &str, required_fps: f64) -> Self {
        Self {
            app: app.into(),
            version: version.into(),
            required_fps,
            priority: None,
            implementation: None,
        }
    }

    /// The same request with `implementation` tried first.
    pub fn preferring(mut self, implementation: Implementation) -> Self {
        self.implementation = Some(implementation);
        self
    }

    /// A request given as a frame deadline instead of a rate.
    pub fn with_max_ms(app: &str, version: &str, max_ms_per_frame: f64) -> Self {
        Self::new(app, version, 1000.0 / max_ms_per_frame)
    }
}

/// One reconfigurable tile: the partial bitstream it holds (`app/version/impl#part`) and whether
/// it has failed.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Tile {
    /// The partial bitstream loaded, `None` when blank.
    #[serde(default)]
    pub bitstream: Option<String>,
    /// True once the tile has failed; the scheduler then places nothing on it.
    #[serde(default)]
    pub failed: bool,
}

/// The platform as the scheduler sees it between cycles: passed in, returned updated.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PlatformState {
    /// Every tile, indexed by tile number.
    pub tiles: Vec<Tile>,
    /// CPU cores currently online.
    pub cores_online: u8,
    /// CPU load not caused by scheduled applications (OS, decision core, a monitor reading above
    /// what the placements account for), as a fraction of the nominal (all cores) CPU.
    #[serde(default)]
    pub external_cpu_load: f64,
}

impl PlatformState {
    /// A healthy, blank board.
    pub fn new(platform: &Platform) -> Self {
        Self {
            tiles: vec![Tile::default(); usize::from(platform.tiles)],
            cores_online: platform.cpu_cores,
            external_cpu_load: 0.0,
        }
    }

    /// Mark `tile` failed (ignored when out of range).
    pub fn fail_tile(&mut self, tile: u8) {
        if let Some(t) = self.tiles.get_mut(usize::from(tile)) {
            t.failed = true;
        }
    }

    /// Mark `tile` healthy again (ignored when out of range).
    pub fn repair_tile(&mut self, tile: u8) {
        if let Some(t) = self.tiles.get_mut(usize::from(tile)) {
            t.failed = false;
        }
    }

    /// Numbers of the failed tiles, increasing.
    pub fn failed_tiles(&self) -> Vec<u8> {
        self.tiles
            .iter()
            .enumerate()
            .filter(|(_, t)| t.failed)
            .map(|(i, _)| i as u8)
            .collect()
    }

    /// External load implied by a CPU monitor reading (utilisation of the online cores) and the
    /// share the current placements account for (fraction of nominal CPU).
    pub fn set_monitored_load(&mut self, platform: &Platform, reading: f64, placed_share: f64) {
        let online = f64::from(self.cores_online.min(platform.cpu_cores));
        let nominal = reading * online / f64::from(platform.cpu_cores);
        self.external_cpu_load = (nominal - placed_share).max(0.0);
    }
}

/// One application variant placed on the platform.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Application placed.
    pub app: String,
    /// Version placed (after any degradation).
    pub version: String,
    /// Speed class chosen: the slowest that meets `required_fps`.
    pub implementation: Implementation,
    /// Where it runs.
    pub support: Support,
    /// Tiles its HW part occupies.
    pub tiles: Vec<u8>,
    /// Fraction of the nominal CPU used at `required_fps`.
    pub cpu_share: f64,
    /// Per-frame time, the sum of the parts, ms.
    pub ms_per_frame: f64,
    /// Per-part times as the paper writes them (`[10, 1]`).
    pub ms: Vec<f64>,
    /// The rate the request asked for, frames per second.
    pub required_fps: f64,
    /// tiles + cpu_share (section 4.3.1).
    pub u_app: f64,
    /// Tiles that had to be (re)configured for this placement.
    pub reconfigured: Vec<u8>,
}

/// An application run at another version than requested, along the policy's degradation path.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Degradation {
    /// The application.
    pub app: String,
    /// The version requested.
    pub from: String,
    /// The version placed instead.
    pub to: String,
    /// Why the requested version did not fit.
    pub reason: String,
}

/// A requested application left out of the schedule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dropped {
    /// The application.
    pub app: String,
    /// The version requested, or the last one tried along its degradation path.
    pub version: String,
    /// Why nothing of it fits.
    pub reason: String,
}

/// Result of one scheduling decision.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Schedule {
    /// Name of the resource policy applied.
    pub policy: String,
    /// In request order.
    pub placements: Vec<Placement>,
    /// Utilisation of the online cores, applications plus external load (the resource BN's
    /// `cpu_load` observation).
    pub cpu_load: f64,
    /// Sum of placement shares, fraction of the nominal CPU.
    pub app_cpu_share: f64,
    /// CPU load not caused by the placements, fraction of the nominal CPU.
    pub external_cpu_load: f64,
    /// CPU cores online during this decision.
    pub cpu_cores_online: u8,
    /// Tiles occupied by the placements.
    pub tiles_used: u8,
    /// Healthy tiles not used by a placement (the resource BN's `free_tiles` observation).
    pub free_tiles: u8,
    /// Numbers of the failed tiles.
    pub failed_tiles: Vec<u8>,
    /// Tiles (re)configured by this decision.
    pub reconfigurations: u32,
    /// Time those reconfigurations take, ms.
    pub reconfiguration_ms: f64,
    /// Board power estimate for this schedule, W.
    pub power_w: f64,
    /// Applications run at a lower version than requested.
    pub degraded: Vec<Degradation>,
    /// Applications left out.
    pub dropped: Vec<Dropped>,
    /// The paper's Resources column: the placements' times joined by " + " (`10 + 5 + 394 ms`).
    pub summary: String,
}

/// A request the scheduler still tries to place. The app is `requests[req].app`; the version
/// is named by the index of a catalogue variant of it, so the working lists borrow nothing and
/// can live in the reusable [`ScheduleWorkspace`].
#[derive(Debug, Clone, Copy)]
struct Item {
    req: usize,
    /// Index (in `catalogue.variants()`) of the first variant of the item's version.
    version: usize,
    fps: f64,
    rank: usize,
}

/// What is left for applications: healthy tiles and CPU (fraction of nominal, after external).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Room {
    /// Healthy tiles.
    pub tiles: u32,
    /// CPU budget of the online cores less the external load (fraction of nominal CPU).
    pub cpu: f64,
    /// Cores of the platform (CPU shares are fractions of all of them).
    pub cores: u8,
}

impl Room {
    /// The room `state` leaves on `platform`, as [`schedule_into`] computes it (a NaN external
    /// load counts as the whole CPU).
    pub fn of(platform: &Platform, state: &PlatformState) -> Room {
        let cores = platform.cpu_cores;
        let online = state.cores_online.min(cores);
        let external = if state.external_cpu_load.is_nan() {
            1.0
        } else {
            state.external_cpu_load.max(0.0)
        };
        let healthy = (0..usize::from(platform.tiles))
            .filter(|&i| state.tiles.get(i).is_none_or(|t| !t.failed))
            .count();
        Room {
            tiles: healthy as u32,
            cpu: platform.cpu_budget * f64::from(online) / f64::from(cores) - external,
            cores,
        }
    }

    /// The scheduler's admission check: whether `v` at `fps` fits beside placements that already
    /// use `used_tiles` tiles and `used_cpu` of the CPU. The search makes exactly this check for
    /// each item after the ones before it, so a version the decision core checks here beside the
    /// applications in force is one the scheduler can place beside them.
    pub fn admits(&self, v: &Variant, fps: f64, used_tiles: u32, used_cpu: f64) -> bool {
        if !v.meets(fps) {
            return false;
        }
        let t = used_tiles + u32::from(v.tiles);
        let share = v.cpu_share_at(fps, self.cores);
        let c = used_cpu + share;
        !(t > self.tiles || (share > 0.0 && c > self.cpu + EPS))
    }

    /// Whether some implementation of `app version` in `catalogue` is admitted ([`Room::admits`]).
    pub fn admits_version(
        &self,
        catalogue: &Catalogue,
        app: &str,
        version: &str,
        fps: f64,
        used_tiles: u32,
        used_cpu: f64,
    ) -> bool {
        catalogue.variants().iter().any(|v| {
            v.app == app && v.version == version && self.admits(v, fps, used_tiles, used_cpu)
        })
    }
}

/// Reusable working memory of [`schedule_into`]: every list the scheduler needs, plus spare
/// records and strings from earlier outputs, so that a warm run (inputs of a size seen before)
/// allocates nothing. It holds no result: any workspace gives the same schedule.
#[derive(Debug, Default)]
pub struct ScheduleWorkspace {
    items: Vec<Item>,
    given_way: Vec<Item>,
    still_out: Vec<Item>,
    /// Candidate variant indices of all items, item `i`'s at `cand_start[i]..cand_start[i + 1]`.
    cand: Vec<usize>,
    cand_start: Vec<usize>,
    chosen: Vec<usize>,
    choice: Vec<usize>,
    /// Scratch list of one version's implementations.
    impls: Vec<usize>,
    healthy: Vec<u8>,
    taken: Vec<bool>,
    /// (item, variant, part) still needing a tile.
    pending: Vec<(usize, usize, u8)>,
    /// (item, tile, reconfigured).
    assigned: Vec<(usize, u8, bool)>,
    order: Vec<usize>,
    spare_placements: Vec<Placement>,
    spare_degraded: Vec<Degradation>,
    spare_dropped: Vec<Dropped>,
    spare_strings: Vec<String>,
}

impl ScheduleWorkspace {
    /// Empty buffers; the first decision allocates.
    pub fn new() -> Self {
        Self::default()
    }

    fn string(&mut self) -> String {
        let mut s = self.spare_strings.pop().unwrap_or_default();
        s.clear();
        s
    }

    fn degradation(&mut self) -> Degradation {
        let mut d = self.spare_degraded.pop().unwrap_or(Degradation {
            app: String::new(),
            from: String::new(),
            to: String::new(),
            reason: String::new(),
        });
        d.app.clear();
        d.from.clear();
        d.to.clear();
        d.reason.clear();
        d
    }

    /// A degradation of `app` from one version to another (a spare's strings reused), its
    /// reason written from `reason`.
    fn degraded(
        &mut self,
        (app, from, to): (&str, &str, &str),
        reason: std::fmt::Arguments<'_>,
    ) -> Degradation {
        let mut d = self.degradation();
        set(&mut d.app, app);
        set(&mut d.from, from);
        set(&mut d.to, to);
        let _ = d.reason.write_fmt(reason);
        d
    }

    fn dropped(&mut self, app: &str, version: &str) -> Dropped {
        let mut d = self.spare_dropped.pop().unwrap_or(Dropped {
            app: String::new(),
            version: String::new(),
            reason: String::new(),
        });
        set(&mut d.app, app);
        set(&mut d.version, version);
        d.reason.clear();
        d
    }
}

/// `dst = src` keeping `dst`'s capacity.
fn set(dst: &mut String, src: &str) {
    dst.clear();
    dst.push_str(src);
}

/// Implementations of `app version` as catalogue indices, slowest first (largest time per frame;
/// ties S before F): [`Catalogue::implementations`] without the allocation. Keys are unique
/// (the catalogue rejects a duplicate implementation), so the unstable sort gives its order.
fn implementations_into(catalogue: &Catalogue, app: &str, version: &str, out: &mut Vec<usize>) {
    let vs = catalogue.variants();
    out.clear();
    out.extend(
        vs.iter()
            .enumerate()
            .filter(|(_, v)| v.app == app && v.version == version)
            .map(|(i, _)| i),
    );
    out.sort_unstable_by(|&a, &b| {
        vs[b]
            .ms_per_frame()
            .total_cmp(&vs[a].ms_per_frame())
            .then(vs[a].implementation.cmp(&vs[b].implementation))
    });
}

/// Whether some implementation of `app version` reaches `fps`.
fn has_candidate(catalogue: &Catalogue, app: &str, version: &str, fps: f64) -> bool {
    catalogue
        .variants()
        .iter()
        .any(|v| v.app == app && v.version == version && v.meets(fps))
}

/// Index of the first catalogue variant of `app version`.
fn version_index(catalogue: &Catalogue, app: &str, version: &str) -> Option<usize> {
    catalogue
        .variants()
        .iter()
        .position(|v| v.app == app && v.version == version)
}

/// First feasible assignment in lexicographic order (items by rank, implementations slowest
/// first), left in `ws.chosen`. Being first means: no item could take a slower implementation
/// with the others fixed.
fn search(
    catalogue: &Catalogue,
    requests: &[Request],
    items: &[Item],
    room: Room,
    ws: &mut ScheduleWorkspace,
) -> bool {
    let vs = catalogue.variants();
    ws.cand.clear();
    ws.cand_start.clear();
    for it in items {
        ws.cand_start.push(ws.cand.len());
        implementations_into(
            catalogue,
            &requests[it.req].app,
            &vs[it.version].version,
            &mut ws.impls,
        );
        let first = ws.cand.len();
        ws.cand
            .extend(ws.impls.iter().copied().filter(|&i| vs[i].meets(it.fps)));
        // A planned implementation that meets the rate goes first; the rest keep their order.
        if let Some(want) = requests[it.req].implementation
            && let Some(k) = ws.cand[first..]
                .iter()
                .position(|&i| vs[i].implementation == want)
        {
            ws.cand[first..=first + k].rotate_right(1);
        }
    }
    ws.cand_start.push(ws.cand.len());
    ws.chosen.clear();
    #[allow(clippy::too_many_arguments)]
    fn dfs(
        i: usize,
        vs: &[Variant],
        cand: &[usize],
        start: &[usize],
        items: &[Item],
        room: Room,
        tiles: u32,
        cpu: f64,
        chosen: &mut Vec<usize>,
    ) -> bool {
        if i == items.len() {
            return true;
        }
        for &k in &cand[start[i]..start[i + 1]] {
            let v = &vs[k];
            // Candidates already meet the rate; `admits` checks it again, which changes nothing.
            if !room.admits(v, items[i].fps, tiles, cpu) {
                continue;
            }
            let t = tiles + u32::from(v.tiles);
            let c = cpu + v.cpu_share_at(items[i].fps, room.cores);
            chosen.push(k);
            if dfs(i + 1, vs, cand, start, items, room, t, c, chosen) {
                return true;
            }
            chosen.pop();
        }
        false
    }
    dfs(
        0,
        vs,
        &ws.cand,
        &ws.cand_start,
        items,
        room,
        0,
        0.0,
        &mut ws.chosen,
    )
}

/// Insert keeping rank order (ties by request order).
fn insert_ranked(items: &mut Vec<Item>, item: Item) -> usize {
    let pos = items
        .iter()
        .position(|x| (x.rank, x.req) > (item.rank, item.req))
        .unwrap_or(items.len());
    items.insert(pos, item);
    pos
}

/// "policy safety ranks tracking 3 of 5", written where it is needed.
struct RankText<'a> {
    policy: &'a str,
    app: &'a str,
    rank: usize,
    of: usize,
}

impl fmt::Display for RankText<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "policy {} ranks {} {} of {}",
            self.policy,
            self.app,
            self.rank + 1,
            self.of
        )
    }
}

/// Why no implementation of `app version` fits in what the other placements leave.
#[allow(clippy::too_many_arguments)]
fn why_not(
    out: &mut String,
    catalogue: &Catalogue,
    app: &str,
    version: &str,
    fps: f64,
    tiles_left: u32,
    cpu_left: f64,
    cores: u8,
    impls: &mut Vec<usize>,
) {
    implementations_into(catalogue, app, version, impls);
    let mut first = true;
    let mut sep = |out: &mut String| {
        if !first {
            out.push_str("; ");
        }
        first = false;
    };
    for &k in impls.iter() {
        let v = &catalogue.variants()[k];
        let i = v.implementation;
        if !v.meets(fps) {
            sep(out);
            let _ = write!(out, "{i} reaches only {:.1} fps", v.max_fps());
            continue;
        }
        let share = v.cpu_share_at(fps, cores);
        if u32::from(v.tiles) > tiles_left {
            sep(out);
            let _ = write!(out, "{i} needs {} tiles ({tiles_left} free)", v.tiles);
        } else if share > 0.0 && share > cpu_left + EPS {
            sep(out);
            let _ = write!(
                out,
                "{i} needs cpu {share:.3} ({:.3} left)",
                cpu_left.max(0.0)
            );
        }
    }
}

/// An `fmt::Write` that compares what is written with a string: whether a bitstream tag equals
/// a variant's `key#part` without building that string.
struct SameAs<'a>(Option<&'a str>);

impl fmt::Write for SameAs<'_> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        self.0 = self.0.and_then(|rest| rest.strip_prefix(s));
        Ok(())
    }
}

/// True when `tag` is the bitstream tag of part `part` of `v` (`app/version/impl#part`, as
/// [`Variant::key`] writes it).
fn is_tag(tag: &str, v: &Variant, part: u8) -> bool {
    let mut w = SameAs(Some(tag));
    let _ = write!(w, "{}/{}/{}#{part}", v.app, v.version, v.implementation);
    w.0 == Some("")
}

/// `dst = src` for a platform state, keeping `dst`'s strings; bitstream strings no longer
/// needed go to the workspace's spares.
fn copy_state(dst: &mut PlatformState, src: &PlatformState, ws: &mut ScheduleWorkspace) {
    while dst.tiles.len() > src.tiles.len() {
        if let Some(Tile {
            bitstream: Some(s), ..
        }) = dst.tiles.pop()
        {
            ws.spare_strings.push(s);
        }
    }
    for (i, t) in src.tiles.iter().enumerate() {
        if i == dst.tiles.len() {
            dst.tiles.push(Tile::default());
        }
        let d = &mut dst.tiles[i];
        d.failed = t.failed;
        match (&mut d.bitstream, &t.bitstream) {
            (Some(a), Some(b)) => set(a, b),
            (slot @ None, Some(b)) => {
                let mut s = ws.string();
                s.push_str(b);
                *slot = Some(s);
            }
            (slot, None) => {
                if let Some(s) = slot.take() {
                    ws.spare_strings.push(s);
                }
            }
        }
    }
    dst.cores_online = src.cores_online;
    dst.external_cpu_load = src.external_cpu_load;
}

mod output;
use output::{assign_tiles, drop_still_out, write_placements, write_totals};

/// Decide placements for `requests` on `state` under `policy`. Returns the schedule and the
/// platform state after it (tile bitstreams updated; faults and loads unchanged).
pub fn schedule(
    platform: &Platform,
    catalogue: &Catalogue,
    policy: &ResourcePolicy,
    state: &PlatformState,
    requests: &[Request],
) -> (Schedule, PlatformState) {
    let mut out = Schedule::default();
    let mut next = PlatformState::default();
    schedule_into(
        platform,
        catalogue,
        policy,
        state,
        requests,
        &mut ScheduleWorkspace::new(),
        &mut out,
        &mut next,
    );
    (out, next)
}

/// [`schedule`] writing into `out` and `next` (the platform state after it) and working in
/// `ws`: the same result, without heap allocation once `ws`, `out` and `next` have been through
/// inputs as large as these (the decision cycle runs the scheduler whenever requests, rates or
/// the platform change, and must not allocate in flight).
#[allow(clippy::too_many_arguments)]
pub fn schedule_into(
    platform: &Platform,
    catalogue: &Catalogue,
    policy: &ResourcePolicy,
    state: &PlatformState,
    requests: &[Request],
    ws: &mut ScheduleWorkspace,
    out: &mut Schedule,
    next: &mut PlatformState,
) {
    // Earlier results become spares.
    ws.spare_placements.append(&mut out.placements);
    ws.spare_degraded.append(&mut out.degraded);
    ws.spare_dropped.append(&mut out.dropped);

    copy_state(next, state, ws);
    let st = next;
    while st.tiles.len() > usize::from(platform.tiles) {
        if let Some(Tile {
            bitstream: Some(s), ..
        }) = st.tiles.pop()
        {
            ws.spare_strings.push(s);
        }
    }
    st.tiles
        .resize(usize::from(platform.tiles), Tile::default());
    let cores = platform.cpu_cores;
    let online = st.cores_online.min(cores);
    let external = if st.external_cpu_load.is_nan() {
        1.0
    } else {
        st.external_cpu_load.max(0.0)
    };
    ws.healthy.clear();
    ws.healthy
        .extend((0..platform.tiles).filter(|&i| !st.tiles[usize::from(i)].failed));
    let room = Room::of(platform, st);
    debug_assert_eq!(room.tiles as usize, ws.healthy.len());

    let inp = Inputs {
        platform,
        catalogue,
        policy,
        requests,
    };
    admit(&inp, ws, out);
    // Resolve: while the set does not fit, the least important application first tries its
    // degradation path, then gives way.
    let mut active = std::mem::take(&mut ws.items);
    resolve(&inp, room, &mut active, ws, out);
    replace_given_way(&inp, room, &mut active, ws, out);
    assign_tiles(&inp, st, ws);
    write_placements(&inp, &active, ws, out);
    drop_still_out(&inp, room, ws, out);
    ws.items = active;
    write_totals(&inp, st, ws, out, online, external);
}

/// What one run of [`schedule_into`] reads.
#[derive(Clone, Copy)]
struct Inputs<'a> {
    platform: &'a Platform,
    catalogue: &'a Catalogue,
    policy: &'a ResourcePolicy,
    requests: &'a [Request],
}

impl Inputs<'_> {
    /// The policy rank of `it`, written into a degradation or drop reason.
    fn rank_text(&self, it: &Item) -> RankText<'_> {
        RankText {
            policy: &self.policy.name,
            app: &self.requests[it.req].app,
            rank: it.rank,
            of: self.policy.priority.len().max(1),
        }
    }
}

/// The requests the catalogue can serve, ranked (each degraded already when no implementation
/// of its version reaches its rate); the others dropped, with why.
fn admit(inp: &Inputs, ws: &mut ScheduleWorkspace, out: &mut Schedule) {
    let Inputs {
        catalogue,
        policy,
        requests,
        ..
    } = *inp;
    let vs = catalogue.variants();
    ws.items.clear();
    for (req, r) in requests.iter().enumerate() {
        if !catalogue.has_version(&r.app, &r.version) {
            let mut d = ws.dropped(&r.app, &r.version);
            let _ = write!(
                d.reason,
                "unknown variant {} {} (not in the catalogue)",
                r.app, r.version
            );
            out.dropped.push(d);
            continue;
        }
        // Seen: an earlier request of the same app that named a catalogue variant.
        let seen = requests[..req]
            .iter()
            .any(|p| p.app == r.app && catalogue.has_version(&p.app, &p.version));
        if seen {
            let mut d = ws.dropped(&r.app, &r.version);
            let _ = write!(
                d.reason,
                "duplicate request: {} already requested this cycle",
                r.app
            );
            out.dropped.push(d);
            continue;
        }
        if !(r.required_fps.is_finite() && r.required_fps > 0.0) {
            let mut d = ws.dropped(&r.app, &r.version);
            let _ = write!(d.reason, "invalid required rate {} fps", r.required_fps);
            out.dropped.push(d);
            continue;
        }
        let mut version = version_index(catalogue, &r.app, &r.version).unwrap_or(0);
        if !has_candidate(catalogue, &r.app, &r.version, r.required_fps) {
            implementations_into(catalogue, &r.app, &r.version, &mut ws.impls);
            let fastest = ws
                .impls
                .last()
                .map(|&k| vs[k].ms_per_frame())
                .unwrap_or(f64::INFINITY);
            let path = policy.degradation_path(&r.app, &r.version);
            let to = path
                .iter()
                .find(|v| has_candidate(catalogue, &r.app, v, r.required_fps));
            let why = |s: &mut String| {
                let _ = write!(
                    s,
                    "no implementation of {} {} reaches {:.1} fps (fastest {} ms per frame)",
                    r.app,
                    r.version,
                    r.required_fps,
                    FmtMs(fastest)
                );
            };
            match to.and_then(|v| Some((v, version_index(catalogue, &r.app, v)?))) {
                Some((v, vi)) => {
                    let mut d = ws.degradation();
                    set(&mut d.app, &r.app);
                    set(&mut d.from, &r.version);
                    set(&mut d.to, v);
                    why(&mut d.reason);
                    out.degraded.push(d);
                    version = vi;
                }
                None => {
                    let mut d = ws.dropped(&r.app, &r.version);
                    why(&mut d.reason);
                    out.dropped.push(d);
                    continue;
                }
            }
        }
        let rank = r
            .priority
            .map(|p| p as usize)
            .unwrap_or_else(|| policy.rank(&r.app));
        insert_ranked(
            &mut ws.items,
            Item {
                req,
                version,
                fps: r.required_fps,
                rank,
            },
        );
    }
}

/// Resolve: while the set does not fit, the least important application first tries its
/// degradation path, then gives way.
fn resolve(
    inp: &Inputs,
    room: Room,
    active: &mut Vec<Item>,
    ws: &mut ScheduleWorkspace,
    out: &mut Schedule,
) {
    let Inputs {
        catalogue,
        policy,
        requests,
        ..
    } = *inp;
    let vs = catalogue.variants();
    let rank_text = |it: &Item| inp.rank_text(it);
    ws.given_way.clear();
    loop {
        if search(catalogue, requests, active, room, ws) {
            break;
        }
        let last = active.pop().expect("the empty set always fits");
        let app = &requests[last.req].app;
        let from = &vs[last.version].version;
        let mut fixed = None;
        for v in policy.degradation_path(app, from) {
            let Some(vi) = version_index(catalogue, app, v) else {
                continue;
            };
            if !has_candidate(catalogue, app, v, last.fps) {
                continue;
            }
            active.push(Item {
                version: vi,
                ..last
            });
            if search(catalogue, requests, active, room, ws) {
                fixed = Some(v);
                break;
            }
            active.pop();
        }
        if let Some(v) = fixed {
            let d = ws.degraded(
                (app, from, v),
                format_args!(
                    "insufficient resources to execute {} {} at {:.1} fps ({} healthy tiles, cpu headroom {:.3}); {}",
                    app,
                    from,
                    last.fps,
                    room.tiles,
                    room.cpu.max(0.0),
                    rank_text(&last)
                ),
            );
            out.degraded.push(d);
            break;
        }
        ws.given_way.push(last);
    }
    ws.choice.clone_from(&ws.chosen);
}

fn replace_given_way(
    inp: &Inputs,
    room: Room,
    active: &mut Vec<Item>,
    ws: &mut ScheduleWorkspace,
    out: &mut Schedule,
) {
    let Inputs {
        catalogue,
        policy,
        requests,
        ..
    } = *inp;
    let vs = catalogue.variants();
    let rank_text = |it: &Item| inp.rank_text(it);
    // Re-place what now fits among those that gave way, most important first: dropping a more
    // important application may have freed room for a less important one.
    ws.still_out.clear();
    while let Some(item) = ws.given_way.pop() {
        let app = &requests[item.req].app;
        let requested = &vs[item.version].version;
        let path = policy.degradation_path(app, requested);
        let mut placed = false;
        for v in std::iter::once(requested).chain(path) {
            let Some(vi) = version_index(catalogue, app, v) else {
                continue;
            };
            if !has_candidate(catalogue, app, v, item.fps) {
                continue;
            }
            let pos = insert_ranked(
                active,
                Item {
                    version: vi,
                    ..item
                },
            );
            if search(catalogue, requests, active, room, ws) {
                if v != requested {
                    let d = ws.degraded(
                        (app, requested, v),
                        format_args!(
                            "insufficient resources to execute {} {}; {}",
                            app,
                            requested,
                            rank_text(&item)
                        ),
                    );
                    out.degraded.push(d);
                }
                ws.choice.clone_from(&ws.chosen);
                placed = true;
                break;
            }
            active.remove(pos);
        }
        if !placed {
            ws.still_out.push(item);
        }
    }
}
