//! One fuzz input, end to end: the functions the coverage-guided fuzz targets in `fuzz/` call,
//! and that `companion/tests/fuzz_corpus.rs` replays on stable Rust (docs/fuzzing.md).
//!
//! Two paths take bytes from outside the process:
//! - [`ingest_one`]: MAVLink bytes from the autopilot or an onboard monitor, through
//!   [`Ingest::push`] (split into chunks at positions the input chooses), the [`Vehicle`]
//!   protocol state and its telemetry, the mission-state estimator and a decision cycle of the
//!   real core, exactly as `companion fly` chains them (`link::fly::run_cycle_at`), minus the
//!   sockets and the clock (time advances by a step the input chooses).
//! - [`params_one`]: one params file's text replaced by the input (through
//!   an in-memory [`ParamsFiles`] copy with that file replaced), then the whole start-up load: `Model::load`, the simulation
//!   world and a scenario, a PANORAMA mission, the fly setup and `companion check`'s report.
//!
//! Both panic when an invariant breaks (that is how a fuzzer sees it); neither panics otherwise,
//! whatever the bytes.

use companion::decider::CoreDecider;
use companion::fly::{self, FlyArgs, FlySetup, Shell};
use companion_core::decision::{Model, ModelKind};
use companion_core::spec::{ParamsFiles, SpecError};
use companion_link::Msg;
use companion_link::actions::LinkParams;
use companion_link::ingest::{self, Encoder, Ingest, IngestStats};
use companion_link::mission_state::MissionState;
use companion_link::vehicle::{Vehicle, VehicleConfig};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

/// The signing key the ingest target uses when an input turns signing on. Fixed, so that the
/// seed corpus can hold frames signed with it (and the fuzzer can reach the verify-ok path).
pub const FUZZ_SIGNING_KEY: [u8; 32] = [0x42; 32];

/// Shortest CRC-valid frame: MAVLink 1 header (6) + CRC (2), empty payload.
const MIN_FRAME_BYTES: u64 = 8;

/// Decision cycles per input at most (the core is the slow part; more adds little coverage).
pub const MAX_CYCLES: usize = 8;

/// What `companion fly` loads before any socket opens, loaded once per fuzzing process.
pub struct IngestFixture {
    pub model: Arc<Model>,
    /// What `companion fly` loads besides the model (link, actions, route, take-off altitude).
    pub setup: FlySetup,
}

impl IngestFixture {
    /// Load from a params directory the way `companion fly --params DIR` does.
    pub fn load(params: &Path) -> anyhow::Result<Self> {
        Ok(Self {
            model: Arc::new(companion::params::load_model(params)?),
            setup: FlySetup::load(&fly_args(params))?,
        })
    }

    /// The vehicle configuration `link::fly::run_with_tlog` builds from params.
    fn vehicle_config(&self) -> VehicleConfig {
        vehicle_config(&self.setup.link, Duration::from_secs(3))
    }
}

/// Fly arguments naming only a params directory (the connect URL is never opened here).
fn fly_args(params: &Path) -> FlyArgs {
    let mut args = FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550", "--auto-start"])
        .expect("valid literal arguments");
    args.params = Some(params.to_path_buf());
    args
}

/// As in `link::fly::run_with_tlog`: the protocol configuration from `params/link.toml`.
fn vehicle_config(link: &LinkParams, link_timeout: Duration) -> VehicleConfig {
    VehicleConfig {
        link_timeout,
        streams: link.stream_ids(),
        streams_not_sent: link.streams_not_sent(),
        telemetry: link.telemetry.clone(),
        arm_wait: Duration::from_secs_f64(link.arm_wait_s),
        max_arm_attempts: link.max_arm_attempts,
        ..VehicleConfig::default()
    }
}

/// How one ingest input is read: `[flags][n][len_1 .. len_n][stream ...]`.
///
/// `flags` bit 0: signing on (key [`FUZZ_SIGNING_KEY`]); bit 1: mission-first policy (else
/// safety-first); bit 2: odd chunks arrive on the `--onboard` link instead of the autopilot's;
/// bit 3: a transport reconnect after the first half of the chunks; bits 4-5: the clock step
/// per chunk (10 ms, 100 ms, 1 s, 5 s: the last two let the link time out).
/// The stream is cut into chunks of `len_1 + 1`, `len_2 + 1`, ... bytes, cycling, with
/// `n = (byte 1 % 8) + 1`; missing header bytes read as zero.
#[derive(Debug, Clone, PartialEq)]
pub struct IngestInput<'a> {
    pub signing: bool,
    /// The policy's name in params/policies.toml.
    pub policy: &'static str,
    pub onboard_odd_chunks: bool,
    pub reconnect: bool,
    pub step: Duration,
    pub chunk_lens: Vec<usize>,
    pub stream: &'a [u8],
}

impl<'a> IngestInput<'a> {
    pub fn parse(data: &'a [u8]) -> Self {
        let at = |i: usize| data.get(i).copied().unwrap_or(0);
        let flags = at(0);
        let n = (at(1) % 8) as usize + 1;
        let chunk_lens = (0..n).map(|i| at(2 + i) as usize + 1).collect();
        let stream = data.get(2 + n..).unwrap_or(&[]);
        let step = [10, 100, 1000, 5000][((flags >> 4) & 3) as usize];
        Self {
            signing: flags & 1 != 0,
            policy: if flags & 2 != 0 { "mission" } else { "safety" },
            onboard_odd_chunks: flags & 4 != 0,
            reconnect: flags & 8 != 0,
            step: Duration::from_millis(step),
            chunk_lens,
            stream,
        }
    }

    /// The inverse of [`IngestInput::parse`] for seeds: `flags`, chunk lengths (1..=256) and a stream.
    pub fn encode(flags: u8, chunk_lens: &[usize], stream: &[u8]) -> Vec<u8> {
        assert!((1..=8).contains(&chunk_lens.len()));
        let mut out = vec![flags, (chunk_lens.len() - 1) as u8];
        out.extend(chunk_lens.iter().map(|&l| (l.clamp(1, 256) - 1) as u8));
        out.extend_from_slice(stream);
        out
    }

    /// The stream cut into chunks as described on the type.
    pub fn chunks(&self) -> Vec<&'a [u8]> {
        let mut out = Vec::new();
        let mut rest = self.stream;
        for len in self.chunk_lens.iter().cycle() {
            if rest.is_empty() {
                break;
            }
            let (c, r) = rest.split_at((*len).min(rest.len()));
            out.push(c);
            rest = r;
        }
        out
    }
}

/// What one ingest input did (for tests and corpus statistics).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct IngestOutcome {
    pub stats: IngestStats,
    pub onboard_stats: IngestStats,
    pub frames: u64,
    pub cycles: usize,
    pub messages_out: u64,
    /// Vehicle actions the cycles chose, in order.
    pub chosen: Vec<String>,
}

/// Check the counters of one [`Ingest`] after a push. `pushed`: bytes pushed so far; `returned`:
/// frames returned so far; `was`: the counters before this push.
fn check_stats(s: &IngestStats, was: &IngestStats, pushed: u64, returned: u64, signing: bool) {
    assert_eq!(s.bytes_in, pushed, "bytes_in counts every byte pushed");
    assert!(
        s.frame_bytes <= s.bytes_in,
        "frame_bytes <= bytes_in: {s:?}"
    );
    assert_eq!(
        s.frames_ok, returned,
        "frames_ok counts the frames returned"
    );
    let framed = s.frames_ok + s.frames_malformed + s.bad_signatures + s.unsigned_commands_refused;
    assert!(
        s.frame_bytes >= MIN_FRAME_BYTES * framed,
        "every counted frame is at least {MIN_FRAME_BYTES} bytes: {s:?}"
    );
    if !signing {
        assert_eq!(s.bad_signatures, 0, "no signature is checked without a key");
        assert_eq!(
            s.unsigned_commands_refused, 0,
            "nothing is refused without a key"
        );
    }
    for (now, before) in [
        (s.frame_bytes, was.frame_bytes),
        (s.frames_malformed, was.frames_malformed),
        (s.bad_signatures, was.bad_signatures),
        (s.unsigned_commands_refused, was.unsigned_commands_refused),
    ] {
        assert!(now >= before, "counters never go down: {was:?} -> {s:?}");
    }
}

/// Outgoing messages, encoded as the fly loop does; each must decode back to itself.
fn send(encoder: &mut Encoder, vehicle: &Vehicle, signing: bool, msgs: &[Msg]) -> u64 {
    encoder.system_id = vehicle.our_system();
    for m in msgs {
        let bytes = encoder.encode(m);
        let mut back = Ingest::new(signing.then(|| ingest::signing_data(FUZZ_SIGNING_KEY)));
        let frames = back.push(&bytes);
        assert_eq!(frames.len(), 1, "our own frame decodes: {m:?}");
        // Debug text, not `==`: a NaN parameter (DO_REPOSITION's "keep yaw") is not equal to itself.
        assert_eq!(
            format!("{:?}", frames[0].msg),
            format!("{m:?}"),
            "our own frame round-trips"
        );
        assert_eq!(frames[0].signed, signing);
    }
    msgs.len() as u64
}

/// One decision cycle exactly as `companion fly` runs it (`link::fly::decide` then
/// `finish_record`), without the sink and the socket; the record must serialise to JSON.
fn cycle(
    core: &mut CoreDecider,
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    now: Duration,
    n: u64,
) -> (Option<String>, Vec<Msg>) {
    let decided = fly::decide(core, shell, vehicle, || now);
    let chosen = decided
        .chosen
        .map(|f| vehicle.actions().name(f).to_string());
    let msgs = decided.msgs.clone();
    let rec = fly::finish_record(decided, shell, vehicle, n, &mut Vec::new());
    serde_json::to_string(&rec).expect("a decision record serialises");
    (chosen, msgs)
}

/// Run one ingest input (see [`IngestInput`]); panics only when an invariant breaks.
pub fn ingest_one(fx: &IngestFixture, data: &[u8]) -> IngestOutcome {
    let input = IngestInput::parse(data);
    let signing = || {
        input
            .signing
            .then(|| ingest::signing_data(FUZZ_SIGNING_KEY))
    };
    let mut ingest = Ingest::new(signing());
    let mut onboard = Ingest::new(signing());
    let mut encoder = Encoder::new(signing());
    let mut vehicle = Vehicle::new(
        fx.vehicle_config(),
        fx.setup.actions.clone(),
        Some(fx.setup.route.clone()),
    );
    let mut shell = Shell::new(&fx.setup);
    let policy = fx
        .model
        .policy(input.policy)
        .expect("a policy of the shipped params");
    let mut core = CoreDecider::new(Arc::clone(&fx.model), ModelKind::Bfm, policy, None);
    let mut out = IngestOutcome::default();
    let (mut pushed, mut returned) = (0u64, 0u64);
    let (mut ob_pushed, mut ob_returned) = (0u64, 0u64);
    let chunks = input.chunks();
    let mut now = Duration::ZERO;
    for (i, chunk) in chunks.iter().enumerate() {
        now += input.step;
        if input.reconnect && i == chunks.len() / 2 && i > 0 {
            ingest.reset();
            vehicle.on_reconnect(now);
        }
        let mut msgs = Vec::new();
        if input.onboard_odd_chunks && i % 2 == 1 {
            let was = onboard.stats;
            let frames = onboard.push(chunk);
            ob_pushed += chunk.len() as u64;
            ob_returned += frames.len() as u64;
            check_stats(&onboard.stats, &was, ob_pushed, ob_returned, input.signing);
            for f in &frames {
                msgs.extend(vehicle.on_monitor_frame(now, f));
            }
            out.frames += frames.len() as u64;
        } else {
            let was = ingest.stats;
            let frames = ingest.push(chunk);
            pushed += chunk.len() as u64;
            returned += frames.len() as u64;
            check_stats(&ingest.stats, &was, pushed, returned, input.signing);
            if input.signing {
                for f in &frames {
                    let to_us_unsigned = !f.signed
                        && matches!(
                            &f.msg,
                            Msg::COMMAND_LONG(c) if (c.target_system == vehicle.our_system() || c.target_system == 0)
                                && (c.target_component == companion_link::OUR_COMPONENT_ID || c.target_component == 0)
                        );
                    assert!(!to_us_unsigned, "an unsigned command to us got through");
                }
            }
            for f in &frames {
                msgs.extend(vehicle.on_frame(now, f));
            }
            ingest.set_our_system(vehicle.our_system());
            out.frames += frames.len() as u64;
        }
        msgs.extend(vehicle.tick(now));
        out.messages_out += send(&mut encoder, &vehicle, input.signing, &msgs);
        if vehicle.has_events() && vehicle.target().is_some() && out.cycles < MAX_CYCLES {
            let (chosen, msgs) = {
                out.cycles += 1;
                cycle(&mut core, &mut shell, &mut vehicle, now, out.cycles as u64)
            };
            out.chosen.extend(chosen);
            out.messages_out += send(&mut encoder, &vehicle, input.signing, &msgs);
        }
    }
    // One last cycle on whatever the telemetry holds, autopilot seen or not: the core must take
    // any observation snapshot the link can produce.
    now += input.step;
    out.cycles += 1;
    let (chosen, msgs) = cycle(&mut core, &mut shell, &mut vehicle, now, out.cycles as u64);
    out.chosen.extend(chosen);
    out.messages_out += send(&mut encoder, &vehicle, input.signing, &msgs);
    assert_eq!(encoder.frames_out, out.messages_out);
    out.stats = ingest.stats;
    out.onboard_stats = onboard.stats;
    out
}

/// The params files the start-up load reads, relative to the params directory, sorted:
/// `*.toml`, `health/*.toml`, `mdp/*.toml`, `missions/*.toml`, `scenarios/*.toml`.
pub struct ParamsFixture {
    pub dir: PathBuf,
    pub files: Vec<PathBuf>,
    /// Every params file as read once; an input replaces one of them in a copy.
    pub params: ParamsFiles,
}

/// Sub-directories of params/ whose files the loaders read.
pub const PARAMS_SUBDIRS: [&str; 4] = ["health", "mdp", "missions", "scenarios"];

impl ParamsFixture {
    pub fn new(dir: &Path) -> std::io::Result<Self> {
        let dir = std::path::absolute(dir)?;
        let mut files = Vec::new();
        for sub in std::iter::once("").chain(PARAMS_SUBDIRS) {
            for e in std::fs::read_dir(dir.join(sub))? {
                let p = e?.path();
                if p.is_file() && p.extension().is_some_and(|x| x == "toml") {
                    files.push(p.strip_prefix(&dir).expect("under dir").to_path_buf());
                }
            }
        }
        files.sort();
        let params = companion::params::read_params_dir(&dir)
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        Ok(Self { dir, files, params })
    }

    /// The file an input's first byte picks.
    pub fn pick(&self, first: u8) -> &Path {
        &self.files[first as usize % self.files.len()]
    }

    /// A seed input for file `i`: its index byte and its real text.
    pub fn seed(&self, i: usize) -> std::io::Result<Vec<u8>> {
        let mut v = vec![i as u8];
        v.extend(std::fs::read(self.dir.join(&self.files[i]))?);
        Ok(v)
    }
}

/// What the start-up load made of one params input.
#[derive(Debug, Clone, Default)]
pub struct ParamsOutcome {
    pub file: PathBuf,
    /// Per loader (`model`, `world`, `scenario`, `mission`, `fly`, `check`): `None` when it
    /// loaded, else the error.
    pub errors: Vec<(&'static str, Option<SpecError>)>,
    /// Decision cycles run on the loaded params (a few simulation steps) when everything loaded.
    pub cycles: usize,
}

impl ParamsOutcome {
    /// Every loader accepted the input.
    pub fn all_ok(&self) -> bool {
        self.errors.iter().all(|(_, e)| e.is_none())
    }
}

/// A loader error must say where and why: a file and a reason (the entry may be `-`).
fn check_error(what: &str, e: &SpecError) {
    assert!(
        !e.file.as_os_str().is_empty(),
        "{what}: error names no file: {e:?}"
    );
    assert!(
        !e.reason.trim().is_empty(),
        "{what}: error gives no reason: {e:?}"
    );
    assert!(!e.entry.is_empty(), "{what}: error names no entry: {e:?}");
}

/// `companion check`'s errors are anyhow chains; the cause must be a [`SpecError`].
fn spec_error_of(e: &anyhow::Error) -> SpecError {
    match e.chain().find_map(|c| c.downcast_ref::<SpecError>()) {
        Some(s) => s.clone(),
        None => panic!("an error without file/entry/reason: {e:#}"),
    }
}

/// Simulation steps run on params that loaded (the first cycles of `companion simulate`).
pub const PARAMS_SIM_STEPS: u32 = 3;

/// Run one params input: byte 0 picks the file ([`ParamsFixture::pick`]), the rest is its
/// text; every other file is the real one. Panics only when an invariant breaks.
pub fn params_one(fx: &ParamsFixture, data: &[u8]) -> ParamsOutcome {
    let Some((&first, text)) = data.split_first() else {
        return ParamsOutcome::default();
    };
    let rel = fx.pick(first).to_path_buf();
    let path = fx.dir.join(&rel);
    let dir = fx.dir.as_path();
    let stem = rel
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("")
        .to_string();
    let in_dir = |d: &str| rel.parent() == Some(Path::new(d));
    let scenario = if in_dir("scenarios") {
        stem.clone()
    } else {
        "complete-1".into()
    };
    // Route files (`*_route*.toml`: the default and the long route) are routes, not PANORAMA
    // missions: the mission planned with them is the tracking one.
    let is_route = stem.contains("_route");
    let panorama_mission = if in_dir("missions") && !is_route {
        stem.clone()
    } else {
        "tracking".into()
    };
    let mut files = fx.params.clone();
    files.insert_bytes(&path, text);
    let files = &files;
    {
        let mut out = ParamsOutcome {
            file: rel.clone(),
            ..Default::default()
        };
        let mut record = |what: &'static str, e: Option<SpecError>| {
            if let Some(e) = &e {
                check_error(what, e);
            }
            out.errors.push((what, e));
        };
        let model = Model::load(files).map(Arc::new);
        record("model", model.as_ref().err().cloned());
        let world = companion::sim::WorldSpec::load(files);
        record("world", world.as_ref().err().cloned());
        let scen = companion::sim::Scenario::load(files, &scenario);
        record("scenario", scen.as_ref().err().cloned());
        let mission = companion_core::guarantee::load_mission(files, &panorama_mission);
        record("mission", mission.as_ref().err().cloned());
        let fly = FlySetup::from_files(files, &fly_args(dir));
        let fly_err = fly.as_ref().err().map(spec_error_of);
        record("fly", fly_err);
        if let Ok(setup) = &fly {
            // What `fly` does next with these numbers (Durations, the mission-state estimator).
            let _ = vehicle_config(&setup.link, Duration::from_secs(3));
            let _ = Duration::from_secs_f64(setup.link.decision_period_s);
            let _ = MissionState::new(
                &setup.route,
                setup.takeoff_alt_m,
                setup.states.clone(),
                &setup.catalogue,
            );
            let _ = setup.route.items((0, 0));
        }
        let args = companion::check::CheckArgs {
            params: Some(dir.to_path_buf()),
            mission: Some(panorama_mission.clone()),
            ..Default::default()
        };
        let check = companion::check::report_from(files.clone(), &args);
        record("check", check.as_ref().err().map(spec_error_of));
        // Whatever loaded must fly: a few simulation steps with the real core.
        if let (Ok(model), Ok(world), Ok(mut scen)) = (&model, &world, scen) {
            scen.steps = scen.steps.min(PARAMS_SIM_STEPS);
            for name in &model.policies {
                let policy = model.policy(name).expect("a policy of this model");
                let mut core = CoreDecider::new(Arc::clone(model), ModelKind::Bfm, policy, None);
                let run = companion::sim::run_cycle(world, &scen, 1, &mut core);
                out.cycles += run.records.len();
            }
        }
        out
    }
}

/// Seed inputs for the ingest target: well-formed telemetry as ArduPilot and onboard monitors
/// send it, so the fuzzer starts past the framing and into the protocol and decision code.
/// `(name, input)`; written to fuzz/corpus/mavlink_ingest/ by `fuzz/seed.sh`.
pub fn ingest_seeds() -> Vec<(String, Vec<u8>)> {
    use companion_link::dialect::*;
    use mavlink::{MavHeader, SigningData};
    let ap = (1u8, 1u8);
    // MAV_COMP_ID_CAMERA: a monitor params/link.toml [telemetry.monitors] allows.
    let monitor = (1u8, 100u8);
    let gcs = (255u8, 190u8);
    let heartbeat = |armed: bool, mode: u32| {
        Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: mode,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: if armed {
                MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                    | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
            } else {
                MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            },
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        })
    };
    let nvf = |n: &str, v: f32| {
        Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
            time_boot_ms: 1000,
            value: v,
            name: n.into(),
        })
    };
    let position = |alt_mm: i32| {
        Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            time_boot_ms: 1000,
            lat: 435_600_000,
            lon: 14_500_000,
            alt: 150_000 + alt_mm,
            relative_alt: alt_mm,
            vx: 300,
            vy: 100,
            vz: 0,
            hdg: 9000,
        })
    };
    let telemetry = vec![
        (ap, heartbeat(false, 4)),
        (
            ap,
            Msg::SYSTEM_TIME(SYSTEM_TIME_DATA {
                time_unix_usec: 0,
                time_boot_ms: 1000,
            }),
        ),
        (
            ap,
            Msg::SYS_STATUS(SYS_STATUS_DATA {
                voltage_battery: 12_400,
                battery_remaining: 55,
                ..SYS_STATUS_DATA::DEFAULT
            }),
        ),
        (
            ap,
            Msg::GPS_RAW_INT(GPS_RAW_INT_DATA {
                fix_type: GpsFixType::GPS_FIX_TYPE_3D_FIX,
                satellites_visible: 12,
                ..GPS_RAW_INT_DATA::DEFAULT
            }),
        ),
        (
            ap,
            Msg::HOME_POSITION(HOME_POSITION_DATA {
                latitude: 435_600_000,
                longitude: 14_500_000,
                altitude: 150_000,
                ..HOME_POSITION_DATA::DEFAULT
            }),
        ),
        (ap, position(0)),
        (
            ap,
            Msg::EKF_STATUS_REPORT(EKF_STATUS_REPORT_DATA {
                flags: EkfStatusFlags::all(),
                ..EKF_STATUS_REPORT_DATA::DEFAULT
            }),
        ),
        (ap, heartbeat(true, 4)),
        (ap, position(12_000)),
        (
            ap,
            Msg::VIBRATION(VIBRATION_DATA {
                vibration_x: 35.0,
                vibration_y: 12.0,
                vibration_z: 20.0,
                ..VIBRATION_DATA::DEFAULT
            }),
        ),
        (
            ap,
            Msg::WIND(WIND_DATA {
                direction: 180.0,
                speed: 9.0,
                speed_z: 0.0,
            }),
        ),
        (
            ap,
            Msg::EXTENDED_SYS_STATE(EXTENDED_SYS_STATE_DATA {
                landed_state: MavLandedState::MAV_LANDED_STATE_IN_AIR,
                ..EXTENDED_SYS_STATE_DATA::DEFAULT
            }),
        ),
        (
            ap,
            Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
                seq: 3,
                ..MISSION_CURRENT_DATA::DEFAULT
            }),
        ),
        (
            ap,
            Msg::DISTANCE_SENSOR(DISTANCE_SENSOR_DATA {
                min_distance: 20,
                max_distance: 4000,
                current_distance: 900,
                orientation: MavSensorOrientation::MAV_SENSOR_ROTATION_NONE,
                ..DISTANCE_SENSOR_DATA::DEFAULT
            }),
        ),
        (
            ap,
            Msg::BATTERY_STATUS(BATTERY_STATUS_DATA {
                battery_remaining: 18,
                energy_consumed: 900,
                current_consumed: 2000,
                ..BATTERY_STATUS_DATA::DEFAULT
            }),
        ),
        (
            ap,
            Msg::COMMAND_ACK(COMMAND_ACK_DATA {
                command: MavCmd::MAV_CMD_NAV_TAKEOFF,
                result: MavResult::MAV_RESULT_ACCEPTED,
                ..COMMAND_ACK_DATA::DEFAULT
            }),
        ),
        (
            ap,
            Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
                seq: 0,
                target_system: 1,
                target_component: 191,
                ..MISSION_REQUEST_INT_DATA::DEFAULT
            }),
        ),
        (
            ap,
            Msg::STATUSTEXT(STATUSTEXT_DATA {
                severity: MavSeverity::MAV_SEVERITY_WARNING,
                text: "PreArm: Gyros inconsistent".into(),
                ..STATUSTEXT_DATA::DEFAULT
            }),
        ),
        (monitor, nvf("tgt_det", 0.9)),
        (monitor, nvf("tgt_spd", 0.4)),
        (monitor, nvf("lum", 20.0)),
        (monitor, nvf("cpu_load", 0.7)),
        (monitor, nvf("free_tiles", 2.0)),
        (
            monitor,
            Msg::CAMERA_TRACKING_IMAGE_STATUS(CAMERA_TRACKING_IMAGE_STATUS_DATA {
                tracking_status: CameraTrackingStatusFlags::CAMERA_TRACKING_STATUS_FLAGS_ACTIVE,
                point_x: 0.5,
                point_y: 0.4,
                ..CAMERA_TRACKING_IMAGE_STATUS_DATA::DEFAULT
            }),
        ),
        (
            monitor,
            Msg::OBSTACLE_DISTANCE(OBSTACLE_DISTANCE_DATA {
                distances: [500; 72],
                min_distance: 20,
                max_distance: 4000,
                increment: 5,
                ..OBSTACLE_DISTANCE_DATA::DEFAULT
            }),
        ),
        (ap, heartbeat(true, 9)),
        (
            ap,
            Msg::EXTENDED_SYS_STATE(EXTENDED_SYS_STATE_DATA {
                landed_state: MavLandedState::MAV_LANDED_STATE_ON_GROUND,
                ..EXTENDED_SYS_STATE_DATA::DEFAULT
            }),
        ),
        (ap, heartbeat(false, 9)),
    ];
    let arm = Msg::COMMAND_LONG(COMMAND_LONG_DATA {
        command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        target_system: 1,
        target_component: companion_link::OUR_COMPONENT_ID,
        param1: 1.0,
        ..COMMAND_LONG_DATA::DEFAULT
    });
    let encode = |msgs: &[((u8, u8), Msg)], v1: bool, signing: Option<&SigningData>| {
        let mut buf = Vec::new();
        for (seq, ((sys, comp), m)) in msgs.iter().enumerate() {
            let h = MavHeader {
                system_id: *sys as u32,
                component_id: *comp,
                sequence: seq as u8,
            };
            // Writing into a Vec cannot fail.
            let _ = if v1 {
                mavlink::write_v1_msg(&mut buf, h, m)
            } else {
                mavlink::write_v2_msg_signed(&mut buf, h, m, signing)
            };
        }
        buf
    };
    let key = ingest::signing_data(FUZZ_SIGNING_KEY);
    let plain = encode(&telemetry, false, None);
    let mut seeds = vec![
        (
            "telemetry_v2".to_string(),
            IngestInput::encode(0x10, &[64, 17, 200], &plain),
        ),
        (
            "telemetry_v2_bytewise".into(),
            IngestInput::encode(0x00, &[1], &plain),
        ),
        (
            "telemetry_v1".into(),
            IngestInput::encode(0x10, &[40], &encode(&telemetry, true, None)),
        ),
        (
            "telemetry_signed".into(),
            IngestInput::encode(0x11, &[100, 3], &encode(&telemetry, false, Some(&key))),
        ),
        (
            "telemetry_onboard_mission_policy".into(),
            IngestInput::encode(0x16, &[30, 50], &plain),
        ),
        (
            "telemetry_link_timeouts_reconnect".into(),
            IngestInput::encode(0x38, &[90], &plain),
        ),
    ];
    let mut cmds = encode(&[(gcs, arm.clone())], false, None);
    cmds.extend(encode(
        &[(gcs, arm)],
        false,
        Some(&ingest::signing_data(FUZZ_SIGNING_KEY)),
    ));
    cmds.extend(encode(
        &telemetry[..3],
        false,
        Some(&ingest::signing_data([9; 32])),
    ));
    seeds.push((
        "commands_signing".into(),
        IngestInput::encode(0x01, &[256], &cmds),
    ));
    let mut noisy = b"\xfd\x00\xfe garbage \xfd\xff".to_vec();
    noisy.extend(&plain[..plain.len() / 2]);
    noisy.extend([0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0]);
    noisy.extend(&plain[plain.len() / 2..]);
    seeds.push((
        "noisy".into(),
        IngestInput::encode(0x20, &[7, 255, 1], &noisy),
    ));
    seeds
}
