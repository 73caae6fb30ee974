//! `companion-log-migrate IN.jsonl OUT.jsonl`: one decision-log part rewritten at this build's
//! schema, line for line, as this build writes it: a schema-1 record goes through
//! `decision_log::migration` and is written again from its typed value; a header gets this
//! build's schema; other lines are copied. `scripts/logs_identical.sh` compares a base
//! revision's migrated logs with the new revision's own, byte for byte.

use companion::decision_log::{Header, SCHEMA_VERSION, migration};
use companion_core::record::DecisionRecord;
use std::io::{BufRead, Write};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output] = args.as_slice() else {
        eprintln!("usage: companion-log-migrate IN.jsonl OUT.jsonl");
        std::process::exit(2);
    };
    if let Err(e) = migrate(input, output) {
        eprintln!("companion-log-migrate: {e}");
        std::process::exit(1);
    }
}

fn migrate(input: &str, output: &str) -> Result<(), String> {
    let file = std::fs::File::open(input).map_err(|e| format!("{input}: {e}"))?;
    let mut out = std::io::BufWriter::new(
        std::fs::File::create(output).map_err(|e| format!("{output}: {e}"))?,
    );
    let mut schema = None;
    for (i, line) in std::io::BufReader::new(file).lines().enumerate() {
        let at = |e: &dyn std::fmt::Display| format!("{input}:{}: {e}", i + 1);
        let line = line.map_err(|e| at(&e))?;
        let mut value: serde_json::Value = serde_json::from_str(&line).map_err(|e| at(&e))?;
        let written = match value.get("kind").and_then(|k| k.as_str()) {
            Some("header") => {
                let mut h: Header = serde_json::from_value(value).map_err(|e| at(&e))?;
                schema = Some(h.schema);
                h.schema = SCHEMA_VERSION;
                serde_json::to_string(&h).map_err(|e| at(&e))?
            }
            None => {
                if migration::needs_migration(schema) {
                    migration::record_v1(&mut value);
                }
                let r: DecisionRecord = serde_json::from_value(value).map_err(|e| at(&e))?;
                serde_json::to_string(&r).map_err(|e| at(&e))?
            }
            Some(_) => line,
        };
        writeln!(out, "{written}").map_err(|e| format!("{output}: {e}"))?;
    }
    out.flush().map_err(|e| format!("{output}: {e}"))
}
