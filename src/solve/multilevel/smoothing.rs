//! The multilevel path's smoother: Chebyshev polynomials in the block-Jacobi preconditioned
//! matrix of a level, the buffers a V-cycle reuses, and the largest eigenvalue they are
//! scaled by.

use rayon::prelude::*;

use super::super::blocks::*;
use super::{Level, RATIO, SMOOTH_DEGREE};

/// The buffers of one level's V-cycle ([`super::Hierarchy::cycle`]).
pub(super) struct Work {
    /// The residual handed to the coarser level.
    pub(super) residual: Vec<f64>,
    /// The smoother's residual, direction, products and preconditioned residual.
    pub(super) smoothing: Vec<f64>,
    pub(super) direction: Vec<f64>,
    pub(super) product: Vec<f64>,
    pub(super) preconditioned: Vec<f64>,
    /// The coarser level's right-hand side and solution.
    pub(super) coarse_b: Vec<f64>,
    pub(super) coarse_x: Vec<f64>,
}

/// Chebyshev smoothing of `H x = b` from `x` (Saad, Algorithm 12.1, with the block-Jacobi
/// preconditioner); `zero`: `x` is zero, so the residual is `b` itself.
pub(super) fn chebyshev(level: &Level, b: &[f64], x: &mut [f64], zero: bool, w: &mut Work) {
    let a = &level.smoother;
    let (hi, lo) = (level.lambda, level.lambda / RATIO);
    let theta = 0.5 * (hi + lo);
    let delta = 0.5 * (hi - lo);
    let sigma = theta / delta;
    let mut rho = 1.0 / sigma;
    let (r, d, ad, z) = (
        &mut w.smoothing,
        &mut w.direction,
        &mut w.product,
        &mut w.preconditioned,
    );
    r.copy_from_slice(b);
    if !zero {
        a.mul(x, ad);
        r.par_iter_mut().zip(&*ad).for_each(|(r, hx)| *r -= hx);
    }
    precondition(a, &level.inverse, r, d);
    d.par_iter_mut().for_each(|v| *v /= theta);
    for k in 0..SMOOTH_DEGREE {
        x.par_iter_mut().zip(&*d).for_each(|(x, d)| *x += d);
        if k + 1 == SMOOTH_DEGREE {
            break;
        }
        a.mul(d, ad);
        r.par_iter_mut().zip(&*ad).for_each(|(r, ad)| *r -= ad);
        precondition(a, &level.inverse, r, z);
        let rho_next = 1.0 / (2.0 * sigma - rho);
        let (c1, c2) = (rho_next * rho, 2.0 * rho_next / delta);
        d.par_iter_mut()
            .zip(&*z)
            .for_each(|(d, z)| *d = c1 * *d + c2 * z);
        rho = rho_next;
    }
}

/// `z = D⁻¹ r` with the diagonal blocks' inverses.
fn precondition<S: Entry>(a: &BlockMatrix<S>, inverse: &[f64], r: &[f64], z: &mut [f64]) {
    let d = a.dof;
    let bb = d * d;
    z.par_chunks_mut(d).enumerate().for_each(|(i, zi)| {
        let m = &inverse[i * bb..(i + 1) * bb];
        let ri = &r[i * d..(i + 1) * d];
        for row in 0..d {
            zi[row] = dot(&m[row * d..(row + 1) * d], ri);
        }
    });
}

/// The largest eigenvalue of `D⁻¹H` by power iteration, with a 10 % margin.
pub(super) fn largest_eigenvalue(a: &BlockMatrix, inverse: &[f64]) -> f64 {
    let n = a.len();
    // A fixed, non-smooth start vector (reproducible runs).
    let mut v: Vec<f64> = (0..n)
        .map(|i| ((i as u64).wrapping_mul(2654435761) % 1000) as f64 / 1000.0 - 0.5)
        .collect();
    let mut hv = vec![0.0; n];
    let mut lambda = 1.0;
    for _ in 0..12 {
        let nv = norm(&v);
        if nv == 0.0 || !nv.is_finite() {
            break;
        }
        v.iter_mut().for_each(|x| *x /= nv);
        a.mul(&v, &mut hv);
        precondition(a, inverse, &hv, &mut v);
        lambda = norm(&v);
    }
    if lambda.is_finite() && lambda > 0.0 {
        1.1 * lambda
    } else {
        2.0
    }
}
