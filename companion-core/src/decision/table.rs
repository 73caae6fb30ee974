//! The decision table in the shape of the BFM paper's Tables 4 to 7, from a run's records.

use crate::model::Model;
use crate::record::{DecisionRecord, Event};

/// The decision table in the shape of the BFM paper's Tables 4 to 7: consecutive cycles with the
/// same state and action set are grouped; a row starts on any change or event.
pub fn table(records: &[DecisionRecord], model: &Model) -> String {
    // Consecutive cycles with the same action set and no event are one row; its state column
    // lists the states they passed through (a tracked target lost and re-acquired: `v1/target`).
    let mut rows: Vec<[String; 5]> = Vec::new();
    let mut last: Option<&crate::action_id::ActionIds> = None;
    for r in records {
        let events = r
            .events
            .iter()
            .map(Event::to_string)
            .collect::<Vec<_>>()
            .join("; ");
        if last == Some(&r.actions) && events.is_empty() {
            if let Some(row) = rows.last_mut() {
                let start = row[0].split('-').next().unwrap_or("").to_string();
                row[0] = format!("{start}-{}", r.cycle);
                if !row[1].split('/').any(|s| s == r.state) {
                    row[1] = format!("{}/{}", row[1], r.state);
                }
            }
            continue;
        }
        last = Some(&r.actions);
        let labels: Vec<&str> = r.actions.iter().map(|a| model.actions.label(a)).collect();
        rows.push([
            r.cycle.to_string(),
            r.state.clone(),
            labels.join(" / "),
            if events.is_empty() {
                "no event".into()
            } else {
                events
            },
            r.resources.as_ref().map_or("-".into(), |x| {
                if x.summary.is_empty() {
                    "-".into()
                } else {
                    x.summary.clone()
                }
            }),
        ]);
    }
    let header = ["step", "state", "set of actions", "events", "resources"];
    let mut width = header.map(str::len);
    for row in &rows {
        for (w, c) in width.iter_mut().zip(row) {
            *w = (*w).max(c.chars().count());
        }
    }
    let mut out = String::new();
    let line = |cells: [&str; 5], out: &mut String| {
        for (i, c) in cells.iter().enumerate() {
            out.push_str(c);
            if i < 4 {
                out.push_str(&" ".repeat(width[i].saturating_sub(c.chars().count())));
                out.push_str(" | ");
            }
        }
        out.push('\n');
    };
    line(header, &mut out);
    out.push_str(
        &width
            .iter()
            .map(|w| "-".repeat(*w))
            .collect::<Vec<_>>()
            .join("-+-"),
    );
    out.push('\n');
    for row in &rows {
        line([&row[0], &row[1], &row[2], &row[3], &row[4]], &mut out);
    }
    out
}
