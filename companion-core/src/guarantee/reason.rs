//! Why the allocation in force must change, written into a reused string: while the guarantee
//! cannot be met the watch says so every cycle.

use std::fmt::Write;

/// Why the allocation in force must change from activity `at`, into `out` (cleared first): its
/// negative margins (`negative energy_j margin -12.0, ...`) and the failed resources its remaining
/// IAs use (`failed resource in plan: ...`, sorted, each once; `FPGA tile` for a lost tile slot),
/// joined by `; `.
pub(super) fn reallocation_reason_into(
    p: &panorama::Problem,
    choice: &[usize],
    at: usize,
    failed: &[String],
    margin: &[f64],
    out: &mut String,
) {
    out.clear();
    for (k, (g, x)) in p
        .goals
        .iter()
        .zip(margin)
        .filter(|(_, x)| **x < 0.0)
        .enumerate()
    {
        out.push_str(if k == 0 { "negative " } else { ", " });
        // Writing into a String cannot fail.
        let _ = write!(out, "{} margin {x:.1}", g.name);
    }
    // The failed resources in the plan as shown, in order, each once: a few names, so picking
    // the next larger one each time needs no set.
    let shown = || {
        (at..p.activities.len())
            .flat_map(|j| p.activities[j].ias[choice[j]].resources.iter())
            .filter(|r| failed.contains(r))
            .map(|r| {
                if r.starts_with("tile_slot:") {
                    "FPGA tile"
                } else {
                    r.as_str()
                }
            })
    };
    let mut last: Option<&str> = None;
    while let Some(next) = shown().filter(|s| last.is_none_or(|l| *s > l)).min() {
        out.push_str(match (last, out.is_empty()) {
            (Some(_), _) => ", ",
            (None, true) => "failed resource in plan: ",
            (None, false) => "; failed resource in plan: ",
        });
        out.push_str(next);
        last = Some(next);
    }
}

#[cfg(test)]
mod tests {
    use super::reallocation_reason_into;
    use panorama::{Activity, Goal, Ia, Problem};

    fn ia(resources: &[&str]) -> Ia {
        Ia {
            name: "ia".into(),
            cost: vec![1.0, 1.0],
            capability: 1.0,
            resources: resources.iter().map(|r| r.to_string()).collect(),
        }
    }

    /// The sentence as the earlier sets-and-joins version wrote it, rewritten over a dirty
    /// buffer: margins first, then the failed resources sorted and once each, tile slots
    /// shown as one `FPGA tile`.
    #[test]
    fn reasons_read_as_before() {
        let p = Problem {
            goals: vec![
                Goal {
                    name: "energy_j".into(),
                    bound: 1.0,
                },
                Goal {
                    name: "duration_s".into(),
                    bound: 1.0,
                },
            ],
            activities: vec![
                Activity {
                    name: "done".into(),
                    ias: vec![ia(&["zeta"])],
                },
                Activity {
                    name: "a".into(),
                    ias: vec![ia(&["lidar", "tile_slot:2", "camera"])],
                },
                Activity {
                    name: "b".into(),
                    ias: vec![ia(&["tile_slot:1", "lidar", "gps"])],
                },
            ],
        };
        let failed: Vec<String> = ["lidar", "tile_slot:1", "tile_slot:2", "camera", "zeta"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let mut out = String::from("left over from the last cycle");
        let cases: [(&[f64], &[String], &str); 4] = [
            (
                &[-12.04, 3.0],
                &failed,
                "negative energy_j margin -12.0; failed resource in plan: FPGA tile, camera, lidar",
            ),
            (
                &[-1.0, -2.26],
                &[],
                "negative energy_j margin -1.0, duration_s margin -2.3",
            ),
            (&[1.0, 2.0], &failed[..1], "failed resource in plan: lidar"),
            (&[1.0, 2.0], &[], ""),
        ];
        for (margin, failed, want) in cases {
            reallocation_reason_into(&p, &[0, 0, 0], 1, failed, margin, &mut out);
            assert_eq!(out, want);
        }
    }
}
