//! What became of each vehicle command, in categories an operator reads at a glance. The result
//! strings are those of `CommandRecord.result` (companion-link's `command::Outcome::label`,
//! `vehicle/executor/`, `mission::MissionError::outcome`; simulate's `SIMULATED`). Only real failures count as failed: a step sent and still awaiting
//! its answer, a mode already set, a step skipped because an earlier one failed or the operator
//! took over are each their own category.

use companion_core::record::{CommandOutcome, Event};

/// The category of one command result.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Category {
    Accepted,
    InProgress,
    Already,
    Skipped,
    Denied,
    Failed,
    TimedOut,
}

impl Category {
    pub const ALL: [Category; 7] = [
        Category::Accepted,
        Category::InProgress,
        Category::Already,
        Category::Skipped,
        Category::Denied,
        Category::Failed,
        Category::TimedOut,
    ];

    pub fn label(self) -> &'static str {
        match self {
            Category::Accepted => "accepted",
            Category::InProgress => "in progress",
            Category::Already => "already",
            Category::Skipped => "skipped",
            Category::Denied => "denied",
            Category::Failed => "failed",
            Category::TimedOut => "timed out",
        }
    }

    /// CSS class / data-attribute spelling.
    pub fn class(self) -> &'static str {
        match self {
            Category::Accepted => "accepted",
            Category::InProgress => "in-progress",
            Category::Already => "already",
            Category::Skipped => "skipped",
            Category::Denied => "denied",
            Category::Failed => "failed",
            Category::TimedOut => "timed-out",
        }
    }

    /// Worth a red mark: the vehicle refused, or the command failed or went unanswered.
    pub fn is_bad(self) -> bool {
        matches!(
            self,
            Category::Denied | Category::Failed | Category::TimedOut
        )
    }
}

/// Category of a `CommandRecord.result`. Unknown spellings count as failed, so nothing new hides.
pub fn categorize(result: &CommandOutcome) -> Category {
    use CommandOutcome::*;
    match result {
        // Arrived: the vehicle reached the landing zone the step flew it to (the step succeeded).
        Accepted | AcceptedVerified { .. } | Simulated | Arrived(_) => Category::Accepted,
        // Not confirmed: sent again, the attempt that follows says how it ended.
        Sent | Pending | InProgress | WaitingReady(_) | NotConfirmed(_) => Category::InProgress,
        Already => Category::Already,
        // Not sent on purpose: an earlier step failed, a newer action set replaced it, the link
        // was down, or commanding stopped (link loss, pilot takeover).
        Skipped(_) | Superseded | NotSent(_) | Cancelled(_) => Category::Skipped,
        Denied | Unsupported | TemporarilyRejected | NotReady(_) => Category::Denied,
        Timeout(_) => Category::TimedOut,
        Failed(_) | Unmapped | Other(_) => Category::Failed,
    }
}

/// Commands counted per category.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct OutcomeCounts {
    counts: [usize; 7],
}

impl OutcomeCounts {
    pub fn add(&mut self, c: Category) {
        self.counts[c as usize] += 1;
    }
    pub fn get(&self, c: Category) -> usize {
        self.counts[c as usize]
    }
    pub fn total(&self) -> usize {
        self.counts.iter().sum()
    }
    /// "9 accepted, 3 in progress, 1 already" (categories with none left out).
    pub fn describe(&self) -> String {
        let parts: Vec<String> = Category::ALL
            .iter()
            .filter(|c| self.get(**c) > 0)
            .map(|c| format!("{} {}", self.get(*c), c.label()))
            .collect();
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join(", ")
        }
    }
}

/// A started-in-flight event as the summary tells it: `resumed (facts)` or `handed off (why not
/// resumed)`; None for the other events and lines (the proof under way).
pub(super) fn restart_words(event: &Event) -> Option<String> {
    let does = match event {
        Event::ResumedInFlight { facts, .. } => {
            return Some(format!(
                "resumed on the operator's consent ({})",
                facts.join("; ")
            ));
        }
        Event::StartedInFlight { does, .. } => does.as_str(),
        _ => return None,
    };
    let (_, why) = does.split_once("not resumed")?;
    let why = why.split("; no start until").next().unwrap_or(why);
    // Logs before restart_in_air: `not resumed (the companion resumes no flight ...)`.
    let why = (why.strip_prefix(" (").and_then(|w| w.strip_suffix(')')))
        .unwrap_or_else(|| why.trim_start_matches([':', ' ']));
    let done = if does.contains("hand-off") {
        "handed off"
    } else {
        "not resumed"
    };
    Some(if why.is_empty() {
        done.to_string()
    } else {
        format!("{done} ({why})")
    })
}

#[cfg(test)]
mod tests {

    #[test]
    fn an_arrival_at_the_zone_counts_as_accepted_and_a_timeout_does_not() {
        let arrived = crate::decision_log::migration::outcome("ARRIVED (1.2 m from the zone)");
        assert!(matches!(arrived, CommandOutcome::Arrived(_)), "{arrived:?}");
        assert_eq!(categorize(&arrived), Category::Accepted);
        let late = crate::decision_log::migration::outcome(
            "TIMEOUT (not within 3.0 m of the zone after 30 s, 7.5 m away; landing here)",
        );
        assert_eq!(categorize(&late), Category::TimedOut);
    }
    use super::*;

    #[test]
    fn result_strings_fall_in_their_categories() {
        for (r, c) in [
            ("ACCEPTED", Category::Accepted),
            ("ACCEPTED (verified 4 items)", Category::Accepted),
            ("SIMULATED", Category::Accepted),
            ("SENT", Category::InProgress),
            ("IN_PROGRESS", Category::InProgress),
            ("WAITING_READY (gps)", Category::InProgress),
            ("ALREADY", Category::Already),
            ("SKIPPED (earlier step failed)", Category::Skipped),
            (
                "SKIPPED (no zone reported; landing here)",
                Category::Skipped,
            ),
            ("SUPERSEDED", Category::Skipped),
            ("NOT_SENT (no link)", Category::Skipped),
            ("CANCELLED (pilot took over)", Category::Skipped),
            ("FAILED (Cancelled(\"link lost\"))", Category::Skipped),
            ("CANCELLED (link lost)", Category::Skipped),
            (
                "TIMEOUT (no answer to MISSION_ITEM_INT)",
                Category::TimedOut,
            ),
            ("DENIED", Category::Denied),
            ("TEMPORARILY_REJECTED", Category::Denied),
            ("NOT_READY (prearm)", Category::Denied),
            ("UNSUPPORTED", Category::Denied),
            ("FAILED", Category::Failed),
            ("FAILED (no position/heading yet)", Category::Failed),
            ("UNMAPPED (not in commands.toml)", Category::Failed),
            ("something new", Category::Failed),
            ("TIMEOUT", Category::TimedOut),
        ] {
            assert_eq!(
                categorize(&crate::decision_log::migration::outcome(r)),
                c,
                "{r}"
            );
        }
    }
}
