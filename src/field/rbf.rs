//! The paper's final transfer: triharmonic radial basis functions (paper §6, [BK05]).
//!
//! The displacement field `d(x) = Σ_i a_i φ(|x − c_i|) + b_0 + B x`, `φ(r) = r³`, interpolates
//! the cell-center displacements `d(c_i) = T_i(c_i) − c_i` exactly, with the side conditions
//! `Σ a_i = 0`, `Σ a_i c_iᵀ = 0` that make it the minimizer of the triharmonic fairness energy:
//!
//! ```text
//! [ Φ   P ] [a]   [d]          Φ_ij = |c_i − c_j|³,   P_i = [1, c_iᵀ]
//! [ Pᵀ  0 ] [b] = [0]
//! ```
//!
//! The matrix depends only on the rest centers: it is factored once per cell complex (dense LU
//! with partial pivoting, faer) and solved for the `D` displacement components at once.
//! Coordinates are scaled to the unit box of the centers first, so the system's conditioning does
//! not depend on the input's units. Evaluation sums over all centers per sample (O(m·n)) with
//! the centers in structure-of-arrays layout and four independent accumulators per component, a
//! loop the compiler vectorizes, built for AVX2 too and chosen at run time with the same bits
//! ([`super::simd`]); samples are parallel in the driver.

use faer::Mat;
use faer::prelude::*;

use super::{Field, Warp};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// The RBF transfer of a field.
pub struct Rbf<const D: usize> {
    /// Center coordinates, axis by axis, scaled.
    centers: [Vec<f64>; D],
    /// Kernel weights `a`, component by component.
    weights: [Vec<f64>; D],
    /// `b_0` per component.
    constant: Vect<D>,
    /// `B` (row: component, column: axis), in scaled coordinates.
    linear: [[f64; D]; D],
    /// Center of the scaling.
    shift: Vect<D>,
    /// Scale factor `1/L`.
    inv_scale: f64,
}

impl<const D: usize> Rbf<D> {
    /// Factors the interpolation system of `field` and solves for the coefficients.
    pub fn new(field: &Field<D>) -> Result<Self> {
        let n = field.centers.len();
        if n == 0 {
            return Err(Error::Solver("the field has no cells".into()));
        }
        let (mut lo, mut hi) = (field.centers[0], field.centers[0]);
        for c in &field.centers {
            lo = lo.inf(c);
            hi = hi.sup(c);
        }
        let shift = (lo + hi) * 0.5;
        let scale = (0.5 * (hi - lo).max()).max(f64::MIN_POSITIVE);
        let inv_scale = 1.0 / scale;
        let c: Vec<Vect<D>> = field
            .centers
            .iter()
            .map(|x| (x - shift) * inv_scale)
            .collect();
        let m = n + D + 1;
        let a = Mat::<f64>::from_fn(m, m, |r, k| match (r < n, k < n) {
            (true, true) => (c[r] - c[k]).norm().powi(3),
            (true, false) => poly(&c[r], k - n),
            (false, true) => poly(&c[k], r - n),
            (false, false) => 0.0,
        });
        let rhs = Mat::<f64>::from_fn(m, D, |r, k| {
            if r < n {
                (field.motions[r].pos[k] - field.centers[r][k]) * inv_scale
            } else {
                0.0
            }
        });
        let x = crate::with_faer(|| a.partial_piv_lu().solve(&rhs));
        if !(0..m).all(|r| (0..D).all(|k| x[(r, k)].is_finite())) {
            return Err(Error::Solver(
                "the RBF system is singular (coincident cell centers?)".into(),
            ));
        }
        Ok(Self {
            centers: std::array::from_fn(|a| c.iter().map(|v| v[a]).collect()),
            weights: std::array::from_fn(|k| (0..n).map(|r| x[(r, k)]).collect()),
            constant: Vect::<D>::from_fn(|k, _| x[(n, k)]),
            linear: std::array::from_fn(|k| std::array::from_fn(|a| x[(n + 1 + a, k)])),
            shift,
            inv_scale,
        })
    }

    /// The displacement `d(x)` at the local point `x`.
    pub fn displacement(&self, x: &Vect<D>) -> Vect<D> {
        let y: [f64; D] = ((x - self.shift) * self.inv_scale).into();
        let sums = super::simd::sum(&y, &self.centers, &self.weights);
        Vect::<D>::from_fn(|k, _| {
            let lin: f64 = (0..D).map(|a| self.linear[k][a] * y[a]).sum();
            (sums[k] + self.constant[k] + lin) / self.inv_scale
        })
    }
}

fn poly<const D: usize>(c: &Vect<D>, k: usize) -> f64 {
    if k == 0 { 1.0 } else { c[k - 1] }
}

impl<const D: usize> Warp<D> for Rbf<D> {
    #[inline]
    fn warp(&self, x: &Vect<D>) -> Vect<D> {
        x + self.displacement(x)
    }

    /// The normal mapped by the inverse transpose of the field's Jacobian, renormalized.
    fn warp_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        let j = self.jacobian(x);
        let mapped = j.try_inverse().map(|inv| inv.transpose() * n).unwrap_or(*n);
        let len = mapped.norm();
        if len > 0.0 && len.is_finite() {
            mapped / len
        } else {
            *n
        }
    }
}

impl<const D: usize> Rbf<D> {
    /// The Jacobian `I + ∂d/∂x` at the local point `x`: `∇_y |y − c|³ = 3 |y − c| (y − c)` in
    /// scaled coordinates, whose scale cancels with the displacement's.
    pub fn jacobian(&self, x: &Vect<D>) -> nalgebra::SMatrix<f64, D, D> {
        let y: [f64; D] = ((x - self.shift) * self.inv_scale).into();
        let mut j = nalgebra::SMatrix::<f64, D, D>::identity();
        for i in 0..self.centers[0].len() {
            let d: [f64; D] = std::array::from_fn(|a| y[a] - self.centers[a][i]);
            let r = d.iter().map(|v| v * v).sum::<f64>().sqrt();
            for k in 0..D {
                let w = 3.0 * r * self.weights[k][i];
                for a in 0..D {
                    j[(k, a)] += w * d[a];
                }
            }
        }
        for k in 0..D {
            for a in 0..D {
                j[(k, a)] += self.linear[k][a];
            }
        }
        j
    }

    /// The coefficients, for saving: `(shift, inv_scale, constant, linear, weights)`.
    #[allow(clippy::type_complexity)]
    pub fn parts(&self) -> (Vect<D>, f64, Vect<D>, [[f64; D]; D], &[Vec<f64>; D]) {
        (
            self.shift,
            self.inv_scale,
            self.constant,
            self.linear,
            &self.weights,
        )
    }

    /// Rebuilds the transfer from saved coefficients over the field's centers.
    pub fn from_parts(
        field: &Field<D>,
        shift: Vect<D>,
        inv_scale: f64,
        constant: Vect<D>,
        linear: [[f64; D]; D],
        weights: [Vec<f64>; D],
    ) -> Result<Self> {
        let n = field.centers.len();
        if weights.iter().any(|w| w.len() != n) {
            return Err(Error::Solver(
                "the saved RBF weights do not match the cells".into(),
            ));
        }
        let c: Vec<Vect<D>> = field
            .centers
            .iter()
            .map(|x| (x - shift) * inv_scale)
            .collect();
        Ok(Self {
            centers: std::array::from_fn(|a| c.iter().map(|v| v[a]).collect()),
            weights,
            constant,
            linear,
            shift,
            inv_scale,
        })
    }
}
