//! The arithmetic of a pair's and a target's blocks in Gauss-Newton's system: `JᵀJ` added to
//! a block stored by its lower triangle, the second-order term of a residual that Newton's
//! steps add, and the positive part that keeps a block semidefinite.

use crate::rigid::{Dim, Rigid, Vect};

use super::{MAX_DOF, tri};

/// `H += a · JᵀJ` on the lower triangle of a diagonal block stored row by row.
#[inline]
pub(super) fn accumulate_diag<const D: usize>(
    h: &mut [f64],
    j: &[Vect<D>; MAX_DOF],
    n: usize,
    a: f64,
) {
    let mut k = 0;
    for x in 0..n {
        for y in 0..=x {
            h[k] += a * j[x].dot(&j[y]);
            k += 1;
        }
    }
}

/// `K += a · ∂²(r · R(ω) y)/∂ω²` at `ω = 0` for the rotated arm `y` (lower triangle of the
/// `ROT × ROT` block): the second-order term of the residual `r` that Gauss-Newton leaves out,
/// `½ r · (e_x × (e_y × y) + e_y × (e_x × y))`.
pub(super) fn accumulate_curvature<const D: usize>(
    k: &mut [f64; 6],
    r: &Vect<D>,
    y: &Vect<D>,
    a: f64,
) where
    Dim<D>: Rigid<D>,
{
    let rot = <Dim<D> as Rigid<D>>::ROT;
    let once = <Dim<D> as Rigid<D>>::cross_jacobian(y);
    let twice: [[Vect<D>; 3]; 3] =
        std::array::from_fn(|s| <Dim<D> as Rigid<D>>::cross_jacobian(&once[s]));
    for x in 0..rot {
        for z in 0..=x {
            k[tri(x) + z] += a * 0.5 * r.dot(&(twice[z][x] + twice[x][z]));
        }
    }
}

/// The positive semidefinite part of a symmetric `n × n` matrix (`n` 1 or 3) stored as its lower
/// triangle: negative eigenvalues set to zero.
pub(super) fn positive_part(k: &[f64; 6], n: usize) -> [f64; 6] {
    if n == 1 {
        return [k[0].max(0.0), 0.0, 0.0, 0.0, 0.0, 0.0];
    }
    let m = nalgebra::Matrix3::new(k[0], k[1], k[3], k[1], k[2], k[4], k[3], k[4], k[5]);
    let eig = m.symmetric_eigen();
    let lambda = eig.eigenvalues.map(|v| v.max(0.0));
    let p =
        eig.eigenvectors * nalgebra::Matrix3::from_diagonal(&lambda) * eig.eigenvectors.transpose();
    [
        p[(0, 0)],
        p[(1, 0)],
        p[(1, 1)],
        p[(2, 0)],
        p[(2, 1)],
        p[(2, 2)],
    ]
}
