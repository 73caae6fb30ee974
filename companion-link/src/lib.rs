//! MAVLink to the autopilot without I/O: connection URLs, frame ingest and signing, and the
//! sans-IO protocol clients (commands, missions, liveness, readiness, modes, telemetry, the
//! vehicle) that the `companion` binary's `fly` shell drives over its sockets and serial ports.
//! Every state machine here takes the clock as a value (`now: Duration`) and returns the
//! messages to send and the events that happened, so tests need no sockets.
//!
//! Protocol reference: docs/mavlink.md.
//!
//! # Layout
//! - `url`: connection strings (MAVSDK forms and serial paths).
//! - `ingest`: frame parsing, counting of malformed frames, MAVLink 2 signing.
//! - `command`: COMMAND_LONG/INT with acknowledgement, retry and timeout.
//! - `mission`: the mission upload protocol.
//! - `liveness`: heartbeats in and out, link-loss detection.
//! - `readiness`: whether the autopilot says it can arm (pre-arm checks, EKF, GPS).
//! - `modes`: flight modes per autopilot (ArduPilot custom modes, PX4 main/sub modes).
//! - `telemetry`: streams requested and telemetry turned into observations.
//! - `actions`: the vehicle actions of `commands.toml` as MAVLink steps; `link.toml`; the route.
//! - `mission_state`: the mission state and end of flight estimated from telemetry.
//! - `operator`: the operator gate (who starts the mission, pilot takeover, STATUSTEXT).
//! - `vehicle`: one autopilot, all of the above composed; what `fly` drives each tick.

pub mod actions;
pub mod command;
pub mod ground_values;
pub mod ingest;
pub mod liveness;
pub mod mission;
pub mod mission_state;
pub mod modes;
pub mod operator;
pub mod readiness;
pub mod restart_in_air;
pub mod telemetry;
pub mod url;
pub mod vehicle;

/// The dialect we speak: ArduPilot's superset of `common`.
pub use mavlink::dialects::ardupilotmega as dialect;
/// One decoded MAVLink message.
pub type Msg = dialect::MavMessage;

/// The MAVLink name of a value of a generated enum (`MAV_CMD_NAV_TAKEOFF`, `MAV_RESULT_DENIED`),
/// from its serde form `{"type": NAME}`: the form commands.toml is read in (so a name written
/// to the log reads back), never the `Debug` text.
pub fn mavlink_name<T: serde::Serialize>(value: &T) -> String {
    match serde_json::to_value(value) {
        Ok(serde_json::Value::Object(mut m)) => match m.remove("type") {
            Some(serde_json::Value::String(name)) => name,
            _ => "?".to_string(),
        },
        _ => "?".to_string(),
    }
}

/// Text from the link (a STATUSTEXT) as a quoted string literal with escapes, so a control
/// character is seen in the record, not sent to a terminal. The one use of `Debug` for a
/// record: a `str`'s Debug form is exactly that quoting.
pub fn quoted(text: &str) -> String {
    format!("{text:?}")
}

/// MAV_COMP_ID_ONBOARD_COMPUTER: the component id this companion uses.
pub const OUR_COMPONENT_ID: u8 = 191;
/// System id used before the autopilot's is learned from its HEARTBEAT (MAVLink default vehicle id).
pub const DEFAULT_SYSTEM_ID: u8 = 1;

/// The unit tests' access to params files on disk (the crate itself is handed params as data).
#[cfg(test)]
pub(crate) mod test_support {
    use companion_core::spec::ParamsFiles;
    use std::path::{Path, PathBuf};

    /// The repository's params/.
    pub(crate) fn default_params_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../params")
    }

    /// The shipped action catalogue (params/actions.toml).
    pub(crate) fn catalogue() -> companion_core::mission::ActionCatalogue {
        let dir = default_params_dir();
        let mut files = ParamsFiles::new(&dir);
        let p = dir.join("actions.toml");
        files.insert(p.clone(), std::fs::read_to_string(&p).unwrap());
        companion_core::mission::ActionCatalogue::load(&files).unwrap()
    }

    /// params/commands.toml-like file `path` from disk, resolved against [`catalogue`].
    pub(crate) fn commands(
        path: &Path,
    ) -> Result<crate::actions::ActionTable, companion_core::spec::SpecError> {
        let mut files = ParamsFiles::new(path.parent().unwrap_or(Path::new(".")));
        match std::fs::read(path) {
            Ok(b) => files.insert_bytes(path, &b),
            Err(e) => files.insert_unreadable(path, format!("cannot read: {e}")),
        }
        crate::actions::ActionTable::load(&files, path, &catalogue())
    }

    /// A loader of one file from disk: `disk(LinkParams::load)(&path)`.
    pub(crate) fn disk<T>(load: fn(&ParamsFiles, &Path) -> T) -> impl Fn(&Path) -> T {
        move |path: &Path| {
            let mut files = ParamsFiles::new(path.parent().unwrap_or(Path::new(".")));
            match std::fs::read(path) {
                Ok(b) => files.insert_bytes(path, &b),
                Err(e) => files.insert_unreadable(path, format!("cannot read: {e}")),
            }
            load(&files, path)
        }
    }
}
