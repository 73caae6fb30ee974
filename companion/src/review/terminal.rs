//! `companion review --summary`: the summary and the Tables 4–7 timeline as a terminal table.
//! Colour only when asked (the caller passes `color` = stdout is a TTY and NO_COLOR unset).
//! Every value from the log goes through [`clean`]: no control character or escape sequence
//! from a log reaches the terminal.

use super::text::clean;
use super::why::Why;
use super::{Mark, Review};
use std::fmt::Write;

struct Style {
    on: bool,
}

impl Style {
    fn paint(&self, code: &str, s: &str) -> String {
        if self.on {
            format!("\x1b[{code}m{s}\x1b[0m")
        } else {
            s.to_string()
        }
    }
}

/// Greedy word wrap at `width` columns (counted in chars).
fn wrap(s: &str, width: usize) -> Vec<String> {
    let mut lines = vec![String::new()];
    for word in s.split(' ') {
        let cur = lines.last_mut().expect("non-empty");
        let len = cur.chars().count();
        if len > 0 && len + 1 + word.chars().count() > width {
            lines.push(word.to_string());
        } else {
            if len > 0 {
                cur.push(' ');
            }
            cur.push_str(word);
        }
    }
    lines
}

fn fmt(v: f64) -> String {
    if v.abs() >= 100.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.2}")
    }
}

pub fn render_terminal(rev: &Review, color: bool) -> String {
    let s = &rev.summary;
    let st = Style { on: color };
    let mut o = String::new();
    let _ = writeln!(o, "{}", st.paint("1", "Summary"));
    let mut kv = |k: &str, v: String| {
        let _ = writeln!(o, "  {:<24} {}", clean(k), clean(&v));
    };
    kv("outcome", s.outcome.clone());
    kv(
        "policy",
        s.policy.clone().unwrap_or_else(|| "unknown".into()),
    );
    if let Some(sc) = &s.scenario {
        kv("scenario", sc.clone());
    }
    kv(
        "records",
        format!("{} ({} s)", s.records, fmt(s.duration_s)),
    );
    kv(
        "tracking time",
        format!("{} steps / {} s", s.tracking_steps, fmt(s.tracking_s)),
    );
    for (goal, m) in &s.final_margins {
        let v = match m.goal {
            Some(g) => format!("{} (goal {})", fmt(m.margin), fmt(g)),
            None => fmt(m.margin),
        };
        kv(&format!("final margin {goal}"), v);
    }
    kv("conflicts", s.conflicts.to_string());
    kv("degradations", s.degradations.to_string());
    kv("re-allocations", s.reallocations.to_string());
    kv(
        "commands",
        format!("{}: {}", s.commands, s.outcomes.describe()),
    );
    kv(
        "failed commands",
        format!("{} of {}", s.failed_commands, s.commands),
    );
    kv("mode changes", s.mode_changes.to_string());
    kv("link events", s.link_events.to_string());
    kv("records lost", s.dropped.to_string());
    if let Some(n) = s.live_dropped {
        kv("live viewers lost", format!("{n} messages (--live)"));
    }
    if s.lost_write_failed > 0 {
        kv(
            "lost to failed writes",
            format!("{} (disk full or I/O error)", s.lost_write_failed),
        );
    }
    if s.lost_capped > 0 {
        kv("lost to the size cap", s.lost_capped.to_string());
    }
    if s.tlog_capped > 0 {
        kv(
            "flight.tlog capped",
            format!(
                "{} telemetry frames not written (size cap, COMPANION_LOG_MAX_BYTES)",
                s.tlog_capped
            ),
        );
    }
    if s.corrupted_lines > 0 {
        kv("corrupted lines", s.corrupted_lines.to_string());
    }
    if let Some(t) = &rev.truncated {
        kv("truncated", format!("{}:{}", t.file.display(), t.line));
    }
    let _ = writeln!(o);
    let _ = writeln!(o, "{}", st.paint("1", "Timeline"));

    let headers = ["cycles", "State", "Set of actions", "Events", "Resources"];
    let widths = [9usize, 10, 44, 34, 18];
    let mut table: Vec<[Vec<String>; 5]> = Vec::new();
    for p in &rev.phases {
        let cycles = if p.first_cycle == p.last_cycle {
            p.first_cycle.to_string()
        } else {
            format!("{}-{}", p.first_cycle, p.last_cycle)
        };
        let mut events: Vec<String> = p
            .events
            .iter()
            .filter_map(|i| rev.spans.get(*i))
            .map(|sp| sp.label().replace('–', "-"))
            .collect();
        events.extend(p.marks.iter().map(Mark::text));
        let events = if events.is_empty() {
            "No event".to_string()
        } else {
            events.join("; ")
        };
        let res = if p.resources.is_empty() {
            "-".to_string()
        } else {
            p.resources.join(" -> ")
        };
        table.push([
            wrap(&clean(&cycles), widths[0]),
            wrap(&clean(&p.state), widths[1]),
            wrap(&clean(&p.actions.join(", ")), widths[2]),
            wrap(&clean(&events), widths[3]),
            wrap(&clean(&res), widths[4]),
        ]);
    }
    let line: String = widths
        .iter()
        .map(|w| "-".repeat(w + 2))
        .collect::<Vec<_>>()
        .join("+");
    let mut head = String::new();
    for (h, w) in headers.iter().zip(widths) {
        let _ = write!(head, " {h:<w$} |");
    }
    let _ = writeln!(o, "{}", st.paint("1", head.trim_end_matches('|')));
    let _ = writeln!(o, "{line}");
    for (row, p) in table.iter().zip(&rev.phases) {
        let height = row.iter().map(Vec::len).max().unwrap_or(1);
        let alert = p
            .marks
            .iter()
            .any(|m| matches!(m, Mark::Failsafe(_) | Mark::Loss(..)));
        for k in 0..height {
            let mut l = String::new();
            for (c, (cell, w)) in row.iter().zip(widths).enumerate() {
                let text = cell.get(k).map(String::as_str).unwrap_or("");
                let padded = format!("{text:<w$}");
                let painted = match c {
                    3 if alert => st.paint("31", &padded),
                    3 if text != "No event" && !text.is_empty() => st.paint("33", &padded),
                    1 => st.paint("1", &padded),
                    _ => padded,
                };
                let _ = write!(l, " {painted} |");
            }
            let _ = writeln!(o, "{}", l.trim_end_matches('|').trim_end());
        }
    }
    if rev.phases_omitted > 0 {
        let _ = writeln!(o, "  ({} more phases not listed)", rev.phases_omitted);
    }
    o
}

/// `review --cycle N`: the why of one cycle.
pub fn render_why(w: &Why, color: bool) -> String {
    let st = Style { on: color };
    let mut o = String::new();
    let _ = writeln!(o, "{}", st.paint("1", &format!("Why, cycle {}", w.cycle)));
    for l in w.lines() {
        let _ = writeln!(o, "{}", clean(&l));
    }
    o
}

#[cfg(test)]
mod tests {
    use super::wrap;

    #[test]
    fn wrap_respects_width_and_keeps_words() {
        let w = wrap(
            "follow_trajectory, detect_obstacles_lidar, search_zone_t",
            20,
        );
        assert_eq!(
            w,
            vec![
                "follow_trajectory,",
                "detect_obstacles_lidar,",
                "search_zone_t"
            ]
        );
        assert_eq!(wrap("a b c", 3), vec!["a b", "c"]);
    }
}
