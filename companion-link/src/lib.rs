//! MAVLink link to the autopilot: connection URLs, byte transports, frame ingest and signing, and
//! the sans-IO protocol clients (commands, missions, liveness, readiness, modes, telemetry) that
//! the `fly` shell drives. Every state machine here takes the clock as a value (`now: Duration`)
//! and returns the messages to send and the events that happened, so tests need no sockets.
//!
//! Protocol reference: docs/mavlink.md.

pub mod actions;
pub mod command;
pub mod fly;
pub mod ingest;
pub mod liveness;
pub mod mission;
pub mod mission_state;
pub mod modes;
pub mod operator;
pub mod readiness;
pub mod telemetry;
pub mod transport;
pub mod url;
pub mod vehicle;

/// The dialect we speak: ArduPilot's superset of `common`.
pub use mavlink::dialects::ardupilotmega as dialect;
/// One decoded MAVLink message.
pub type Msg = dialect::MavMessage;

/// MAV_COMP_ID_ONBOARD_COMPUTER: the component id this companion uses.
pub const OUR_COMPONENT_ID: u8 = 191;
/// System id used before the autopilot's is learned from its HEARTBEAT (MAVLink default vehicle id).
pub const DEFAULT_SYSTEM_ID: u8 = 1;
