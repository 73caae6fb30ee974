//! The decision channels: one definition of the topics, schemas and messages a record is told
//! in, used by `export --format mcap` (the file) and `--live` (the Foxglove WebSocket server),
//! so the file and the live view always carry the same channels.
//!
//! One channel per record field group (`/decisions/summary`, `/decisions/probabilities`, ...),
//! JSON messages with a JSON schema; each message holds the record's `cycle` and `time_s` and
//! the group's fields at top level, where plotting tools look.

use companion_core::record::DecisionRecord;

/// Record field groups, each a channel.
pub const GROUPS: [&str; 10] = [
    "summary",
    "observations",
    "evidence",
    "probabilities",
    "proposals",
    "conflicts",
    "resources",
    "guarantee",
    "commands",
    "vehicle",
];

/// Message encoding of every decision channel.
pub const MESSAGE_ENCODING: &str = "json";
/// Schema encoding of every decision channel.
pub const SCHEMA_ENCODING: &str = "jsonschema";

/// The channel's topic: `/decisions/<group>`.
pub fn topic(group: &str) -> String {
    format!("/decisions/{group}")
}

/// The channel's schema name: `companion.decisions.<group>`.
pub fn schema_name(group: &str) -> String {
    format!("companion.decisions.{group}")
}

/// The channel's JSON schema (cycle and time always; the group's fields as they come).
pub fn schema(group: &str) -> String {
    serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": schema_name(group),
        "type": "object",
        "properties": {
            "cycle": {"type": "integer"},
            "time_s": {"type": "number"}
        },
        "additionalProperties": true
    })
    .to_string()
}

/// A record as JSON, the form [`message`] reads.
pub fn record_value(r: &DecisionRecord) -> serde_json::Value {
    serde_json::to_value(r).unwrap_or(serde_json::Value::Null)
}

/// The message of `group` for one record (its JSON from [`record_value`]).
pub fn message(r: &serde_json::Value, group: &str) -> serde_json::Value {
    let get = |k: &str| r.get(k).cloned().unwrap_or(serde_json::Value::Null);
    let mut o = serde_json::Map::new();
    o.insert("cycle".into(), get("cycle"));
    o.insert("time_s".into(), get("time_s"));
    match group {
        "summary" => {
            for k in ["state", "actions", "events", "link_events"] {
                o.insert(k.into(), get(k));
            }
        }
        "proposals" | "conflicts" | "commands" => {
            o.insert(group.into(), get(group));
        }
        _ => {
            // Maps and optional objects: their fields at top level, where plotting tools look.
            if let Some(m) = r.get(group).and_then(|v| v.as_object()) {
                for (k, v) in m {
                    o.insert(k.clone(), v.clone());
                }
            }
        }
    }
    serde_json::Value::Object(o)
}

/// The message's log time: the run's start plus the record's `time_s`, in ns since the epoch.
pub fn log_time_ns(start_ns: u64, r: &DecisionRecord) -> u64 {
    start_ns.saturating_add((r.time_s.max(0.0) * 1e9) as u64)
}
