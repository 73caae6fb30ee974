//! The run's `flight.tlog` as the `telemetry` table: one row per MAVLink message, its time, sender,
//! name and fields (JSON). Read one entry at a time (8-byte big-endian microseconds, then one
//! frame), so a long flight's tlog is never held whole.

use crate::export::RunKey;
use crate::table::{Cell, Kind, TableWriter};
use std::io::{BufReader, Read};
use std::path::Path;

/// Length of the MAVLink frame whose first bytes are `b`, from its header (v1 or v2).
fn frame_len(b: &[u8; 3]) -> Option<usize> {
    match b[0] {
        0xFD => Some(12 + b[1] as usize + if b[2] & 0x01 != 0 { 13 } else { 0 }),
        0xFE => Some(8 + b[1] as usize),
        _ => None,
    }
}

/// Read up to `buf.len()` bytes; false at a clean end of file or a cut-off entry.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<bool> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..])? {
            0 => return Ok(false),
            n => got += n,
        }
    }
    Ok(true)
}

/// Write the telemetry of the run in `dir` to `path` (an empty table without a tlog); the
/// messages written. Reading stops, as `companion`'s tlog reader does, at the first entry cut off
/// or not starting with a MAVLink start byte.
pub fn export_tlog(dir: &Path, path: &Path, key: &RunKey) -> anyhow::Result<u64> {
    let columns: Vec<(String, Kind)> = [
        ("run_id", Kind::Str),
        ("vehicle", Kind::Str),
        ("t_us", Kind::I64),
        ("sysid", Kind::I64),
        ("compid", Kind::I64),
        ("seq", Kind::I64),
        ("name", Kind::Str),
        ("fields", Kind::Str),
    ]
    .iter()
    .map(|(n, k)| (n.to_string(), *k))
    .collect();
    let mut w = TableWriter::create(path, &columns)?;
    let tlog = dir.join("flight.tlog");
    if tlog.is_file() {
        let file =
            std::fs::File::open(&tlog).map_err(|e| anyhow::anyhow!("{}: {e}", tlog.display()))?;
        let mut r = BufReader::new(file);
        let mut ingest = companion_link::ingest::Ingest::new(None);
        let mut frame = vec![0u8; 300];
        loop {
            let mut head = [0u8; 11];
            if !read_full(&mut r, &mut head)? {
                break;
            }
            let t_us = u64::from_be_bytes(head[..8].try_into().expect("8 bytes"));
            let Some(n) = frame_len(&[head[8], head[9], head[10]]) else {
                break;
            };
            frame.resize(n, 0);
            frame[..3].copy_from_slice(&head[8..]);
            if !read_full(&mut r, &mut frame[3..])? {
                break;
            }
            let mut rows = Vec::new();
            ingest.push_each(&frame, |fr| {
                rows.push(vec![
                    key.run_id.as_str().into(),
                    key.vehicle.as_str().into(),
                    Cell::from(t_us),
                    i64::from(fr.header.system_id).into(),
                    i64::from(fr.header.component_id).into(),
                    i64::from(fr.header.sequence).into(),
                    mavlink::Message::message_name(fr.msg).into(),
                    serde_json::to_string(fr.msg).unwrap_or_default().into(),
                ]);
            });
            for row in rows {
                w.push(row)?;
            }
        }
    }
    w.finish()
}
