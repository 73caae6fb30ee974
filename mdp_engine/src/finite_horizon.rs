//! Finite-horizon undiscounted backward induction with its certified early stop.

use crate::kernels::{backup_stage, backup_stage_screened};
use crate::lockstep::{Lockstep, SharedRows, Sweeps, run_sweeps};
use crate::model::{Mdp, NONE, beat_bar};
use crate::solution::FiniteHorizonSolution;
use crate::workspace::Workspace;
use std::ops::Range;

/// Relative bound for the finite-horizon early stop: the extrapolated stages may differ from full
/// backward induction by at most this times `max(1, |V_0|)` in value, and a kept action may be
/// worse than the best by at most as much beyond the [`TIE_TOLERANCE`] (see
/// [`Workspace::finite_horizon`]). Full backward induction's own rounding is of order
/// `H * 1e-16 * |V_0|`, a hundred times smaller at the paper's horizon.
///
/// [`TIE_TOLERANCE`]: crate::TIE_TOLERANCE
pub const FH_STOP_TOLERANCE: f64 = 1e-12;

/// What one certified backup (stage `b - 1` from `V_b`, `V_{b+1}`) measures about `g = V_b -
/// V_{b+1}`, to bound the remaining stages without computing them.
///
/// With `T` the Bellman operator (monotone; `T(V + c) = TV + c` at non-terminal states for a
/// constant `c`, terminal states fixed at 0), for every `k >= 1`:
/// * span bound: `min g <= d <= max g` propagates to every earlier difference, so
///   `|V_{b-k} - (V_b + k g)| <= k * span(g)`;
/// * componentwise bound (multichain models, where terminal states keep `g = 0` and the others
///   earn a positive gain, so the span never shrinks): with `eps_up = max_{s,a} (P_a g)(s) -
///   g(s)` and `eps_lo = max_s g(s) - (P_{pi_b} g)(s)`, induction on `T(V + w) <= TV + max_a P_a
///   w` and `T(V + w) >= T_{pi_b}(V + w)` gives `V_b + k g - k(k+1)/2 eps_lo <= V_{b-k} <= V_b +
///   k g + k(k+1)/2 eps_up`.
///
/// Actions: at an earlier stage, `Q(s,a) = qb(s,a) + k (P_a g)(s) + (P_a err)(s)` with `qb` the
/// Q-values of stage `b - 1`, so the stage `b - 1` choice `a*` loses to another action at most
/// `2 E + k ((P_a g)(s) - (P_a* g)(s))`, and that gain difference is at most `eps_up + eps_star`
/// (`eps_star = max_s g(s) - (P_{a*} g)(s)`) or `span(g)`.
#[derive(Debug, Clone, Copy)]
struct FhCertificate {
    eps_up: f64,
    eps_lo: f64,
    eps_star: f64,
    span: f64,
    vmax: f64,
    gmax: f64,
}

/// The bounds of [`FhCertificate`] over `k` remaining stages.
#[derive(Debug, Clone, Copy)]
struct FhBound {
    /// On every extrapolated value.
    value: f64,
    /// On how much a kept action's Q-value may fall below the best (beyond the tie tolerance).
    action: f64,
}

impl FhCertificate {
    fn stop_bound(&self, k: usize) -> Option<FhBound> {
        let k = k as f64;
        let value = (k * self.span).min(k * (k + 1.0) * 0.5 * self.eps_up.max(self.eps_lo));
        let eta = (self.eps_up + self.eps_star).min(self.span);
        let action = 2.0 * value + k * eta;
        action.is_finite().then_some(FhBound { value, action })
    }

    /// An upper bound on `max(1, |V_0|)` when `V_0 ~ V_b + k g`.
    fn scale(&self, k: usize) -> f64 {
        (self.vmax + k as f64 * self.gmax).max(1.0)
    }
}

/// The early-stop screen `(max_s |vb - 2 vb1 + vb2|, max(1, max_s |vb|))` as a separate pass
/// (over the states the slices hold).
fn screen(vb: &[f64], vb1: &[f64], vb2: &[f64]) -> (f64, f64) {
    let (mut delta, mut scale) = (0.0f64, 1.0f64);
    for ((a, b), c) in vb.iter().zip(vb1).zip(vb2) {
        delta = delta.max((a - 2.0 * b + c).abs());
        scale = scale.max(a.abs());
    }
    (delta, scale)
}

/// What the threads of a stage combine: the screen for the next stage and, on a certified
/// backup, the certificate's measures (maxima and minima: the same bits however split).
#[derive(Debug, Clone, Copy)]
struct StageReduction {
    screen: (f64, f64),
    cert: Partial,
}

impl StageReduction {
    const EMPTY: StageReduction = StageReduction {
        screen: (0.0, 1.0),
        cert: Partial::EMPTY,
    };

    fn merge(a: StageReduction, b: StageReduction) -> StageReduction {
        StageReduction {
            screen: (a.screen.0.max(b.screen.0), a.screen.1.max(b.screen.1)),
            cert: Partial::merge(a.cert, b.cert),
        }
    }
}

/// A certificate's measures over some of the states (`span` not yet: from `gmin`, `gmaxs`).
#[derive(Debug, Clone, Copy)]
struct Partial {
    cert: FhCertificate,
    gmin: f64,
    gmaxs: f64,
}

impl Partial {
    const EMPTY: Partial = Partial {
        cert: FhCertificate {
            eps_up: 0.0,
            eps_lo: 0.0,
            eps_star: 0.0,
            span: 0.0,
            vmax: 0.0,
            gmax: 0.0,
        },
        gmin: f64::INFINITY,
        gmaxs: f64::NEG_INFINITY,
    };

    /// The certificate of every state's measures.
    fn certificate(self) -> FhCertificate {
        let mut cert = self.cert;
        cert.span = if self.gmaxs >= self.gmin {
            self.gmaxs - self.gmin
        } else {
            0.0
        };
        cert
    }

    fn merge(a: Partial, b: Partial) -> Partial {
        let (x, y) = (a.cert, b.cert);
        Partial {
            cert: FhCertificate {
                eps_up: x.eps_up.max(y.eps_up),
                eps_lo: x.eps_lo.max(y.eps_lo),
                eps_star: x.eps_star.max(y.eps_star),
                span: 0.0,
                vmax: x.vmax.max(y.vmax),
                gmax: x.gmax.max(y.gmax),
            },
            gmin: a.gmin.min(b.gmin),
            gmaxs: a.gmaxs.max(b.gmaxs),
        }
    }
}

/// One backup from `vb` (`V_b`) over the states `s0 .. s0 + cur.len()` (`cur`, `pol` hold just
/// those) that also measures there the [`FhCertificate`] of `g = vb - vb1`, with `pol_b` the
/// decision rule of stage `b` (every state).
fn certified_range(
    mdp: &Mdp,
    vb: &[f64],
    vb1: &[f64],
    pol_b: &[u32],
    s0: usize,
    cur: &mut [f64],
    pol: &mut [u32],
) -> Partial {
    let ss = &mdp.state_start;
    let mut cert = FhCertificate {
        eps_up: 0.0,
        eps_lo: 0.0,
        eps_star: 0.0,
        span: 0.0,
        vmax: 0.0,
        gmax: 0.0,
    };
    let (mut gmin, mut gmaxs) = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 0..cur.len() {
        let s = s0 + k;
        let gs = vb[s] - vb1[s];
        gmin = gmin.min(gs);
        gmaxs = gmaxs.max(gs);
        cert.gmax = cert.gmax.max(gs.abs());
        cert.vmax = cert.vmax.max(vb[s].abs());
        let lo = ss[s] as usize;
        let hi = ss[s + 1] as usize;
        if lo == hi {
            cur[k] = 0.0;
            pol[k] = NONE;
            continue;
        }
        let mut best_c = lo;
        let mut best = f64::NEG_INFINITY;
        let mut bar = f64::NEG_INFINITY;
        let mut best_pg = 0.0;
        for c in lo..hi {
            let t = mdp.transition_range(c);
            let (mut q, mut pg) = (0.0, 0.0);
            for (n, p) in mdp.next[t.clone()].iter().zip(&mdp.prob[t]) {
                let n = *n as usize;
                q += p * vb[n];
                pg += p * (vb[n] - vb1[n]);
            }
            let q = mdp.choice_reward[c] + q;
            cert.eps_up = cert.eps_up.max(pg - gs);
            if mdp.choice_action[c] == pol_b[s] {
                cert.eps_lo = cert.eps_lo.max(gs - pg);
            }
            if c == lo || q > bar {
                best = q;
                best_c = c;
                bar = beat_bar(best);
                best_pg = pg;
            }
        }
        cert.eps_star = cert.eps_star.max(gs - best_pg);
        cur[k] = best;
        pol[k] = mdp.choice_action[best_c];
    }
    Partial { cert, gmin, gmaxs }
}

/// The finite-horizon tables as the threads of a solve share them: `(H + 1) x n` values and `H x
/// n` actions, stage-major, under the lockstep rule of [`SharedRows`].
struct FhTables<'a> {
    vals: SharedRows<'a, f64>,
    pol: SharedRows<'a, u32>,
    n: usize,
    horizon: usize,
}

impl<'a> FhTables<'a> {
    fn new(vals: &'a mut [f64], pol: &'a mut [u32], n: usize, horizon: usize) -> Self {
        FhTables {
            vals: SharedRows::new(vals, n, horizon + 1),
            pol: SharedRows::new(pol, n, horizon),
            n,
            horizon,
        }
    }

    /// Stage `t`'s values, every state.
    ///
    /// # Safety
    /// Stage `t` was completed before this thread's last combine (or before the solve started).
    unsafe fn values(&self, t: usize) -> &[f64] {
        // SAFETY: no thread writes a completed stage.
        unsafe { self.vals.row(t) }
    }

    /// Stage `t`'s decision rule, every state.
    ///
    /// # Safety
    /// As [`FhTables::values`].
    unsafe fn actions(&self, t: usize) -> &[u32] {
        // SAFETY: as in `values`.
        unsafe { self.pol.row(t) }
    }

    /// Stage `t`'s values and actions at the states `r`, to write.
    ///
    /// # Safety
    /// `r` is this thread's range (no other thread's overlaps it) and no thread reads stage `t`
    /// until the next combine.
    #[allow(clippy::mut_from_ref)]
    unsafe fn stage_mut(&self, t: usize, r: &Range<usize>) -> (&mut [f64], &mut [u32]) {
        // SAFETY: by the caller's contract.
        unsafe { (self.vals.row_mut(t, r), self.pol.row_mut(t, r)) }
    }
}

/// Where a backward induction ended: the stages computed, the early stop's bound, and the stage
/// `t` whose earlier stages are to be extrapolated from base `t + 1` (None: all computed).
#[derive(Debug, Clone, Copy)]
struct FhOutcome {
    computed: u32,
    bound: f64,
    stopped_at: Option<usize>,
}

/// Backward induction on the tables, stage `H` already zero.
struct BackwardInduction<'a> {
    mdp: &'a Mdp,
    tables: FhTables<'a>,
}

impl Sweeps<StageReduction> for BackwardInduction<'_> {
    type Out = FhOutcome;

    /// Backward induction over `lock`'s states of every stage (all of them alone, one range in
    /// a team); every thread of a team takes the same decisions, from the combined reductions.
    /// After an early stop, fills this thread's states of the extrapolated stages.
    fn run(&self, lock: &mut impl Lockstep<StageReduction>) -> FhOutcome {
        let (mdp, tables) = (self.mdp, &self.tables);
        let (n, horizon) = (tables.n, tables.horizon);
        let r = lock.states(n);
        let mut out = FhOutcome {
            computed: 0,
            bound: 0.0,
            stopped_at: None,
        };
        // The second difference at which the last certificate attempt failed: retry only once it
        // has at least halved, so a model that never settles costs no more than a few attempts.
        let mut retry_below = f64::INFINITY;
        // Screen for the stage about to be computed (from the three stages after it), filled
        // by the previous backup.
        let mut screen_next: Option<(f64, f64)> = None;
        let mut t = horizon;
        while t > 0 {
            t -= 1;
            out.computed += 1;
            // SAFETY (every table view below): stages after `t` were completed before the last
            // combine (stage H before the solve); `r` is this thread's range of stage `t`, which
            // no one reads until the combine that ends this stage.
            let (cur, pol_t) = unsafe { tables.stage_mut(t, &r) };
            // Candidate for a certificate at base b = t + 1: needs V_{b+1} (so b + 1 <= H) and
            // the decision rule pi_b (b <= H - 1), and a cheap sign that g has settled:
            // delta = max |d_b - d_{b+1}| (needs V_{b+2}).
            let b = t + 1;
            if let Some((delta, scale)) = screen_next.take() {
                let kk = b as f64;
                let tol = FH_STOP_TOLERANCE * scale;
                if delta < retry_below && kk * (kk + 1.0) * 0.5 * delta <= 16.0 * tol {
                    let (vb, vb1, pol_b) =
                        unsafe { (tables.values(b), tables.values(b + 1), tables.actions(b)) };
                    let cert = certified_range(mdp, vb, vb1, pol_b, r.start, cur, pol_t);
                    // The screen for the stage after, should the certificate fail.
                    let scr = screen(cur, &vb[r.clone()], &vb1[r.clone()]);
                    let all =
                        lock.combine(StageReduction { screen: scr, cert }, StageReduction::merge);
                    let cert = all.cert.certificate();
                    match cert.stop_bound(b) {
                        Some(e) if e.action <= FH_STOP_TOLERANCE * cert.scale(b) => {
                            out.bound = e.value;
                            out.stopped_at = Some(t);
                            break;
                        }
                        _ => retry_below = delta * 0.5,
                    }
                    if t > 0 {
                        screen_next = Some(all.screen);
                    }
                    continue;
                }
            }
            let next = unsafe { tables.values(t + 1) };
            // The stage after this one (t - 1, base t) is a certificate candidate when t + 2 <= H.
            if t > 0 && t + 2 <= horizon {
                let next2 = unsafe { tables.values(t + 2) };
                let scr = backup_stage_screened(mdp, next, next2, r.start, cur, pol_t);
                let cert = Partial::EMPTY;
                let all = lock.combine(StageReduction { screen: scr, cert }, StageReduction::merge);
                screen_next = Some(all.screen);
            } else {
                backup_stage(mdp, next, r.start, cur, pol_t);
                lock.combine(StageReduction::EMPTY, StageReduction::merge);
            }
        }
        if let Some(t) = out.stopped_at {
            fill_extrapolated(tables, t, &r);
        }
        out
    }
}

/// Fill this thread's states `r` of stages `0..t` by the certified extrapolation from base `b =
/// t + 1`: `V_{t'} = V_b + (b - t') g` and the decision rule of stage `t`.
fn fill_extrapolated(tables: &FhTables<'_>, t: usize, r: &Range<usize>) {
    let b = t + 1;
    // SAFETY: stages b, b + 1 are complete, stage t's states `r` are this thread's and
    // complete; stages before t are written only here, by each thread at its own states.
    let (vb, vb1) = unsafe {
        (
            &tables.values(b)[r.clone()],
            &tables.values(b + 1)[r.clone()],
        )
    };
    let row = unsafe { &tables.actions(t)[r.clone()] };
    for tp in 0..t {
        let k = (b - tp) as f64;
        let (out, pol) = unsafe { tables.stage_mut(tp, r) };
        for ((o, v), v1) in out.iter_mut().zip(vb).zip(vb1) {
            *o = v + k * (v - v1);
        }
        pol.copy_from_slice(row);
    }
}

impl Workspace {
    /// Finite-horizon undiscounted backward induction (paper eq. 1–3): `V_H = 0` and
    /// `V_t(s) = max_a R(s,a) + sum_s' p(s'|s,a) V_{t+1}(s')` for `t = H-1 .. 0`. Stage `t` is the
    /// decision taken with `H - t` steps to go; `t = 0` is the decision to execute now.
    ///
    /// **Early stop with a certified bound.** Once the stage differences `g = V_b - V_{b+1}` have
    /// settled, the remaining stages are `V_{b-k} = V_b + k g` up to a bound proved from the
    /// monotonicity of the Bellman operator (see the private `FhCertificate`); when that bound, propagated
    /// over the remaining stages, is below [`FH_STOP_TOLERANCE`] relative to the values, the
    /// earlier stages are filled by that extrapolation (values) and by the last computed decision
    /// rule (actions), and [`FiniteHorizonSolution::stats`] reports the stages actually computed
    /// and the bound (`residual`). Models whose stage differences never settle (periodic ones) are
    /// solved in full.
    ///
    /// **Threads.** A model above the split threshold is solved by a team of every thread of
    /// the current rayon pool, each on its own range of states, in lockstep stage by stage (see
    /// the `lockstep` module); alone when the pool has one thread or another team is running.
    pub fn finite_horizon(&mut self, mdp: &Mdp, horizon: usize) -> FiniteHorizonSolution<'_> {
        let n = mdp.n_states();
        self.reserve(n, horizon, false);
        self.horizon = horizon;
        let par = crate::kernels::split(mdp, self.par_min_transitions);
        self.fh_values[horizon * n..(horizon + 1) * n].fill(0.0);
        let tables = FhTables::new(&mut self.fh_values, &mut self.fh_policy, n, horizon);
        let induction = BackwardInduction { mdp, tables };
        let out = run_sweeps(par && horizon > 0, StageReduction::EMPTY, &induction);
        FiniteHorizonSolution {
            ws: self,
            n,
            horizon,
            computed: out.computed,
            bound: out.bound,
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::{MdpBuilder, Workspace};

    /// Finite horizon by hand: "wait" (action 0, reward 1, self loop) versus "cash" (action 1,
    /// reward 5, to a terminal state). With h steps to go V_h = max(1 + V_{h-1}, 5): V_1 = 5
    /// (cash), then V_h = h + 4 (wait). With a wait reward of 0 instead, V_h = 5 for all h and
    /// from h = 2 on both actions tie, so the lowest index (wait) must be chosen.
    #[test]
    fn finite_horizon_by_hand() {
        for wait_reward in [1.0, 0.0] {
            let mut b = MdpBuilder::new(2, 2);
            b.choice(0, 0, wait_reward, &[(0, 1.0)])
                .choice(0, 1, 5.0, &[(1, 1.0)]);
            let m = b.build().unwrap();
            let mut ws = Workspace::new();
            for h in 1..10usize {
                let fh = ws.finite_horizon(&m, h);
                let expected = if wait_reward == 1.0 {
                    h as f64 + 4.0
                } else {
                    5.0
                };
                assert_eq!(fh.value(0, 0), expected, "h={h}");
                assert_eq!(fh.decision(0), Some(if h == 1 { 1 } else { 0 }), "h={h}");
                // The last stage always cashes in.
                assert_eq!(fh.action(h - 1, 0), Some(1));
                assert_eq!(fh.decision(1), None);
            }
        }
    }
}
