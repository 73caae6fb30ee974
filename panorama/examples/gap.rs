//! Measures the optimality gap of the paper's allocation (RAS0) against the branch-and-bound
//! optimum on seeded random instances. `cargo run -p panorama --example gap [SEED] [N]`.
//!
//! Instances: 4..=8 activities, 2..=8 IAs each, one or two goals; costs uniform in [1, 20);
//! capability either correlated with cost (cost + noise: more capable IAs cost more, the paper's
//! assumption) or independent; bounds uniform between the lowest and the highest reachable totals.

use panorama::*;

struct SplitMix(u64);
impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: usize, hi: usize) -> usize {
        lo + (self.next() % (hi - lo + 1) as u64) as usize
    }
}

fn instance(r: &mut SplitMix, goals: usize, correlated: bool) -> Problem {
    let na = r.range(4, 8);
    let activities: Vec<Activity> = (0..na)
        .map(|j| Activity {
            name: format!("A{j}"),
            ias: (0..r.range(2, 8))
                .map(|i| {
                    let cost: Vec<f64> = (0..goals).map(|_| 1.0 + 19.0 * r.unit()).collect();
                    let capability = if correlated {
                        cost.iter().sum::<f64>() + 5.0 * r.unit()
                    } else {
                        20.0 * r.unit()
                    };
                    Ia {
                        name: format!("ia{i}"),
                        cost,
                        capability,
                        resources: vec![],
                    }
                })
                .collect(),
        })
        .collect();
    let goals = (0..goals)
        .map(|g| {
            let lo: f64 = activities
                .iter()
                .map(|a| {
                    a.ias
                        .iter()
                        .map(|x| x.cost[g])
                        .fold(f64::INFINITY, f64::min)
                })
                .sum();
            let hi: f64 = activities
                .iter()
                .map(|a| a.ias.iter().map(|x| x.cost[g]).fold(0.0, f64::max))
                .sum();
            Goal {
                name: format!("g{g}"),
                bound: lo + (hi - lo) * r.unit(),
            }
        })
        .collect();
    Problem { goals, activities }
}

/// One family's measurement (a row of the table in docs/guarantee.md, "the optimality gap").
pub(crate) struct GapRow {
    /// Goals per instance (1 or 2).
    pub(crate) goals: usize,
    /// Capability correlated with cost (else independent).
    pub(crate) correlated: bool,
    /// Instances the exact search solved (the gaps measured).
    pub(crate) solved: usize,
    /// Share of them where RAS0 is optimal (%).
    pub(crate) optimal_pct: f64,
    /// Mean gap (% of the optimum).
    pub(crate) mean: f64,
    /// 95th percentile of the gap (%).
    pub(crate) p95: f64,
    /// Largest gap (%).
    pub(crate) max: f64,
    /// Instances with a solution that RAS0 did not find.
    pub(crate) missed: usize,
}

/// The four families on one seeded stream, `n` instances each, in the table's order
/// (docs numbers: companion/tests/doc_numbers.rs reads this file).
pub(crate) fn rows(seed: u64, n: usize) -> Vec<GapRow> {
    let mut r = SplitMix(seed);
    let mut out = Vec::new();
    for goals in [1, 2] {
        for correlated in [true, false] {
            let mut gaps = Vec::new();
            let (mut missed, mut optimal) = (0, 0);
            for _ in 0..n {
                let p = instance(&mut r, goals, correlated);
                let opt = match exact(&p, Selection::MostCapable, 50_000_000) {
                    Exact::Optimal(o) => o,
                    _ => continue,
                };
                match allocate(&p, Selection::MostCapable) {
                    Ok(a) => {
                        let gap = (opt.score - a.score) / opt.score.abs().max(1e-12);
                        if gap <= 1e-12 {
                            optimal += 1;
                        }
                        gaps.push(gap * 100.0);
                    }
                    Err(_) => missed += 1,
                }
            }
            gaps.sort_by(f64::total_cmp);
            out.push(GapRow {
                goals,
                correlated,
                solved: gaps.len(),
                optimal_pct: 100.0 * optimal as f64 / gaps.len().max(1) as f64,
                mean: gaps.iter().sum::<f64>() / gaps.len().max(1) as f64,
                p95: gaps.get(gaps.len() * 95 / 100).copied().unwrap_or(0.0),
                max: gaps.last().copied().unwrap_or(0.0),
                missed,
            });
        }
    }
    out
}

#[allow(dead_code)] // the entry point of the example, not of the doc-numbers test including it
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seed = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(2024);
    let n: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(2000);
    println!(
        "seed {seed}, {n} instances per row; gap = (optimum - RAS0) / optimum of the summed score"
    );
    println!(
        "{:<28} {:>8} {:>9} {:>10} {:>9} {:>9} {:>11}",
        "family", "solved", "optimal%", "mean gap%", "p95 gap%", "max gap%", "missed sol."
    );
    for row in rows(seed, n) {
        let family = format!(
            "{} goal(s), {}",
            row.goals,
            if row.correlated {
                "capability~cost"
            } else {
                "independent"
            }
        );
        println!(
            "{family:<28} {:>8} {:>9.1} {:>10.2} {:>9.2} {:>9.2} {:>11}",
            row.solved, row.optimal_pct, row.mean, row.p95, row.max, row.missed
        );
    }
}
