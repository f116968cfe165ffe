//! The elastic glue energy between rigid cells (paper eq. 1–2).
//!
//! For face neighbors `i, j` with rigid motions `T_i(x) = R_i (x − c_i) + p_i`:
//!
//! ```text
//! E_ij = 1/(V_i+V_j) · ∫_{C_i ∪ C_j} |T_i(x) − T_j(x)|² dx
//!      = 1/(V_i+V_j) · Σ_{k∈{i,j}} V_k · ( |T_i(c_k) − T_j(c_k)|² + h_k²/3 · |R_i − R_j|_F² )
//! E    = Σ_{i~j} s_ij · w_ij · E_ij,     w_ij = A_ij / (h_i + h_j)
//! ```
//!
//! The closed form holds because `T_i − T_j` is affine: on a box of half size `h` centered at
//! `c`, the integral of `|M (x − c) + d|²` is `V (|d|² + h²/3 |M|²_F)`. The same integral is
//! computed exactly by a few points ([`quadrature`]: `D + 1` of them, with the union's mean and
//! covariance), which turns the energy into a sum of squared residuals — the form the
//! Gauss-Newton solver works on.

use crate::cells::{Cell, CellComplex};
use crate::rigid::{Motion, Vect};

/// `E_ij` of paper eq. (1) in closed form (without the weight `w_ij`).
pub fn pair_energy<const D: usize>(
    ci: &Cell<D>,
    mi: &Motion<D>,
    cj: &Cell<D>,
    mj: &Motion<D>,
) -> f64 {
    let dr = (mi.rot - mj.rot).norm_squared();
    let term = |c: &Cell<D>| {
        let d = mi.apply(&ci.center, &c.center) - mj.apply(&cj.center, &c.center);
        c.volume() * (d.norm_squared() + c.half * c.half / 3.0 * dr)
    };
    (term(ci) + term(cj)) / (ci.volume() + cj.volume())
}

/// The quadrature points of `E_ij` and their weights: `D + 1` points of weight `1/(D + 1)`,
/// so that `E_ij = Σ weight · |T_i(q) − T_j(q)|²` exactly.
///
/// Every integrand the solver takes over `C_i ∪ C_j` (the residual's square, the Jacobians'
/// products, Newton's curvature) is a product of two maps affine in `x`, so its integral
/// depends on the union's mass, mean `μ` and covariance `Σ` alone; any rule with those three
/// moments is exact. The union, the two boxes weighted by volume (`w_k = V_k / (V_i + V_j)`),
/// has `Σ = α I + w_i w_j d dᵀ` with `α = (w_i h_i² + w_j h_j²) / 3` and `d = c_j − c_i`, whose
/// symmetric square root is `L = √α I + γ d̂ d̂ᵀ`, `(√α + γ)² = α + w_i w_j |d|²`. The points
/// are `μ + L s_k` for the vertices `s_k` of a regular simplex with `Σ s_k = 0` and
/// `Σ s_k s_kᵀ = (D + 1) I`: four points where the two boxes' Gauss points are sixteen (in
/// 3D), the same sums from a quarter of the evaluations (a Gauss-Newton assembly of the hilly
/// strip took half its time, BENCHMARKS.md §3).
pub fn quadrature<const D: usize>(
    ci: &Cell<D>,
    cj: &Cell<D>,
) -> impl Iterator<Item = (Vect<D>, f64)> + use<D> {
    let (vi, vj) = (ci.volume(), cj.volume());
    let (wi, wj) = (vi / (vi + vj), vj / (vi + vj));
    let mean = ci.center * wi + cj.center * wj;
    let d = cj.center - ci.center;
    let alpha = (wi * ci.half * ci.half + wj * cj.half * cj.half) / 3.0;
    let (root, len2) = (alpha.sqrt(), d.norm_squared());
    // `γ / |d|²`, written so that it stays finite (and small) as `d` vanishes.
    let gamma = wi * wj / ((alpha + wi * wj * len2).sqrt() + root);
    let weight = 1.0 / (D + 1) as f64;
    (0..=D).map(move |k| {
        let s = simplex::<D>(k);
        (mean + s * root + d * (gamma * d.dot(&s)), weight)
    })
}

/// Vertex `k` of the regular simplex of [`quadrature`] in `D` dimensions (`D` is 2 or 3):
/// `Σ s_k = 0`, `Σ s_k s_kᵀ = (D + 1) I`.
fn simplex<const D: usize>(k: usize) -> Vect<D> {
    // The tetrahedron of alternate corners of the cube `[−1, 1]³`; the triangle on the circle
    // of radius √2 (at 0°, 120° and 240°).
    const TETRAHEDRON: [[f64; 3]; 4] = [
        [1.0, 1.0, 1.0],
        [1.0, -1.0, -1.0],
        [-1.0, 1.0, -1.0],
        [-1.0, -1.0, 1.0],
    ];
    const TRIANGLE: [[f64; 2]; 3] = [
        [std::f64::consts::SQRT_2, 0.0],
        [-std::f64::consts::FRAC_1_SQRT_2, 1.224_744_871_391_589],
        [-std::f64::consts::FRAC_1_SQRT_2, -1.224_744_871_391_589],
    ];
    match D {
        3 => Vect::<D>::from_fn(|a, _| TETRAHEDRON[k][a]),
        _ => Vect::<D>::from_fn(|a, _| TRIANGLE[k][a]),
    }
}

/// The glue energy `E = Σ s_ij w_ij E_ij` of the whole complex, where `s_ij` is the geometric
/// mean of the two cells' stiffness scales.
pub fn glue_energy<const D: usize>(
    complex: &CellComplex<D>,
    motions: &[Motion<D>],
    stiffness: &[f64],
) -> f64 {
    use rayon::prelude::*;
    // Summed in chunks of a fixed length and the chunks in order: the same bits whatever the
    // number of threads (the line search compares these sums).
    let parts: Vec<f64> = complex
        .pairs
        .par_chunks(1 << 12)
        .map(|chunk| {
            chunk
                .iter()
                .map(|p| {
                    let (i, j) = (p.i as usize, p.j as usize);
                    let s = (stiffness[i] * stiffness[j]).sqrt();
                    s * p.weight
                        * pair_energy(
                            &complex.cells[i],
                            &motions[i],
                            &complex.cells[j],
                            &motions[j],
                        )
                })
                .sum::<f64>()
        })
        .collect();
    parts.iter().sum()
}

/// The strain of every cell (the paper's refinement criterion, §5): `max_j sqrt(E_ij) / (h_i + h_j)` over its face
/// neighbors `j`; dimensionless, zero for a rigid motion of the whole complex.
pub fn cell_strain<const D: usize>(complex: &CellComplex<D>, motions: &[Motion<D>]) -> Vec<f64> {
    let mut strain = vec![0.0f64; complex.len()];
    for p in &complex.pairs {
        let (i, j) = (p.i as usize, p.j as usize);
        let (ci, cj) = (&complex.cells[i], &complex.cells[j]);
        let s = pair_energy(ci, &motions[i], cj, &motions[j]).sqrt() / (ci.half + cj.half);
        strain[i] = strain[i].max(s);
        strain[j] = strain[j].max(s);
    }
    strain
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::{CellKey, CellKind};
    use crate::rigid::{Dim, Mat, Rigid};
    use rand::{Rng, SeedableRng, rngs::StdRng};

    fn cell<const D: usize>(center: Vect<D>, half: f64) -> Cell<D> {
        Cell {
            key: CellKey {
                level: 0,
                coord: [0; D],
            },
            center,
            half,
            kind: CellKind::Boundary,
        }
    }

    /// Midpoint rule on `n^D` sub-boxes of each cell: an independent numerical quadrature of
    /// paper eq. (1).
    fn midpoint<const D: usize>(
        ci: &Cell<D>,
        mi: &Motion<D>,
        cj: &Cell<D>,
        mj: &Motion<D>,
        n: usize,
    ) -> f64 {
        let mut sum = 0.0;
        for c in [ci, cj] {
            let step = 2.0 * c.half / n as f64;
            let dv = step.powi(D as i32);
            for idx in 0..n.pow(D as u32) {
                let x = Vect::<D>::from_fn(|a, _| {
                    let k = (idx / n.pow(a as u32)) % n;
                    c.center[a] - c.half + (k as f64 + 0.5) * step
                });
                sum += (mi.apply(&ci.center, &x) - mj.apply(&cj.center, &x)).norm_squared() * dv;
            }
        }
        sum / (ci.volume() + cj.volume())
    }

    fn random_motion<const D: usize>(rng: &mut StdRng, center: &Vect<D>) -> Motion<D>
    where
        Dim<D>: Rigid<D>,
    {
        let axis = Vect::<D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
        Motion {
            rot: <Dim<D> as Rigid<D>>::axis_angle(&axis, rng.random_range(-3.0..3.0)),
            pos: center + Vect::<D>::from_fn(|_, _| rng.random_range(-0.5..0.5)),
        }
    }

    fn check<const D: usize>(n: usize)
    where
        Dim<D>: Rigid<D>,
    {
        let mut rng = StdRng::seed_from_u64(7);
        for ratio in [1.0, 2.0, 4.0] {
            for _ in 0..4 {
                let hi = rng.random_range(0.2..1.0);
                let hj = hi / ratio;
                let ci = cell(Vect::<D>::zeros(), hi);
                let mut off = Vect::<D>::zeros();
                off[0] = hi + hj;
                let cj = cell(off, hj);
                let (mi, mj) = (
                    random_motion(&mut rng, &ci.center),
                    random_motion(&mut rng, &cj.center),
                );
                let closed = pair_energy(&ci, &mi, &cj, &mj);
                let numeric = midpoint(&ci, &mi, &cj, &mj, n);
                assert!(
                    (closed - numeric).abs() <= 2e-3 * closed,
                    "D={D} ratio {ratio}: closed {closed} vs midpoint {numeric}"
                );
                let gauss: f64 = quadrature(&ci, &cj)
                    .map(|(q, w)| {
                        w * (mi.apply(&ci.center, &q) - mj.apply(&cj.center, &q)).norm_squared()
                    })
                    .sum();
                assert!((closed - gauss).abs() <= 1e-12 * closed);
            }
        }
    }

    /// The rule's mass, mean and second moment are the union's (each box's moments summed,
    /// weighted by volume), for cells of any sizes and any offset.
    fn moments<const D: usize>()
    where
        Dim<D>: Rigid<D>,
    {
        let mut rng = StdRng::seed_from_u64(11);
        for _ in 0..50 {
            let hi = rng.random_range(0.1..2.0);
            let hj = hi * [1.0, 0.5, 0.25, 2.0][rng.random_range(0..4)];
            let ci = cell(Vect::<D>::from_fn(|_, _| rng.random_range(-5.0..5.0)), hi);
            let off = if rng.random_bool(0.2) {
                Vect::<D>::zeros()
            } else {
                Vect::<D>::from_fn(|_, _| rng.random_range(-3.0..3.0))
            };
            let cj = cell(ci.center + off, hj);
            let total = ci.volume() + cj.volume();
            let (mut mass, mut first, mut second) = (0.0, Vect::<D>::zeros(), Mat::<D>::zeros());
            for (q, w) in quadrature(&ci, &cj) {
                mass += w;
                first += q * w;
                second += q * q.transpose() * w;
            }
            let (mut want_first, mut want_second) = (Vect::<D>::zeros(), Mat::<D>::zeros());
            for c in [&ci, &cj] {
                let w = c.volume() / total;
                want_first += c.center * w;
                want_second += (c.center * c.center.transpose()
                    + Mat::<D>::identity() * (c.half * c.half / 3.0))
                    * w;
            }
            let scale = want_second.norm();
            assert!((mass - 1.0).abs() < 1e-14);
            assert!((first - want_first).norm() <= 1e-13 * scale.sqrt().max(1.0));
            assert!((second - want_second).norm() <= 1e-13 * scale, "D={D}");
        }
    }

    #[test]
    fn the_rule_has_the_unions_moments() {
        moments::<3>();
        moments::<2>();
    }

    #[test]
    fn closed_form_matches_numerical_quadrature_3d() {
        check::<3>(24);
    }

    #[test]
    fn closed_form_matches_numerical_quadrature_2d() {
        check::<2>(200);
    }

    #[test]
    fn rigid_motion_of_both_cells_has_zero_energy() {
        let ci = cell(Vect::<3>::zeros(), 0.5);
        let cj = cell(Vect::<3>::new(0.75, 0.0, 0.0), 0.25);
        let r = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::new(1.0, 1.0, 0.0), 1.0);
        let t = Vect::<3>::new(3.0, -1.0, 2.0);
        let m = |c: &Cell<3>| Motion {
            rot: r,
            pos: r * c.center + t,
        };
        assert!(pair_energy(&ci, &m(&ci), &cj, &m(&cj)) < 1e-24);
    }
}
