//! The hot sweeps over the CSR arrays: one Bellman backup per finite-horizon stage and one
//! value-iteration sweep, each with a kernel per fixed successor count. The entry points are
//! `#[inline]` so the solvers in other modules get them inlined, as when they shared one module.

use crate::model::{Mdp, NONE, beat_bar};

/// `sum_t p[t] * v[next[t]]` over the transitions `t..end` of one choice, in transition order.
///
/// With `K > 0` the choice has exactly `K` transitions (`end = t + K`): unrolled, no loop
/// control, which is most of the cost when choices have a few successors. With `K = 0` a plain
/// loop (unrolling it by two measured 6-8 % more ARMv7 instructions on navigation/monolithic).
///
/// # Safety
/// `t <= end <= pr.len() == nx.len()` and every `nx[t..end]` is `< v.len()`.
#[inline(always)]
unsafe fn dot_choice<const K: usize>(
    pr: &[f64],
    nx: &[u32],
    v: &[f64],
    mut t: usize,
    end: usize,
) -> f64 {
    // SAFETY: by the caller's contract.
    unsafe {
        let mut acc = 0.0;
        if K > 0 {
            for i in 0..K {
                acc +=
                    *pr.get_unchecked(t + i) * *v.get_unchecked(*nx.get_unchecked(t + i) as usize);
            }
            return acc;
        }
        while t < end {
            acc += *pr.get_unchecked(t) * *v.get_unchecked(*nx.get_unchecked(t) as usize);
            t += 1;
        }
        acc
    }
}

/// One plain Bellman backup with gamma = 1: `cur = T next`, `pol` the greedy actions. When
/// `next2` (`V_{t+2}`, one stage after `next`) is given, also returns the early-stop screen of
/// [`Workspace::finite_horizon`] for the next stage, `(max_s |cur - 2 next + next2|, max(1, max_s
/// |cur|))`, fused here so the screen costs two loads per state instead of a separate pass.
///
/// The hot loop of the finite-horizon solve: it walks the CSR arrays with running choice and
/// transition cursors (choices of consecutive states and transitions of consecutive choices are
/// contiguous, `state_start[0] = choice_start[0] = 0`) and reads them unchecked. Every index is in
/// range by the layout invariants that [`MdpBuilder::build_unchecked`] and deserialization check
/// before an [`Mdp`] exists (offsets start at 0, are monotone and end at the array lengths; every
/// `next` is `< n_states`) and that nothing can change afterwards ([`Mdp::probs_mut`] and
/// [`Mdp::rewards_mut`] only change values); the debug assertions recheck them. Summation order
/// is the plain one (`acc += p * v` in transition order, then `reward + acc`), so values are
/// bit-identical to the straightforward loop.
///
/// [`Workspace::finite_horizon`]: crate::Workspace::finite_horizon
/// [`MdpBuilder::build_unchecked`]: crate::MdpBuilder::build_unchecked
///
/// `cur` and `pol` hold the states `s0 .. s0 + cur.len()` (all of them, or one thread's chunk);
/// `next` and `next2` hold every state.
#[inline(always)]
fn backup_stage_impl<const SCREEN: bool, const K: usize>(
    mdp: &Mdp,
    next: &[f64],
    next2: &[f64],
    s0: usize,
    cur: &mut [f64],
    pol: &mut [u32],
) -> (f64, f64) {
    let n = next.len();
    let s1 = s0 + cur.len();
    assert!(s1 <= n && pol.len() == cur.len() && mdp.state_start.len() == n + 1);
    if SCREEN {
        assert!(next2.len() == n);
    }
    let (ss, cs, nx, pr) = (&mdp.state_start, &mdp.choice_start, &mdp.next, &mdp.prob);
    let (rw, ca) = (&mdp.choice_reward, &mdp.choice_action);
    debug_assert!(ss[0] == 0 && cs[0] == 0 && ss[n] as usize == rw.len());
    debug_assert!(cs.len() == rw.len() + 1 && ca.len() == rw.len());
    debug_assert!(cs[rw.len()] as usize == nx.len() && pr.len() == nx.len());
    debug_assert!(nx.iter().all(|&j| (j as usize) < n));
    let (mut delta, mut scale) = (0.0f64, 1.0f64);
    // The cursors at the range's first state (0, 0 for the whole model).
    let mut c = ss[s0] as usize;
    let mut t = cs[c] as usize;
    for s in s0..s1 {
        // SAFETY: see the function docs; s < n, c < hi <= n_choices, t < choice_start[c + 1]
        // <= n_transitions, next[t] < n.
        unsafe {
            let hi = *ss.get_unchecked(s + 1) as usize;
            let (best, act) = if c == hi {
                (0.0, NONE)
            } else {
                let end = choice_end::<K>(cs, c, t);
                let acc = dot_choice::<K>(pr, nx, next, t, end);
                t = end;
                let mut best = *rw.get_unchecked(c) + acc;
                let mut best_c = c;
                let mut bar = beat_bar(best);
                c += 1;
                while c < hi {
                    let end = choice_end::<K>(cs, c, t);
                    let acc = dot_choice::<K>(pr, nx, next, t, end);
                    t = end;
                    let q = *rw.get_unchecked(c) + acc;
                    if q > bar {
                        best = q;
                        best_c = c;
                        bar = beat_bar(best);
                    }
                    c += 1;
                }
                (best, *ca.get_unchecked(best_c))
            };
            *cur.get_unchecked_mut(s - s0) = best;
            *pol.get_unchecked_mut(s - s0) = act;
            if SCREEN {
                let d = best - 2.0 * *next.get_unchecked(s) + *next2.get_unchecked(s);
                delta = delta.max(d.abs());
                scale = scale.max(best.abs());
            }
        }
    }
    (delta, scale)
}

/// The end of choice `c`'s transitions, which start at `t`: `t + K` for a uniform model (no
/// load), else from `choice_start`.
///
/// # Safety
/// `c + 1 < cs.len()`.
#[inline(always)]
unsafe fn choice_end<const K: usize>(cs: &[u32], c: usize, t: usize) -> usize {
    if K > 0 {
        debug_assert!(cs[c + 1] as usize == t + K);
        t + K
    } else {
        // SAFETY: by the caller's contract.
        unsafe { *cs.get_unchecked(c + 1) as usize }
    }
}

/// Calls `$f::<.., K>` with `K` the model's uniform successor count (0: mixed counts).
macro_rules! by_successors {
    ($mdp:expr, $f:ident $(::<$($g:tt),*>)?, ($($arg:expr),*)) => {
        match $mdp.uniform_successors {
            1 => $f::<$($($g,)*)? 1>($($arg),*),
            2 => $f::<$($($g,)*)? 2>($($arg),*),
            3 => $f::<$($($g,)*)? 3>($($arg),*),
            4 => $f::<$($($g,)*)? 4>($($arg),*),
            5 => $f::<$($($g,)*)? 5>($($arg),*),
            _ => $f::<$($($g,)*)? 0>($($arg),*),
        }
    };
}

/// Whether a sweep over `mdp` is split across threads: the `parallel` feature is on (never on
/// 32-bit ARM, the A9 build), and the model has at least `min_transitions` transitions (see
/// [`PARALLEL_MIN_TRANSITIONS`]).
#[inline]
pub(crate) fn split(mdp: &Mdp, min_transitions: usize) -> bool {
    cfg!(all(feature = "parallel", not(target_arch = "arm")))
        && mdp.n_transitions() >= min_transitions
        && mdp.n_states() >= 2
}

/// Default [`Workspace::set_parallel_min_transitions`]: models with fewer transitions sweep on
/// one thread (a team meets once per stage or sweep, a fraction of a microsecond across cores,
/// and starts once per solve; the paper's models take under ten microseconds per solve).
/// Measured on the benches' random models (10 actions, 5 successors; finite horizon 100, value
/// iteration gamma 0.95; medians of one run alternating one and two threads, 2026-11-26): two
/// threads against one took, finite horizon and value iteration, 0.82x and 2.1x at 100 states
/// (5,000 transitions), 0.67x and 0.64x at 200 (10,000), 0.60x and 0.61x at 400, 0.50x and
/// 0.60x at 1,000, 0.48x and 0.52x at 10,000; the split pays from about 10,000.
///
/// [`Workspace::set_parallel_min_transitions`]: crate::Workspace::set_parallel_min_transitions
pub const PARALLEL_MIN_TRANSITIONS: usize = 10_000;

/// States per chunk: four chunks per thread, so uneven rows balance out.
#[cfg(all(feature = "parallel", not(target_arch = "arm")))]
fn chunk_size(n: usize) -> usize {
    n.div_ceil(rayon::current_num_threads() * 4).max(1)
}

/// `f(s0, chunk)` over chunks of `out` (the states `s0..`), on rayon's pool when the `parallel`
/// feature is on (else one call), the results combined by `fold` (exact min/max reductions keep
/// the answer independent of the split).
pub(crate) fn par_states<T: Send, R: Send + Sync + Copy>(
    out: &mut [T],
    f: impl Fn(usize, &mut [T]) -> R + Sync,
    fold: fn(R, R) -> R,
    init: R,
) -> R {
    #[cfg(all(feature = "parallel", not(target_arch = "arm")))]
    {
        use rayon::prelude::*;
        let size = chunk_size(out.len());
        out.par_chunks_mut(size)
            .enumerate()
            .map(|(k, c)| f(k * size, c))
            .reduce(|| init, fold)
    }
    #[cfg(not(all(feature = "parallel", not(target_arch = "arm"))))]
    {
        fold(init, f(0, out))
    }
}

/// [`backup_stage_impl`] without the screen, over the states `s0 .. s0 + cur.len()` (all of
/// them, or one thread's range).
#[inline(always)]
pub(crate) fn backup_stage(mdp: &Mdp, next: &[f64], s0: usize, cur: &mut [f64], pol: &mut [u32]) {
    by_successors!(
        mdp,
        backup_stage_impl::<false>,
        (mdp, next, &[], s0, cur, pol)
    );
}

/// [`backup_stage_impl`] with the screen from `next2`, over the states `s0 .. s0 + cur.len()`
/// (the screen's maxima over those states; exact, so a team's combined screen is one pass's).
#[inline(always)]
pub(crate) fn backup_stage_screened(
    mdp: &Mdp,
    next: &[f64],
    next2: &[f64],
    s0: usize,
    cur: &mut [f64],
    pol: &mut [u32],
) -> (f64, f64) {
    by_successors!(
        mdp,
        backup_stage_impl::<true>,
        (mdp, next, next2, s0, cur, pol)
    )
}

/// One value-iteration sweep `nxt = T cur` (terminal states 0) over the states `s0 .. s0 +
/// nxt.len()` (all of them, or one thread's range), returning `(min d, max d)` of `d = nxt - cur`
/// there (infinities when there is no state). The same cursor walk and unchecked reads as
/// [`backup_stage_impl`] (same invariants), with `q = R + gamma * (sum p v)` in transition order.
#[inline(always)]
pub(crate) fn vi_sweep(
    mdp: &Mdp,
    gamma: f64,
    cur: &[f64],
    s0: usize,
    nxt: &mut [f64],
) -> (f64, f64) {
    by_successors!(mdp, vi_sweep_impl, (mdp, gamma, cur, s0, nxt))
}

/// [`vi_sweep`] for models whose choices all have `K` transitions (`K = 0`: any count).
#[inline(always)]
fn vi_sweep_impl<const K: usize>(
    mdp: &Mdp,
    gamma: f64,
    cur: &[f64],
    s0: usize,
    nxt: &mut [f64],
) -> (f64, f64) {
    let n = cur.len();
    let s1 = s0 + nxt.len();
    assert!(s1 <= n && mdp.state_start.len() == n + 1);
    let (ss, cs, nx, pr, rw) = (
        &mdp.state_start,
        &mdp.choice_start,
        &mdp.next,
        &mdp.prob,
        &mdp.choice_reward,
    );
    debug_assert!(ss[0] == 0 && cs[0] == 0 && ss[n] as usize == rw.len());
    debug_assert!(cs.len() == rw.len() + 1 && cs[rw.len()] as usize == nx.len());
    debug_assert!(pr.len() == nx.len() && nx.iter().all(|&j| (j as usize) < n));
    let (mut dmin, mut dmax) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut c = ss[s0] as usize;
    let mut t = cs[c] as usize;
    for s in s0..s1 {
        // SAFETY: as in backup_stage_impl.
        unsafe {
            let hi = *ss.get_unchecked(s + 1) as usize;
            let mut best = f64::NEG_INFINITY;
            let terminal = c == hi;
            while c < hi {
                let end = choice_end::<K>(cs, c, t);
                let acc = dot_choice::<K>(pr, nx, cur, t, end);
                t = end;
                let q = *rw.get_unchecked(c) + gamma * acc;
                // A plain select (one maxsd), not f64::max's NaN handling: values are finite.
                best = if q > best { q } else { best };
                c += 1;
            }
            let q = if terminal { 0.0 } else { best };
            let d = q - *cur.get_unchecked(s);
            dmin = dmin.min(d);
            dmax = dmax.max(d);
            *nxt.get_unchecked_mut(s - s0) = q;
        }
    }
    (dmin, dmax)
}

#[cfg(test)]
mod tests {
    use crate::model::MAX_UNIFORM_SUCCESSORS;
    use crate::testing::xorshift_unit;
    use crate::{Config, MdpBuilder, Workspace};

    #[test]
    fn fixed_successor_kernels_match_the_general_one_bit_for_bit() {
        // Models where every choice has k successors take the kernels with k fixed at compile
        // time; clearing the marker sends the same model through the general kernel, which must
        // give identical bits (same summation order) for every k with a kernel, and more.
        let mut rnd = xorshift_unit(0x9e37_79b9_7f4a_7c15);
        for k in 1..=MAX_UNIFORM_SUCCESSORS as usize + 1 {
            let (n, m) = (12, 4);
            let mut b = MdpBuilder::new(n, m);
            for s in 1..n {
                for a in 0..m {
                    if a > 0 && rnd() < 0.3 {
                        continue; // not every action admissible
                    }
                    let mut next: Vec<usize> = Vec::new();
                    while next.len() < k {
                        let j = (rnd() * n as f64) as usize % n;
                        if !next.contains(&j) {
                            next.push(j);
                        }
                    }
                    let w: Vec<f64> = (0..k).map(|_| 0.1 + rnd()).collect();
                    let sum: f64 = w.iter().sum();
                    let tr: Vec<(usize, f64)> =
                        next.iter().zip(&w).map(|(&j, &x)| (j, x / sum)).collect();
                    b.choice(s, a, rnd() * 10.0 - 3.0, &tr);
                }
            }
            // state 0 is terminal: the choices' counts stay uniform
            let uniform = b.build().unwrap();
            let expected = if k <= MAX_UNIFORM_SUCCESSORS as usize {
                k as u32
            } else {
                0
            };
            assert_eq!(uniform.uniform_successors, expected, "k={k}");
            let mut general = uniform.clone();
            general.uniform_successors = 0;
            let (mut w1, mut w2) = (Workspace::new(), Workspace::new());
            let (f1, f2) = (
                w1.finite_horizon(&uniform, 60),
                w2.finite_horizon(&general, 60),
            );
            assert_eq!(f1.stats().iterations, f2.stats().iterations, "k={k}");
            for t in 0..60 {
                for s in 0..n {
                    assert_eq!(
                        f1.value(t, s).to_bits(),
                        f2.value(t, s).to_bits(),
                        "k={k} t={t}"
                    );
                    assert_eq!(f1.action(t, s), f2.action(t, s), "k={k} t={t} s={s}");
                }
            }
            let cfg = Config::default();
            let v1 = w1.value_iteration(&uniform, &cfg).unwrap();
            let (vals1, pol1, it1) = (v1.values().to_vec(), v1.policy(), v1.stats.iterations);
            let v2 = w2.value_iteration(&general, &cfg).unwrap();
            assert_eq!(it1, v2.stats.iterations, "k={k}");
            assert_eq!(pol1, v2.policy(), "k={k}");
            for (a, b) in vals1.iter().zip(v2.values()) {
                assert_eq!(a.to_bits(), b.to_bits(), "k={k}");
            }
        }
    }
}
