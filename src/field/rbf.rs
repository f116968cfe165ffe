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
//! The matrix depends only on the rest centers: it is factored once per cell complex and solved
//! for the `D` displacement components at once, by Cholesky on the system projected onto the
//! side conditions (half the flops of LU on the saddle-point system, see [`projected`]; LU
//! remains for fields of a handful of cells).
//! Coordinates are scaled to the unit box of the centers first, so the system's conditioning does
//! not depend on the input's units. Evaluation sums over all centers per sample (O(m·n)) with
//! the centers in structure-of-arrays layout and four independent accumulators per component, a
//! loop the compiler vectorizes, built for AVX2 too and chosen at run time with the same bits
//! ([`super::simd`]); samples are parallel in the driver.

use faer::Mat;
use faer::prelude::*;

use super::far::FarField;
use super::simd::slices;
use super::{Field, Warp};
use crate::error::{Error, Result};
use crate::rigid::Vect;
use crate::said::{Opt, Said};

/// The RBF transfer of a field.
#[derive(Clone)]
pub struct Rbf<const D: usize> {
    /// In one allocation, so that evaluating a patch of [`super::PuRbf`] reads one block of
    /// memory: the center coordinates axis by axis (scaled), the kernel weights `a` component
    /// by component, and `w_k[i] c_a[i]` axis by axis then component by component (the second
    /// sums of the Jacobian, [`Rbf::jacobian`]); `n` numbers each.
    data: Vec<f64>,
    /// The number of centers.
    n: usize,
    /// `b_0` per component.
    constant: Vect<D>,
    /// `B` (row: component, column: axis), in scaled coordinates.
    linear: [[f64; D]; D],
    /// Center of the scaling.
    shift: Vect<D>,
    /// Scale factor `1/L`.
    inv_scale: f64,
    /// The far-field evaluation, when one was asked for ([`Rbf::with_tolerance`]).
    far: Option<FarField<D>>,
}

impl<const D: usize> Rbf<D> {
    /// Factors the interpolation system of `field` and solves for the coefficients.
    pub fn new(field: &Field<D>) -> Result<Self> {
        let (c, shift, inv_scale) = scaled_centers(field)?;
        let n = c.len();
        let m = n + D + 1;
        let d = Mat::<f64>::from_fn(n, D, |r, k| {
            (field.motions[r].pos[k] - field.centers[r][k]) * inv_scale
        });
        let finite = |x: &Mat<f64>| (0..m).all(|r| (0..D).all(|k| x[(r, k)].is_finite()));
        let mut x = match projected(&c, &d) {
            Some(x) => x,
            None => saddle(&c, &d, 0.0),
        };
        if !finite(&x) {
            x = saddle(&c, &d, DEGENERATE);
        }
        if !finite(&x) {
            return Err(Error::solver(
                "the RBF system is singular (coincident cell centers?)",
            ));
        }
        Ok(Self::from_solution(&c, |r, k| x[(r, k)], shift, inv_scale))
    }

    /// [`Rbf::new`] for a few hundred cells at most, on the calling thread alone: LU of the
    /// whole saddle-point system (nalgebra) and one step of iterative refinement. For the
    /// patches of [`super::PuRbf`], which are fitted in parallel, many small fits each asking
    /// for threads of their own overflowed the worker threads' stacks.
    pub(crate) fn new_serial(field: &Field<D>) -> Result<Self> {
        Self::new_serial_with(field, 0.0).or_else(|_| Self::new_serial_with(field, DEGENERATE))
    }

    /// [`Rbf::new_serial`] with `regularize` on the polynomial block ([`DEGENERATE`]).
    fn new_serial_with(field: &Field<D>, regularize: f64) -> Result<Self> {
        let (c, shift, inv_scale) = scaled_centers(field)?;
        let n = c.len();
        let m = n + D + 1;
        use faer::linalg::lu::partial_pivoting::{factor, solve};
        let a = faer::Mat::<f64>::from_fn(m, m, |r, k| match (r < n, k < n) {
            (true, true) => (c[r] - c[k]).norm().powi(3),
            (true, false) => poly(&c[r], k - n),
            (false, true) => poly(&c[k], r - n),
            (false, false) if r == k => -regularize,
            (false, false) => 0.0,
        });
        let rhs = faer::Mat::<f64>::from_fn(m, D, |r, k| {
            if r < n {
                (field.motions[r].pos[k] - field.centers[r][k]) * inv_scale
            } else {
                0.0
            }
        });
        // faer's sequential LU with partial pivoting (a third of `apply`'s time went to
        // nalgebra's on the corridor's patches); the patches are fitted in parallel already.
        let par = faer::Par::Seq;
        let mut lu = a.clone();
        let (mut fwd, mut inv) = (vec![0usize; m], vec![0usize; m]);
        let mut mem = faer::dyn_stack::MemBuffer::new(faer::dyn_stack::StackReq::any_of(&[
            factor::lu_in_place_scratch::<usize, f64>(m, m, par, Default::default()),
            solve::solve_in_place_scratch::<usize, f64>(m, D, par),
        ]));
        let stack = faer::dyn_stack::MemStack::new(&mut mem);
        let (_, perm) = factor::lu_in_place(
            lu.as_mut(),
            &mut fwd,
            &mut inv,
            par,
            stack,
            Default::default(),
        );
        let mut solved = |b: &mut faer::Mat<f64>| {
            solve::solve_in_place_with_conj(
                lu.as_ref(),
                lu.as_ref(),
                perm,
                faer::Conj::No,
                b.as_mut(),
                par,
                stack,
            )
        };
        let singular = || Error::solver("the RBF system is singular (coincident cell centers?)");
        let mut x = rhs.clone();
        solved(&mut x);
        if !x.col_iter().all(|col| col.iter().all(|v| v.is_finite())) {
            return Err(singular());
        }
        let mut correction = &rhs - &a * &x;
        solved(&mut correction);
        if correction
            .col_iter()
            .all(|col| col.iter().all(|v| v.is_finite()))
        {
            x += &correction;
        }
        Ok(Self::from_solution(&c, |r, k| x[(r, k)], shift, inv_scale))
    }

    /// The transfer from its scaled centers `c` and the solution `x(row, component)` of its
    /// system: `a` in rows `0..n`, then `b_0`, then `B` by rows of axes.
    fn from_solution(
        c: &[Vect<D>],
        x: impl Fn(usize, usize) -> f64,
        shift: Vect<D>,
        inv_scale: f64,
    ) -> Self {
        let n = c.len();
        Self::assemble(
            c,
            std::array::from_fn(|k| (0..n).map(|r| x(r, k)).collect()),
            Vect::<D>::from_fn(|k, _| x(n, k)),
            std::array::from_fn(|k| std::array::from_fn(|a| x(n + 1 + a, k))),
            shift,
            inv_scale,
        )
    }

    /// The transfer from its scaled centers `c` and coefficients.
    fn assemble(
        c: &[Vect<D>],
        weights: [Vec<f64>; D],
        constant: Vect<D>,
        linear: [[f64; D]; D],
        shift: Vect<D>,
        inv_scale: f64,
    ) -> Self {
        let n = c.len();
        let mut data = Vec::with_capacity((2 * D + D * D) * n);
        for a in 0..D {
            data.extend(c.iter().map(|v| v[a]));
        }
        for w in &weights {
            data.extend_from_slice(w);
        }
        for a in 0..D {
            for w in &weights {
                data.extend(w.iter().zip(c).map(|(w, c)| w * c[a]));
            }
        }
        Self {
            data,
            n,
            constant,
            linear,
            shift,
            inv_scale,
            far: None,
        }
    }

    /// Brings the centers and weights (what an evaluation reads) into the caches.
    pub(crate) fn prefetch(&self) {
        super::simd::prefetch(&self.data[..2 * D * self.n]);
    }

    /// The scaled centers, axis by axis.
    #[inline]
    fn centers(&self) -> [&[f64]; D] {
        std::array::from_fn(|a| &self.data[a * self.n..(a + 1) * self.n])
    }

    /// The kernel weights, component by component.
    #[inline]
    fn weights(&self) -> [&[f64]; D] {
        std::array::from_fn(|k| &self.data[(D + k) * self.n..(D + k + 1) * self.n])
    }

    /// `w_k[i] c_a[i]` for axis `a` and component `k`.
    #[inline]
    fn weighted_centers(&self, a: usize, k: usize) -> &[f64] {
        let s = 2 * D + a * D + k;
        &self.data[s * self.n..(s + 1) * self.n]
    }

    /// Evaluates positions through the far field of [`super::far`]: each coordinate of the
    /// displacement within `tolerance` (world units) of the exact sum's. A tolerance of zero
    /// is the exact sum; normals and Jacobians stay exact.
    pub fn with_tolerance(mut self, tolerance: f64) -> Result<Self> {
        Self::check_tolerance(tolerance)?;
        self.far = (tolerance > 0.0)
            .then(|| FarField::new(self.centers(), self.weights(), tolerance * self.inv_scale));
        Ok(self)
    }

    /// The distance (world units) from the centers' centroid within which the far field sums
    /// every center exactly ([`FarField::expands_at`]), if positions are evaluated through one.
    pub fn far_field_reach(&self) -> Option<f64> {
        self.far.as_ref().map(|far| far.reach() / self.inv_scale)
    }

    /// Refuses a far-field tolerance that is not a finite length of at least 0 (what
    /// [`Rbf::with_tolerance`] takes; the CLI checks it before solving).
    pub fn check_tolerance(tolerance: f64) -> Result<()> {
        if tolerance >= 0.0 && tolerance.is_finite() {
            Ok(())
        } else {
            Err(Error::param(
                Said::from("the RBF tolerance (")
                    .opt(Opt::RbfTolerance)
                    .text(format!(") must be a length of at least 0, not {tolerance}")),
            ))
        }
    }

    /// The displacement `d(x)` at the local point `x`.
    pub fn displacement(&self, x: &Vect<D>) -> Vect<D> {
        let y = self.scaled(x);
        let sums = match &self.far {
            Some(far) if far.expands_at(&y) => far.sum(&y),
            _ => super::simd::sum(&y, &self.centers(), &self.weights()),
        };
        self.finish(&y, sums)
    }

    /// [`Rbf::displacement`] at four local points in one pass over the centers, with the same
    /// bits (no far field).
    pub(crate) fn displacements4(&self, xs: &[Vect<D>; 4]) -> [Vect<D>; 4] {
        let ys: [[f64; D]; 4] = std::array::from_fn(|s| self.scaled(&xs[s]));
        let sums = super::simd::sums(&ys, &self.centers(), &self.weights());
        std::array::from_fn(|s| self.finish(&ys[s], sums[s]))
    }

    fn scaled(&self, x: &Vect<D>) -> [f64; D] {
        ((x - self.shift) * self.inv_scale).into()
    }

    /// The displacement at the scaled point `y` from its kernel sums.
    #[inline]
    fn finish(&self, y: &[f64; D], sums: [f64; D]) -> Vect<D> {
        Vect::<D>::from_fn(|k, _| {
            let lin: f64 = (0..D).map(|a| self.linear[k][a] * y[a]).sum();
            (sums[k] + self.constant[k] + lin) / self.inv_scale
        })
    }
}

/// The centers of `field` scaled to the unit box around their middle, with the shift and the
/// inverse scale (so the system's conditioning does not depend on the input's units).
/// The regularization of the polynomial block when the exact system is singular: centers on one
/// plane (or line) leave the linear part's component across it undetermined (a four-point scan
/// with `--transfer rbf` failed the solve, exit 1). `−ε I` there picks the least-norm linear
/// part, zero across the plane, and leaves the interpolation conditions exact; the kernel block's
/// entries are of order 1 to 40 in the scaled coordinates.
const DEGENERATE: f64 = 1e-9;

fn scaled_centers<const D: usize>(field: &Field<D>) -> Result<(Vec<Vect<D>>, Vect<D>, f64)> {
    if field.centers.is_empty() {
        return Err(Error::solver("the field has no cells"));
    }
    let (mut lo, mut hi) = (field.centers[0], field.centers[0]);
    for c in &field.centers {
        lo = lo.inf(c);
        hi = hi.sup(c);
    }
    let shift = (lo + hi) * 0.5;
    let inv_scale = 1.0 / (0.5 * (hi - lo).max()).max(f64::MIN_POSITIVE);
    let c = field
        .centers
        .iter()
        .map(|x| (x - shift) * inv_scale)
        .collect();
    Ok((c, shift, inv_scale))
}

/// The coefficients (`a`, then `b_0`, then `B` by rows of axes) by LU with partial pivoting of
/// the whole saddle-point system: for fields with too few cells for [`projected`].
/// `regularize` goes on the polynomial block's diagonal ([`DEGENERATE`]; 0: the exact system).
fn saddle<const D: usize>(c: &[Vect<D>], d: &Mat<f64>, regularize: f64) -> Mat<f64> {
    let n = c.len();
    let m = n + D + 1;
    let a = Mat::<f64>::from_fn(m, m, |r, k| match (r < n, k < n) {
        (true, true) => (c[r] - c[k]).norm().powi(3),
        (true, false) => poly(&c[r], k - n),
        (false, true) => poly(&c[k], r - n),
        (false, false) if r == k => -regularize,
        (false, false) => 0.0,
    });
    let rhs = Mat::<f64>::from_fn(m, D, |r, k| if r < n { d[(r, k)] } else { 0.0 });
    crate::with_faer(|| a.partial_piv_lu().solve(&rhs))
}

/// The coefficients as [`saddle`] gives them, by Cholesky on the system projected onto the
/// side conditions; `None` when the field has too few cells or the projected matrix is not
/// positive definite (then [`saddle`] decides).
///
/// `r³` is conditionally positive definite of order 2: `aᵀ Φ a > 0` for `a ≠ 0` with `Pᵀ a = 0`.
/// With `P = Q R` (Householder, `q = D + 1` reflectors `H_j = I − τ_j v_j v_jᵀ`) the kernel
/// weights are `a = Q [0; γ]` and `Qᵀ Φ Q = [A11 A12; A21 A22]` with `A22` positive definite:
///
/// ```text
/// A22 γ = (Qᵀ d)[q..],     R b = (Qᵀ d)[..q] − A12 γ
/// ```
///
/// Each reflector changes the matrix by a symmetric rank-2 term, `H M H = M − v uᵀ − u vᵀ` with
/// `w = M v`, `u = τ w − ½ τ² (vᵀ w) v`, so `Qᵀ Φ Q = Φ − Σ_j (v_j u_jᵀ + u_j v_jᵀ)`, and every
/// `w_j` follows from `Φ v_j` and the earlier terms. `Φ` is therefore never stored: one pass of
/// kernel sums gives `Φ V`, and a second writes the lower triangle of `A22` entry by entry,
/// straight into the matrix that Cholesky then factors in place. Before, `Φ` was built, passed
/// over twice per reflector and copied for the factorization, 0.35 s of work at 5.5k cells;
/// the whole factorization went from 1.6–1.7 s to 0.80–0.84 s. Cholesky takes `n³/3` flops
/// against LU's `2n³/3`.
fn projected<const D: usize>(c: &[Vect<D>], d: &Mat<f64>) -> Option<Mat<f64>> {
    use rayon::prelude::*;
    let n = c.len();
    let q = D + 1;
    if n < 2 * q + 8 {
        return None;
    }
    // Householder QR of P.
    let mut p = Mat::<f64>::from_fn(n, q, |r, k| poly(&c[r], k));
    let mut reflectors: Vec<(Vec<f64>, f64)> = Vec::with_capacity(q);
    for j in 0..q {
        let norm = (j..n).map(|r| p[(r, j)] * p[(r, j)]).sum::<f64>().sqrt();
        let alpha = if p[(j, j)] > 0.0 { -norm } else { norm };
        let mut v = vec![0.0; n];
        for r in j..n {
            v[r] = p[(r, j)];
        }
        v[j] -= alpha;
        let vv: f64 = v.iter().map(|x| x * x).sum();
        if vv.is_nan() || vv <= 0.0 || norm == 0.0 {
            return None;
        }
        let tau = 2.0 / vv;
        for k in j..q {
            let dot: f64 = (j..n).map(|r| v[r] * p[(r, k)]).sum();
            for r in j..n {
                p[(r, k)] -= tau * v[r] * dot;
            }
        }
        reflectors.push((v, tau));
    }
    let centers: [Vec<f64>; D] = std::array::from_fn(|a| c.iter().map(|v| v[a]).collect());
    // Φ V, one kernel sum per row for all reflectors at once (padded to 4 with zeros in 2D).
    let phi_v: Vec<Vec<f64>> = {
        let v: [Vec<f64>; 4] = std::array::from_fn(|j| match reflectors.get(j) {
            Some((v, _)) => v.clone(),
            None => vec![0.0; n],
        });
        let rows: Vec<[f64; 4]> = (0..n)
            .into_par_iter()
            .map(|r| super::simd::sum(&c[r].into(), &slices(&centers), &slices(&v)))
            .collect();
        (0..q)
            .map(|j| rows.iter().map(|row| row[j]).collect())
            .collect()
    };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut us: Vec<Vec<f64>> = Vec::with_capacity(q);
    for (j, (v, tau)) in reflectors.iter().enumerate() {
        // w = M_j v with M_j = Φ − Σ_{i<j} (v_i u_iᵀ + u_i v_iᵀ).
        let mut w = phi_v[j].clone();
        for (i, u) in us.iter().enumerate() {
            let vi = &reflectors[i].0;
            let (uv, vv) = (dot(u, v), dot(vi, v));
            for r in 0..n {
                w[r] -= vi[r] * uv + u[r] * vv;
            }
        }
        let s = dot(v, &w);
        us.push(
            v.iter()
                .zip(&w)
                .map(|(vi, wi)| tau * wi - 0.5 * tau * tau * s * vi)
                .collect(),
        );
    }
    let vs: Vec<&[f64]> = reflectors.iter().map(|(v, _)| v.as_slice()).collect();
    let entry = |r: usize, k: usize| -> f64 {
        let mut m = (c[r] - c[k]).norm_squared();
        m *= m.sqrt();
        for (v, u) in vs.iter().zip(&us) {
            m -= v[r] * u[k] + u[r] * v[k];
        }
        m
    };
    // A22's lower triangle, column by column, into zeroed memory the kernel maps on first
    // write (no memset, and the page faults are shared by the threads).
    let m = n - q;
    let mut a22 = vec![0.0f64; m * m];
    a22.par_chunks_mut(m).enumerate().for_each(|(k, col)| {
        for r in k..m {
            col[r] = entry(q + r, q + k);
        }
    });
    let a12 = Mat::<f64>::from_fn(q, m, |r, k| entry(r, q + k));
    let mut l = faer::MatMut::from_column_major_slice_mut(&mut a22, m, m);
    crate::with_faer(|| {
        let par = faer::get_global_parallelism();
        let mut mem = faer::dyn_stack::MemBuffer::new(
            faer::linalg::cholesky::llt::factor::cholesky_in_place_scratch::<f64>(
                m,
                par,
                Default::default(),
            ),
        );
        faer::linalg::cholesky::llt::factor::cholesky_in_place(
            l.rb_mut(),
            Default::default(),
            par,
            faer::dyn_stack::MemStack::new(&mut mem),
            Default::default(),
        )
    })
    .ok()?;
    let l = l.into_const();
    let apply = |z: &mut Mat<f64>, (v, tau): &(Vec<f64>, f64)| {
        for k in 0..z.ncols() {
            let dot: f64 = (0..n).map(|r| v[r] * z[(r, k)]).sum();
            for r in 0..n {
                z[(r, k)] -= tau * v[r] * dot;
            }
        }
    };
    // The coefficients for the right-hand side `d`.
    let solve = |d: &Mat<f64>| -> Mat<f64> {
        let mut qd = d.clone();
        for h in &reflectors {
            apply(&mut qd, h);
        }
        let mut gamma = qd.as_ref().submatrix(q, 0, m, D).to_owned();
        crate::with_faer(|| {
            faer::linalg::cholesky::llt::solve::solve_in_place(
                l,
                gamma.as_mut(),
                faer::get_global_parallelism(),
                faer::dyn_stack::MemStack::new(&mut faer::dyn_stack::MemBuffer::new(
                    faer::dyn_stack::StackReq::EMPTY,
                )),
            )
        });
        // a = Q [0; γ].
        let mut a = Mat::<f64>::from_fn(n, D, |r, k| if r < q { 0.0 } else { gamma[(r - q, k)] });
        for h in reflectors.iter().rev() {
            apply(&mut a, h);
        }
        // R b = (Qᵀ d)[..q] − A12 γ, by back substitution.
        let a12g = &a12 * &gamma;
        let mut b = Mat::<f64>::from_fn(q, D, |r, k| qd[(r, k)] - a12g[(r, k)]);
        for k in 0..D {
            for r in (0..q).rev() {
                let mut v = b[(r, k)];
                for j in r + 1..q {
                    v -= p[(r, j)] * b[(j, k)];
                }
                b[(r, k)] = v / p[(r, r)];
            }
        }
        Mat::<f64>::from_fn(
            n + q,
            D,
            |r, k| if r < n { a[(r, k)] } else { b[(r - n, k)] },
        )
    };
    // Iterative refinement against the unprojected system, whose residual `d − Φ a − P b` is
    // recomputed from the kernel: the projection's rounding otherwise leaves errors of 1.3e-9
    // of the extent at the centers of `tests/field.rs`. One step leaves 7.2e-11 (portable
    // kernel; two steps 5.8e-11) and 8.8e-11 with AVX-512's, where a second step gains
    // nothing: the kernel's own rounding is the limit there.
    let residual = |x: &Mat<f64>| -> Mat<f64> {
        let weights: [Vec<f64>; D] = std::array::from_fn(|k| (0..n).map(|j| x[(j, k)]).collect());
        let rows: Vec<[f64; D]> = (0..n)
            .into_par_iter()
            .map(|r| {
                let y: [f64; D] = c[r].into();
                let sums = super::simd::sum(&y, &slices(&centers), &slices(&weights));
                std::array::from_fn(|k| {
                    let lin: f64 = (0..D).map(|a| c[r][a] * x[(n + 1 + a, k)]).sum();
                    d[(r, k)] - x[(n, k)] - lin - sums[k]
                })
            })
            .collect();
        Mat::<f64>::from_fn(n, D, |r, k| rows[r][k])
    };
    let mut x = solve(d);
    for _ in 0..REFINEMENTS {
        let correction = solve(&residual(&x));
        x += correction;
    }
    Some(x)
}

const REFINEMENTS: usize = 1;

fn poly<const D: usize>(c: &Vect<D>, k: usize) -> f64 {
    if k == 0 { 1.0 } else { c[k - 1] }
}

impl<const D: usize> Warp<D> for Rbf<D> {
    #[inline]
    fn warp(&self, x: &Vect<D>) -> Vect<D> {
        x + self.displacement(x)
    }

    /// Four samples per pass over the centers (`field::simd::sums`), the same bits as
    /// [`Warp::warp`].
    fn warp_run(&self, origin: &Vect<D>, points: &[Vect<D>], out: &mut [Vect<D>]) {
        const S: usize = 4;
        let mut chunks = points.chunks_exact(S);
        let mut outs = out.chunks_exact_mut(S);
        for (p, o) in (&mut chunks).zip(&mut outs) {
            let xs: [Vect<D>; S] = std::array::from_fn(|s| p[s] - origin);
            let ys: [[f64; D]; S] = std::array::from_fn(|s| self.scaled(&xs[s]));
            if let Some(far) = &self.far
                && ys.iter().any(|y| far.expands_at(y))
            {
                for s in 0..S {
                    o[s] = self.warp(&xs[s]) + origin;
                }
                continue;
            }
            let sums = super::simd::sums(&ys, &self.centers(), &self.weights());
            for s in 0..S {
                o[s] = xs[s] + self.finish(&ys[s], sums[s]) + origin;
            }
        }
        for (p, o) in chunks.remainder().iter().zip(outs.into_remainder()) {
            *o = self.warp(&(p - origin)) + origin;
        }
    }

    /// The closed form ([`Rbf::jacobian`]); `h` is not used.
    fn jacobian(&self, x: &Vect<D>, _h: f64) -> nalgebra::SMatrix<f64, D, D> {
        Rbf::jacobian(self, x)
    }

    /// The normal mapped by the inverse transpose of the field's Jacobian, with its length.
    fn warp_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        let j = Rbf::jacobian(self, x);
        let mapped = j.try_inverse().map(|inv| inv.transpose() * n).unwrap_or(*n);
        super::normal_like(mapped, n)
    }
}

impl<const D: usize> Rbf<D> {
    /// The Jacobian `I + ∂d/∂x` at the local point `x`: `∇_y |y − c|³ = 3 |y − c| (y − c)` in
    /// scaled coordinates, whose scale cancels with the displacement's. The sum over centers is
    /// `3 (y_a Σ w_k r − Σ (w_k c_a) r)`: one vectorized pass of `D + D²` sums of `r`
    /// (`field::simd`), with the products `w_k c_a` kept since construction.
    pub fn jacobian(&self, x: &Vect<D>) -> nalgebra::SMatrix<f64, D, D> {
        // One pass for all `D + D²` sums (12 in 3D; in 2D the unused slots repeat a weight
        // vector and their sums are not read).
        let y = self.scaled(x);
        let weights: [&[f64]; 12] = std::array::from_fn(|s| match s {
            s if s < D => self.weights()[s],
            s if s < D + D * D => self.weighted_centers((s - D) / D, (s - D) % D),
            _ => self.weights()[0],
        });
        let sums = super::simd::sum_linear(&y, &self.centers(), &weights);
        let mut j = nalgebra::SMatrix::<f64, D, D>::identity();
        for a in 0..D {
            for k in 0..D {
                j[(k, a)] += 3.0 * (y[a] * sums[k] - sums[D + a * D + k]) + self.linear[k][a];
            }
        }
        j
    }

    /// The coefficients, for saving: `(shift, inv_scale, constant, linear, weights)`.
    #[allow(clippy::type_complexity)]
    pub fn parts(&self) -> (Vect<D>, f64, Vect<D>, [[f64; D]; D], [&[f64]; D]) {
        (
            self.shift,
            self.inv_scale,
            self.constant,
            self.linear,
            self.weights(),
        )
    }

    /// The frame the coefficients are computed in: the center of the cells' centers' box and
    /// one over its half longest extent.
    pub(crate) fn frame_of(field: &Field<D>) -> Result<(Vect<D>, f64)> {
        let (_, shift, inv_scale) = scaled_centers(field)?;
        Ok((shift, inv_scale))
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
            return Err(Error::solver(
                "the saved RBF weights do not match the cells",
            ));
        }
        let c: Vec<Vect<D>> = field
            .centers
            .iter()
            .map(|x| (x - shift) * inv_scale)
            .collect();
        Ok(Self::assemble(
            &c, weights, constant, linear, shift, inv_scale,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rigid::Motion;

    /// `n` centers in a box of edge 8, displaced smoothly and by a little noise, at rest
    /// rotation.
    fn random_field(n: usize, next: &mut impl FnMut() -> f64) -> Field<3> {
        let centers: Vec<Vect<3>> = (0..n)
            .map(|_| Vect::<3>::new(next(), next(), next()) * 4.0)
            .collect();
        Field {
            origin: Vect::<3>::zeros(),
            halves: vec![0.1; n],
            motions: centers
                .iter()
                .map(|c| Motion {
                    rot: nalgebra::SMatrix::<f64, 3, 3>::identity(),
                    pos: c + Vect::<3>::new(0.2 * c.y.sin(), 0.1 * c.x, 0.05 * next()),
                })
                .collect(),
            centers,
            prescribed: Default::default(),
            heights_kept: false,
            trend: Default::default(),
        }
    }

    /// Centers on one plane leave the linear part across it undetermined: the exact system is
    /// singular (a four-point scan with `--transfer rbf` failed, exit 1). The fit now takes the
    /// least-norm linear part and still interpolates every center's motion; for few centers
    /// (the saddle-point LU), many (the projected Cholesky), and the patches' serial fit.
    #[test]
    fn centers_on_one_plane_are_fitted() {
        let mut next = super::super::test_numbers(5);
        for n in [4, 40] {
            let mut field = random_field(n, &mut next);
            for (c, m) in field.centers.iter_mut().zip(&mut field.motions) {
                c.x = 0.5;
                m.pos.x = 0.5;
            }
            for rbf in [Rbf::new(&field).unwrap(), Rbf::new_serial(&field).unwrap()] {
                for (c, m) in field.centers.iter().zip(&field.motions) {
                    let got = rbf.warp(c);
                    assert!((got - m.pos).norm() < 1e-6, "{n}: {got:?} for {:?}", m.pos);
                }
                // Off the plane the map is finite, and moves nothing across it.
                let off = rbf.warp(&Vect::<3>::new(2.0, 1.0, 1.0));
                assert!(off.iter().all(|v| v.is_finite()), "{off:?}");
            }
        }
    }

    /// The vectorized Jacobian against the term-by-term sum of `3 r w (y − c)`, and against
    /// central differences of the displacement.
    #[test]
    fn the_jacobian_matches_its_definition() {
        let mut next = super::super::test_numbers(7);
        let n = 300;
        let field = random_field(n, &mut next);
        let rbf = Rbf::new(&field).unwrap();
        for _ in 0..20 {
            let x = Vect::<3>::new(next(), next(), next()) * 3.0;
            let j = rbf.jacobian(&x);
            let y = rbf.scaled(&x);
            let mut want = nalgebra::SMatrix::<f64, 3, 3>::identity();
            for i in 0..n {
                let d: [f64; 3] = std::array::from_fn(|a| y[a] - rbf.centers()[a][i]);
                let r = d.iter().map(|v| v * v).sum::<f64>().sqrt();
                for k in 0..3 {
                    for a in 0..3 {
                        want[(k, a)] += 3.0 * r * rbf.weights()[k][i] * d[a];
                    }
                }
            }
            for k in 0..3 {
                for a in 0..3 {
                    want[(k, a)] += rbf.linear[k][a];
                }
            }
            assert!(
                (j - want).amax() < 1e-9 * want.amax().max(1.0),
                "{j} vs {want}"
            );
            let h = 1e-5;
            for a in 0..3 {
                let mut e = Vect::<3>::zeros();
                e[a] = h;
                let column = (rbf.warp(&(x + e)) - rbf.warp(&(x - e))) / (2.0 * h);
                assert!((column - j.column(a)).amax() < 1e-5, "column {a}");
            }
        }
    }

    /// Through the far field: points inside the model are summed exactly (the same bits), and
    /// points far enough for expansions to be used stay within the tolerance of the exact sum
    /// (to the exact sum's own rounding).
    #[test]
    fn the_far_field_keeps_its_tolerance() {
        let mut next = super::super::test_numbers(3);
        let n = 400;
        let field = random_field(n, &mut next);
        let exact = Rbf::new(&field).unwrap();
        let tolerance = 0.5;
        let far = exact.clone().with_tolerance(tolerance).unwrap();
        assert!(exact.clone().with_tolerance(-1.0).is_err());
        let reach = far.far_field_reach().unwrap();
        assert!(reach > 8.0, "{reach}");
        let mut expanded = 0;
        for i in 0..200 {
            let s = if i % 2 == 0 {
                3.0
            } else {
                (1.05 + 0.01 * i as f64) * reach
            };
            let x = Vect::<3>::new(next(), next(), next()).normalize() * s;
            let (got, want) = (far.displacement(&x), exact.displacement(&x));
            let y = far.scaled(&x);
            if far.far.as_ref().unwrap().expands_at(&y) {
                expanded += 1;
                let magnitude: f64 = (0..n)
                    .map(|j| {
                        let r2: f64 = (0..3).map(|a| (y[a] - far.centers()[a][j]).powi(2)).sum();
                        (0..3)
                            .map(|k| far.weights()[k][j].abs())
                            .fold(0.0, f64::max)
                            * r2
                            * r2.sqrt()
                    })
                    .sum::<f64>()
                    / far.inv_scale;
                assert!(
                    (got - want).amax() <= tolerance + 1e-14 * magnitude,
                    "{} at {s}",
                    (got - want).amax()
                );
            } else {
                assert_eq!(got, want);
            }
        }
        assert!(expanded > 50, "{expanded}");
        let points: Vec<Vect<3>> = (0..9)
            .map(|_| Vect::<3>::new(next(), next(), 0.0))
            .collect();
        let (mut a, mut b) = (points.clone(), points.clone());
        far.warp_run(&Vect::<3>::zeros(), &points, &mut a);
        exact.warp_run(&Vect::<3>::zeros(), &points, &mut b);
        assert_eq!(a, b);
    }
}
