//! Stage-by-stage sweeps in lockstep: one thread alone, or a team of every thread of the current
//! rayon pool, each on a fixed range of states, meeting after each stage to combine the stage's
//! reductions (minima and maxima, exact whatever the order).
//!
//! Why a team rather than a fork-join per stage: a stage of the 10,000-state benchmark model
//! takes about 0.15 ms per thread, and between stages the fork-join's idle worker went to sleep
//! and had to be woken; two threads took 15.5-22 ms against one thread's 30.3 ms (median 17.2,
//! 2026-11-26). A team's threads wait for each other by spinning (then yielding), and keep their
//! own states every stage, so each core's cache keeps its half of the model.

use std::marker::PhantomData;
use std::ops::Range;

/// Rows of `n` entries (a solver's stages or sweep buffers) shared by the threads of a solve.
/// The lockstep rule that makes the unchecked views sound: a thread writes only its own states
/// (its [`Lockstep::states`]) of a row no thread reads until the next [`Lockstep::combine`], and
/// reads only rows no thread writes until then.
pub(crate) struct SharedRows<'a, T> {
    ptr: *mut T,
    n: usize,
    rows: usize,
    _rows: PhantomData<&'a mut [T]>,
}

// SAFETY: the pointer comes from a `&mut` slice that outlives the view; the threads' accesses
// follow the lockstep rule above.
unsafe impl<T: Send + Sync> Sync for SharedRows<'_, T> {}

impl<'a, T> SharedRows<'a, T> {
    /// The first `rows` rows of `n` entries of `buf`.
    pub(crate) fn new(buf: &'a mut [T], n: usize, rows: usize) -> Self {
        assert!(buf.len() >= rows * n);
        SharedRows {
            ptr: buf.as_mut_ptr(),
            n,
            rows,
            _rows: PhantomData,
        }
    }

    /// Row `i`, every state.
    ///
    /// # Safety
    /// No thread writes row `i` while the returned slice lives (the lockstep rule).
    pub(crate) unsafe fn row(&self, i: usize) -> &[T] {
        assert!(i < self.rows);
        // SAFETY: in bounds (checked here and in `new`); read-only by the caller's contract.
        unsafe { std::slice::from_raw_parts(self.ptr.add(i * self.n), self.n) }
    }

    /// Row `i` at the states `r`, to write.
    ///
    /// # Safety
    /// `r` is this thread's range, no other thread's overlaps it, and no thread reads row `i`
    /// while the returned slice lives (the lockstep rule).
    #[allow(clippy::mut_from_ref)]
    pub(crate) unsafe fn row_mut(&self, i: usize, r: &Range<usize>) -> &mut [T] {
        assert!(i < self.rows && r.start <= r.end && r.end <= self.n);
        // SAFETY: in bounds (checked here and in `new`); exclusive by the caller's contract.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.add(i * self.n + r.start), r.len()) }
    }
}

/// How a thread computing some of a stage's states meets the others after the stage.
pub(crate) trait Lockstep<R> {
    /// The states this thread computes, out of `n`.
    fn states(&self, n: usize) -> Range<usize>;
    /// This thread's reduction of the stage folded with every other thread's, in thread order
    /// (the same bits in every thread); returns once every thread has finished the stage, so
    /// the stage's values are complete for all to read.
    fn combine(&mut self, mine: R, fold: fn(R, R) -> R) -> R;
}

/// One thread computing every state.
pub(crate) struct Alone;

impl<R> Lockstep<R> for Alone {
    fn states(&self, n: usize) -> Range<usize> {
        0..n
    }

    fn combine(&mut self, mine: R, _fold: fn(R, R) -> R) -> R {
        mine
    }
}

/// A solve's stages, run by one thread or by each thread of a team.
pub(crate) trait Sweeps<R>: Sync {
    /// What the solve returns (every thread of a team returns the same).
    type Out: Send;
    /// The solve over `lock`'s states.
    fn run(&self, lock: &mut impl Lockstep<R>) -> Self::Out;
}

/// `sweeps` as a team of the current rayon pool's threads when `split` (and a team can run:
/// see [`team::run_team`]), else alone; `init` fills the team's reduction slots.
pub(crate) fn run_sweeps<R: Copy + Send, S: Sweeps<R>>(split: bool, init: R, sweeps: &S) -> S::Out {
    #[cfg(all(feature = "parallel", not(target_arch = "arm")))]
    if split && let Some(out) = team::run_team(init, |member| sweeps.run(member)) {
        return out;
    }
    let _ = (split, init);
    sweeps.run(&mut Alone)
}

#[cfg(all(test, feature = "parallel", not(target_arch = "arm")))]
use team::run_team;

#[cfg(all(feature = "parallel", not(target_arch = "arm")))]
mod team {
    use super::Lockstep;
    use crossbeam_utils::Backoff;
    use std::ops::Range;
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

    /// One team at a time in the process. Its threads wait by spinning, outside rayon's
    /// scheduler: two teams sharing a pool could each hold a thread the other waits for.
    static TEAM_RUNNING: AtomicBool = AtomicBool::new(false);

    /// `body` run by every thread of the current rayon pool as one team, or `None` (nothing run)
    /// when the pool has one thread or another team is running (the caller then runs alone).
    /// Returns the first thread's result.
    pub(crate) fn run_team<R, T>(
        init: R,
        body: impl Fn(&mut Member<'_, R>) -> T + Sync,
    ) -> Option<T>
    where
        R: Copy + Send,
        T: Send,
    {
        let size = rayon::current_num_threads();
        if size < 2
            || TEAM_RUNNING
                .compare_exchange(false, true, Ordering::Acquire, Ordering::Relaxed)
                .is_err()
        {
            return None;
        }
        struct Release;
        impl Drop for Release {
            fn drop(&mut self) {
                TEAM_RUNNING.store(false, Ordering::Release);
            }
        }
        let _release = Release;
        let barrier = Barrier {
            size,
            arrived: AtomicUsize::new(0),
            generation: AtomicUsize::new(0),
            broken: AtomicBool::new(false),
        };
        // Two rows of slots: a thread writes the next stage's row while a slower one may still
        // be reading this stage's.
        let slots: Vec<Mutex<R>> = (0..2 * size).map(|_| Mutex::new(init)).collect();
        let mut results = rayon::broadcast(|ctx| {
            let mut member = Member {
                index: ctx.index(),
                size,
                barrier: &barrier,
                slots: &slots,
                row: 0,
            };
            body(&mut member)
        });
        Some(results.swap_remove(0))
    }

    /// One thread of a team: computes the `index`-th of `size` equal ranges of states.
    pub(crate) struct Member<'a, R> {
        index: usize,
        size: usize,
        barrier: &'a Barrier,
        slots: &'a [Mutex<R>],
        row: usize,
    }

    impl<R: Copy> Lockstep<R> for Member<'_, R> {
        fn states(&self, n: usize) -> Range<usize> {
            let per = n.div_ceil(self.size);
            (self.index * per).min(n)..((self.index + 1) * per).min(n)
        }

        fn combine(&mut self, mine: R, fold: fn(R, R) -> R) -> R {
            let row = &self.slots[self.row * self.size..(self.row + 1) * self.size];
            *lock(&row[self.index]) = mine;
            self.barrier.wait();
            let all = row.iter().map(|s| *lock(s)).reduce(fold);
            self.row ^= 1;
            all.unwrap_or(mine)
        }
    }

    impl<R> Drop for Member<'_, R> {
        fn drop(&mut self) {
            // A thread unwinding out of the team would leave the others waiting for ever.
            if std::thread::panicking() {
                self.barrier.broken.store(true, Ordering::Release);
            }
        }
    }

    fn lock<R>(m: &Mutex<R>) -> std::sync::MutexGuard<'_, R> {
        m.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A reusable barrier whose waiters spin, then yield ([`Backoff::snooze`]): the stages are
    /// a fraction of a millisecond apart, too close for a sleep and a wake-up.
    struct Barrier {
        size: usize,
        arrived: AtomicUsize,
        generation: AtomicUsize,
        broken: AtomicBool,
    }

    impl Barrier {
        fn wait(&self) {
            let generation = self.generation.load(Ordering::Acquire);
            if self.arrived.fetch_add(1, Ordering::AcqRel) + 1 == self.size {
                self.arrived.store(0, Ordering::Relaxed);
                self.generation
                    .store(generation.wrapping_add(1), Ordering::Release);
                return;
            }
            let backoff = Backoff::new();
            while self.generation.load(Ordering::Acquire) == generation {
                assert!(
                    !self.broken.load(Ordering::Acquire),
                    "another thread of the solve's team panicked"
                );
                backoff.snooze();
            }
        }
    }
}

#[cfg(all(test, feature = "parallel", not(target_arch = "arm")))]
mod tests {
    use super::{Lockstep, run_team};
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// The tests here each need the one team slot: one at a time.
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

    fn pool(threads: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool")
    }

    /// Every thread of the pool takes part, the ranges partition the states, and after each
    /// combine every thread sees every other thread's writes of that stage and the same fold.
    #[test]
    fn a_team_covers_the_states_and_sees_each_stage_complete() {
        let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        for threads in [2, 3] {
            let n = 10;
            // One row per stage, as the solvers write a new stage while a slower thread may
            // still read the last one.
            let cells: Vec<AtomicUsize> = (0..n * 51).map(|_| AtomicUsize::new(0)).collect();
            let seen = pool(threads).install(|| {
                run_team(0usize, |m| {
                    let r = m.states(n);
                    let mut folds = Vec::new();
                    for stage in 1..=50 {
                        let row = &cells[stage * n..(stage + 1) * n];
                        for s in r.clone() {
                            row[s].store(stage, Ordering::Relaxed);
                        }
                        let all = m.combine(r.len() * stage, |a, b| a + b);
                        // Every state written at this stage, by whichever thread owns it.
                        assert!(row.iter().all(|c| c.load(Ordering::Relaxed) == stage));
                        folds.push(all);
                    }
                    (r, folds)
                })
            });
            let (r0, folds) = seen.expect("a pool of several threads runs a team");
            assert_eq!(r0.start, 0);
            let expected: Vec<usize> = (1..=50).map(|stage| n * stage).collect();
            assert_eq!(folds, expected, "threads={threads}");
        }
    }

    /// One team at a time: a solve started inside a team runs alone (None), and a team whose
    /// thread panics ends the others with a panic too and frees the next team to run.
    #[test]
    fn nested_teams_run_alone_and_a_panic_ends_the_team() {
        let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
        let p = pool(2);
        let inner = p.install(|| run_team((), |_| run_team((), |_| ()).is_some()));
        assert_eq!(inner, Some(false));
        let crashed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            p.install(|| {
                run_team(0u8, |m| {
                    for stage in 0..5 {
                        assert!(!(stage == 2 && m.states(2).start == 1), "thread 1 fails");
                        m.combine(0, |a, _| a);
                    }
                })
            })
        }));
        assert!(crashed.is_err());
        assert!(p.install(|| run_team((), |_| ())).is_some());
    }
}
