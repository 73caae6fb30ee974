//! `companion export` of the synthetic mission's records: MCAP and CSV read back.

use companion::export::*;
use companion_core::record::DecisionRecord;
use companion_testkit::synthetic;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn write_log(dir: &Path, n: u64) -> (PathBuf, Vec<DecisionRecord>) {
    let recs = synthetic::mission(n);
    let p = dir.join("decisions.jsonl");
    let mut text = String::from(
        "{\"kind\":\"header\",\"schema\":1,\"started_utc\":\"2025-06-01T12:00:00Z\",\"command\":\"companion simulate\"}\n",
    );
    for r in &recs {
        text.push_str(&serde_json::to_string(r).unwrap());
        text.push('\n');
    }
    text.push_str("{\"kind\":\"end\"}\n");
    std::fs::write(&p, text).unwrap();
    (p, recs)
}

#[test]
fn mcap_export_reads_back_one_message_per_record_on_every_channel() {
    let dir = tempfile::tempdir().unwrap();
    let (log, recs) = write_log(dir.path(), 60);
    let out = dir.path().join("x.mcap");
    let stats = export_mcap(&log, &out).unwrap();
    assert_eq!(stats.records, 60);
    let bytes = std::fs::read(&out).unwrap();
    let mut per_topic: BTreeMap<String, usize> = BTreeMap::new();
    let mut first_probs = None;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert_eq!(m.channel.message_encoding, "json");
        assert_eq!(m.channel.schema.as_ref().unwrap().encoding, "jsonschema");
        if m.channel.topic == "/decisions/probabilities" && first_probs.is_none() {
            first_probs = Some((
                m.log_time,
                serde_json::from_slice::<serde_json::Value>(&m.data).unwrap(),
            ));
        }
        *per_topic.entry(m.channel.topic.clone()).or_default() += 1;
    }
    assert_eq!(per_topic.len(), GROUPS.len());
    for g in GROUPS {
        assert_eq!(per_topic[&format!("/decisions/{g}")], recs.len(), "{g}");
    }
    let (t, v) = first_probs.unwrap();
    assert_eq!(t, rfc3339_ns("2025-06-01T12:00:00Z").unwrap());
    for (k, p) in &recs[0].probabilities {
        assert_eq!(v[k].as_f64(), Some(*p), "{k}");
    }
}

#[test]
fn csv_export_has_one_row_per_record_with_flattened_columns() {
    let dir = tempfile::tempdir().unwrap();
    let (log, recs) = write_log(dir.path(), 30);
    let out = dir.path().join("x.csv");
    let stats = export_csv(&log, &out).unwrap();
    assert_eq!(stats.records, 30);
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 31);
    let head: Vec<&str> = lines[0].split(',').collect();
    assert_eq!(&head[..2], &["cycle", "time_s"]);
    let name = recs[5].probabilities.keys().next().unwrap();
    let col = head
        .iter()
        .position(|h| *h == format!("probabilities.{name}"))
        .unwrap();
    // Synthetic values hold no commas or quotes in these columns.
    let row5: Vec<&str> = lines[6].split(',').collect();
    assert_eq!(row5[0], "5");
    assert_eq!(
        row5[col].parse::<f64>().unwrap(),
        recs[5].probabilities[name]
    );
}

#[test]
fn csv_fields_are_quoted_and_formulas_defused() {
    assert_eq!(csv_field("a,b"), "\"a,b\"");
    assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
    assert_eq!(csv_field("=HYPERLINK(1)"), "'=HYPERLINK(1)");
    assert_eq!(csv_field("-3.5"), "-3.5");
}

#[test]
fn rfc3339_parses_utc_times() {
    assert_eq!(rfc3339_ns("1970-01-01T00:00:00Z"), Some(0));
    assert_eq!(
        rfc3339_ns("2000-03-01T00:00:01Z"),
        Some(951_868_801_000_000_000)
    );
    assert_eq!(rfc3339_ns("junk"), None);
}
