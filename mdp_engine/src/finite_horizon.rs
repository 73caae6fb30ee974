//! Finite-horizon undiscounted backward induction with its certified early stop.

use crate::kernels::{backup_stage, backup_stage_screened};
use crate::model::{Mdp, NONE, beat_bar};
use crate::solution::FiniteHorizonSolution;
use crate::workspace::Workspace;

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

/// The early-stop screen `(max_s |vb - 2 vb1 + vb2|, max(1, max_s |vb|))` as a separate pass.
fn screen(vb: &[f64], vb1: &[f64], vb2: &[f64]) -> (f64, f64) {
    let (mut delta, mut scale) = (0.0f64, 1.0f64);
    for ((a, b), c) in vb.iter().zip(vb1).zip(vb2) {
        delta = delta.max((a - 2.0 * b + c).abs());
        scale = scale.max(a.abs());
    }
    (delta, scale)
}

/// [`backup_stage`] from `vb` (`V_b`) that also measures the [`FhCertificate`] of `g = vb -
/// vb1`, with `pol_b` the decision rule of stage `b`; split across threads when `par` (every
/// measure is a maximum or minimum, so the split changes no bit).
fn backup_certified(
    mdp: &Mdp,
    vb: &[f64],
    vb1: &[f64],
    pol_b: &[u32],
    cur: &mut [f64],
    pol: &mut [u32],
    par: bool,
) -> FhCertificate {
    let range = |s0: usize, cur: &mut [f64], pol: &mut [u32]| {
        certified_range(mdp, vb, vb1, pol_b, s0, cur, pol)
    };
    let init = Partial {
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
    #[cfg(all(feature = "parallel", not(target_arch = "arm")))]
    let p = if par {
        crate::kernels::par_chunks(cur, pol, range, Partial::merge, init)
    } else {
        Partial::merge(init, range(0, cur, pol))
    };
    #[cfg(not(all(feature = "parallel", not(target_arch = "arm"))))]
    let p = {
        let _ = par;
        Partial::merge(init, range(0, cur, pol))
    };
    let mut cert = p.cert;
    cert.span = if p.gmaxs >= p.gmin {
        p.gmaxs - p.gmin
    } else {
        0.0
    };
    cert
}

/// A certificate's measures over some of the states (`span` not yet: from `gmin`, `gmaxs`).
#[derive(Debug, Clone, Copy)]
struct Partial {
    cert: FhCertificate,
    gmin: f64,
    gmaxs: f64,
}

impl Partial {
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

/// [`backup_certified`] over the states `s0 .. s0 + cur.len()` (`cur`, `pol` hold just those).
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

/// Fill stages `0..t` by the certified extrapolation from base `b = t + 1`: `V_{t'} = V_b + (b -
/// t') g` and the decision rule of stage `t`.
fn fill_extrapolated(vals: &mut [f64], pol: &mut [u32], n: usize, t: usize, b: usize) {
    if n == 0 {
        return;
    }
    let (lo, hi) = vals.split_at_mut(b * n);
    let (vb, vb1) = hi[..2 * n].split_at(n);
    for (tp, out) in lo[..t * n].chunks_exact_mut(n).enumerate() {
        let k = (b - tp) as f64;
        for ((o, v), v1) in out.iter_mut().zip(vb).zip(vb1) {
            *o = v + k * (v - v1);
        }
    }
    let (head, row) = pol.split_at_mut(t * n);
    let row = &row[..n];
    for out in head.chunks_exact_mut(n) {
        out.copy_from_slice(row);
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
    pub fn finite_horizon(&mut self, mdp: &Mdp, horizon: usize) -> FiniteHorizonSolution<'_> {
        let n = mdp.n_states();
        self.reserve(n, horizon, false);
        self.horizon = horizon;
        let par = crate::kernels::split(mdp, self.par_min_transitions);
        let (vals, pol) = (&mut self.fh_values, &mut self.fh_policy);
        vals[horizon * n..(horizon + 1) * n].fill(0.0);
        let mut computed = 0u32;
        let mut bound = 0.0;
        // The second difference at which the last certificate attempt failed: retry only once it
        // has at least halved, so a model that never settles costs no more than a few attempts.
        let mut retry_below = f64::INFINITY;
        // Screen for the stage about to be computed (from the three stages after it), filled
        // by the previous backup.
        let mut screen_next: Option<(f64, f64)> = None;
        let mut t = horizon;
        while t > 0 {
            t -= 1;
            computed += 1;
            // Candidate for a certificate at base b = t + 1: needs V_{b+1} (so b + 1 <= H) and
            // the decision rule pi_b (b <= H - 1), and a cheap sign that g has settled:
            // delta = max |d_b - d_{b+1}| (needs V_{b+2}).
            let b = t + 1;
            if let Some((delta, scale)) = screen_next.take() {
                let kk = b as f64;
                let tol = FH_STOP_TOLERANCE * scale;
                if delta < retry_below && kk * (kk + 1.0) * 0.5 * delta <= 16.0 * tol {
                    let (cur, rest) = vals[t * n..(t + 3) * n].split_at_mut(n);
                    let (vb, vb1) = rest.split_at(n);
                    let (pol_t, pol_b) = pol[t * n..(t + 2) * n].split_at_mut(n);
                    let cert = backup_certified(mdp, vb, vb1, pol_b, cur, pol_t, par);
                    match cert.stop_bound(b) {
                        Some(e) if e.action <= FH_STOP_TOLERANCE * cert.scale(b) => {
                            bound = e.value;
                            fill_extrapolated(vals, pol, n, t, b);
                            break;
                        }
                        _ => retry_below = delta * 0.5,
                    }
                    if t > 0 {
                        let (cur, rest) = vals[t * n..(t + 3) * n].split_at(n);
                        let (vb, vb1) = rest.split_at(n);
                        screen_next = Some(screen(cur, vb, vb1));
                    }
                    continue;
                }
            }
            // The stage after this one (t - 1, base t) is a certificate candidate when t + 2 <= H.
            if t > 0 && t + 2 <= horizon {
                let (cur, rest) = vals[t * n..(t + 3) * n].split_at_mut(n);
                let (next, next2) = rest.split_at(n);
                screen_next = Some(backup_stage_screened(
                    mdp,
                    next,
                    next2,
                    cur,
                    &mut pol[t * n..(t + 1) * n],
                    par,
                ));
            } else {
                let (cur, next) = vals[t * n..(t + 2) * n].split_at_mut(n);
                backup_stage(mdp, next, cur, &mut pol[t * n..(t + 1) * n], par);
            }
        }
        FiniteHorizonSolution {
            ws: self,
            n,
            horizon,
            computed,
            bound,
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
