//! Dense linear algebra for exact policy evaluation: an LU solve with partial pivoting.

use nalgebra::{DMatrix, DVector};

/// A pivot smaller than this (relative to the largest matrix entry) makes the evaluation singular.
pub const SINGULAR_TOLERANCE: f64 = 1e-12;

/// Solves `a x = b` for a square `a` (left as given: a row-major copy is factored), `x` written
/// into `b`, by `lu_solve`. Returns `false` if the matrix is singular.
pub fn solve_dense(a: &DMatrix<f64>, b: &mut DVector<f64>) -> bool {
    let m = a.nrows();
    assert!(a.ncols() == m && b.len() == m);
    let mut rows: Vec<f64> = a.transpose().as_slice().to_vec();
    lu_solve(&mut rows, b.as_mut_slice(), m)
}

/// Gaussian elimination with partial pivoting on a row-major `m x m` matrix `a` (overwritten by
/// its factors), `x` written into `b`. `false` if a pivot is NaN or at most
/// [`SINGULAR_TOLERANCE`] times `max(1, max |a|)`. Row-major so row swaps and the elimination's
/// row updates are contiguous; tested against nalgebra's LU.
pub(crate) fn lu_solve(a: &mut [f64], b: &mut [f64], m: usize) -> bool {
    assert!(a.len() == m * m && b.len() == m);
    let scale = a.iter().fold(1.0f64, |s, x| s.max(x.abs()));
    for k in 0..m {
        let mut p = k;
        let mut best = a[k * m + k].abs();
        for i in k + 1..m {
            let x = a[i * m + k].abs();
            if x > best {
                best = x;
                p = i;
            }
        }
        if best.is_nan() || best <= SINGULAR_TOLERANCE * scale {
            return false;
        }
        if p != k {
            let (top, bottom) = a.split_at_mut(p * m);
            top[k * m..k * m + m].swap_with_slice(&mut bottom[..m]);
            b.swap(k, p);
        }
        let (top, bottom) = a.split_at_mut((k + 1) * m);
        let pivot_row = &top[k * m..k * m + m];
        let pivot = pivot_row[k];
        let bk = b[k];
        for (r, row) in bottom.chunks_exact_mut(m).enumerate() {
            let l = row[k] / pivot;
            row[k] = l;
            b[k + 1 + r] -= l * bk;
            if l != 0.0 {
                for (x, u) in row[k + 1..].iter_mut().zip(&pivot_row[k + 1..]) {
                    *x -= l * u;
                }
            }
        }
    }
    for k in (0..m).rev() {
        let row = &a[k * m..k * m + m];
        let mut x = b[k];
        for (u, bj) in row[k + 1..].iter().zip(&b[k + 1..]) {
            x -= u * bj;
        }
        b[k] = x / row[k];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::xorshift_unit;

    #[test]
    fn lu_solve_matches_nalgebra_on_random_systems_and_detects_singular_ones() {
        // uniform in [-1, 1)
        let mut unit = xorshift_unit(0x2545_f491_4f6c_dd1d);
        let mut rnd = move || unit() * 2.0 - 1.0;
        for m in 1..=12 {
            for _ in 0..20 {
                let a0 = DMatrix::from_fn(m, m, |_, _| if rnd() > 0.0 { rnd() } else { 0.0 });
                let b0 = DVector::from_fn(m, |_, _| rnd());
                let Some(expect) = a0.clone().lu().solve(&b0) else {
                    continue;
                };
                if a0.clone().lu().determinant().abs() < 1e-6 {
                    continue; // ill-conditioned: the two eliminations may differ a lot
                }
                let mut b = b0.clone();
                assert!(solve_dense(&a0, &mut b), "m={m}");
                let err = (&b - &expect).amax() / expect.amax().max(1.0);
                assert!(err < 1e-9, "m={m}: {err}");
                // residual of our own answer
                assert!((&a0 * &b - &b0).amax() < 1e-9, "m={m}");
            }
            if m >= 2 {
                // two equal rows: singular, reported, never a division by ~0
                let mut a = DMatrix::from_fn(m, m, |_, _| rnd());
                let r0 = a.row(0).clone_owned();
                a.set_row(m - 1, &r0);
                let mut b = DVector::from_fn(m, |_, _| rnd());
                assert!(!solve_dense(&a, &mut b), "m={m}");
            }
        }
    }

    #[test]
    fn solve_dense_matches_nalgebra_lu() {
        let a0 = DMatrix::from_row_slice(3, 3, &[0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 4.0]);
        let b0 = DVector::from_row_slice(&[1.0, 2.0, 3.0]);
        let expect = a0.clone().lu().solve(&b0).unwrap();
        let mut b = b0;
        assert!(solve_dense(&a0, &mut b));
        assert!((b - expect).amax() < 1e-12);
    }
}
