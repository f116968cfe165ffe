//! A local-global minimization of the glue energy: one constant matrix, factored once.
//!
//! The energy is that of [`super::total_energy`]: every pair `i ~ j` contributes
//! `a_ij Σ_q ω_q |T_i(q) − T_j(q)|²` over its quadrature points ([`super::energy::quadrature`],
//! `a_ij = s_ij w_ij`), every soft target `λ |mask ∘ (T_c(y) − to)|²`. With an auxiliary point
//! `P` per quadrature point, `|T_i − T_j|² = 2 min_P (|T_i − P|² + |T_j − P|²)`, minimized at the
//! midpoint. Two exact block minimizations of that lifted energy alternate, so the energy never
//! rises:
//!
//! - **global**: rotations fixed, the free cells' positions `p` (and `P`, eliminated) solve
//!   `L p = b` with `L` the weighted graph Laplacian of the free cells plus the targets'
//!   weights on the diagonal — the matrix of [`super::positions::Positions`], which does not
//!   depend on the motions and is factored once: every iteration is one back substitution with
//!   `D` right-hand sides. Fixed and handle cells are known values; a pinned cell's position is
//!   `to − R (y − c)`, known given its rotation.
//! - **local**: positions fixed and `P` at the midpoints of the current maps, every rotating
//!   cell's (free or pinned) terms are independent: a Procrustes problem `max tr(Rᵀ M_i)` with
//!   `M_i = Σ a ω (P(q) − y_i)(q − z_i)ᵀ` over its pairs' quadrature points (`z_i` its center of
//!   rotation, `y_i = T_i(z_i)`), solved by the polar factor ([`Rigid::nearest_rotation`]). As
//!   `P` is affine in `q`, each pair side needs only its points' first and second moments about
//!   `z_i`, computed once. A pair whose other cell is prescribed is not lifted: the cell is
//!   fitted to the prescribed map itself (`P = T_j`, weight `a`), still independent of the other
//!   rotating cells. A target's masked-out axes ask for where the point is now (a majorizer of
//!   its term, equal at the current motion), as in the global step.
//!
//! **Anderson acceleration** (Peng, Deng, Zhang, Liu, Zhang 2018, "Anderson acceleration for
//! geometry optimization and physics simulation") of the fixed-point map `G` (rotations → one
//! local step after a global one) on the rotations' `D × D` entries: the candidate
//! `g_k − Σ θ_j Δg_j`, `θ` the least-squares fit of the residual `f_k = g_k − x_k` by the last
//! `m` residual differences, is projected to rotations and kept only where its energy is below
//! the last accepted one; otherwise the plain step `g_k` (never higher) is taken and the history
//! restarts. The energy stays monotone either way.
//!
//! One load step at full load, from the motions given; 3D and 2D share the code.

use std::time::Instant;

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::constraints::{Constraints, Role};
use super::energy::quadrature;
use super::positions::Positions;
use super::{prescribe, targets_at, total_energy};
use crate::cells::CellComplex;
use crate::rigid::{Dim, Mat, Motion, Rigid, Vect};

/// Parameters of [`minimize_local_global`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalGlobalParams {
    /// Iterations at most. Default 1000.
    pub max_iterations: usize,
    /// Stop when an iteration lowers the energy by less than this fraction of it; 0 runs all
    /// `max_iterations`. Default 1e-9.
    pub tolerance: f64,
    /// Previous iterates of Anderson acceleration; 0 turns it off. Default 5.
    pub anderson: usize,
}

impl Default for LocalGlobalParams {
    fn default() -> Self {
        Self {
            max_iterations: 1000,
            tolerance: 1e-9,
            anderson: 5,
        }
    }
}

/// What [`minimize_local_global`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LocalGlobalInfo {
    /// Iterations done.
    pub iterations: usize,
    /// The energy ([`super::total_energy`]) at the start and after every iteration.
    pub energies: Vec<f64>,
    /// Seconds since the start (factorization included) at each entry of `energies`.
    pub seconds: Vec<f64>,
    /// Seconds to factor the position matrix.
    pub seconds_factor: f64,
    /// Mean seconds per iteration (the energy's evaluation included).
    pub seconds_per_iteration: f64,
    /// Iterations whose Anderson candidate was kept.
    pub accelerated: usize,
    /// Seconds in the local steps (the Procrustes fits) over all iterations.
    pub seconds_local: f64,
    /// Seconds in the global steps (back substitutions) over all iterations.
    pub seconds_global: f64,
    /// Seconds evaluating the energy over all iterations.
    pub seconds_energy: f64,
}

/// One side of a pair, seen from a rotating cell: the cell, the other cell, the pair's weight
/// (doubled where the pair is lifted), and the moments `m = Σ ω u`, `S = Σ ω u uᵀ` of the
/// pair's quadrature points `u = q − z` about the cell's center of rotation.
struct Side<const D: usize> {
    other: u32,
    weight: f64,
    lifted: bool,
    first: Vect<D>,
    second: Mat<D>,
}

/// The problem's constant parts.
struct Layout<const D: usize> {
    /// Center of rotation of every cell (the rest center, or the pinned point).
    centers: Vec<Vect<D>>,
    /// Where each pinned cell sends its point (`None` for the other cells).
    pinned: Vec<Option<Vect<D>>>,
    /// Rotating cells (free or pinned).
    rotating: Vec<u32>,
    /// Sides of each rotating cell, in the order of `rotating`.
    sides: Vec<Vec<Side<D>>>,
    /// Targets of each rotating cell.
    targets: Vec<Vec<u32>>,
}

impl<const D: usize> Layout<D> {
    fn new(complex: &CellComplex<D>, constraints: &Constraints<D>) -> Self {
        let n = complex.len();
        let mut centers: Vec<Vect<D>> = complex.cells.iter().map(|c| c.center).collect();
        let mut pinned = vec![None; n];
        let mut index = vec![u32::MAX; n];
        let mut rotating = Vec::new();
        for (c, role) in constraints.roles.iter().enumerate() {
            match role {
                Role::Free => {}
                Role::Pin(k) => {
                    let pin = &constraints.pins[*k as usize];
                    centers[c] = pin.point;
                    pinned[c] = Some(pin.to);
                }
                _ => continue,
            }
            index[c] = rotating.len() as u32;
            rotating.push(c as u32);
        }
        let mut sides: Vec<Vec<Side<D>>> = rotating.iter().map(|_| Vec::new()).collect();
        for pr in &complex.pairs {
            let (i, j) = (pr.i as usize, pr.j as usize);
            let a = (constraints.stiffness[i] * constraints.stiffness[j]).sqrt() * pr.weight;
            let lifted = index[i] != u32::MAX && index[j] != u32::MAX;
            for (me, other) in [(i, j), (j, i)] {
                if index[me] == u32::MAX {
                    continue;
                }
                let (mut first, mut second) = (Vect::<D>::zeros(), Mat::<D>::zeros());
                for (q, w) in quadrature(&complex.cells[i], &complex.cells[j]) {
                    let u = q - centers[me];
                    first += u * w;
                    second += u * u.transpose() * w;
                }
                sides[index[me] as usize].push(Side {
                    other: other as u32,
                    weight: if lifted { 2.0 * a } else { a },
                    lifted,
                    first,
                    second,
                });
            }
        }
        let mut targets: Vec<Vec<u32>> = rotating.iter().map(|_| Vec::new()).collect();
        for (k, t) in constraints.targets.iter().enumerate() {
            let r = index[t.cell as usize];
            if r != u32::MAX {
                targets[r as usize].push(k as u32);
            }
        }
        Self {
            centers,
            pinned,
            rotating,
            sides,
            targets,
        }
    }

    /// The local step: every rotating cell's rotation fitted to the midpoints of its pairs'
    /// current maps (the prescribed maps of its prescribed neighbors) and its targets.
    fn local(
        &self,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        motions: &[Motion<D>],
        targets_to: &[Vect<D>],
    ) -> Vec<Mat<D>>
    where
        Dim<D>: Rigid<D>,
    {
        let map = |c: usize, x: &Vect<D>| motions[c].apply(&complex.cells[c].center, x);
        (0..self.rotating.len())
            .into_par_iter()
            .map(|r| {
                let c = self.rotating[r] as usize;
                let z = self.centers[c];
                let y = map(c, &z);
                let mut m = Mat::<D>::zeros();
                for s in &self.sides[r] {
                    let o = s.other as usize;
                    // The map fitted to, P(x) = A (x − z) + P(z).
                    let (a, pz) = if s.lifted {
                        (
                            (motions[c].rot + motions[o].rot) * 0.5,
                            (y + map(o, &z)) * 0.5,
                        )
                    } else {
                        (motions[o].rot, map(o, &z))
                    };
                    m += (a * s.second + (pz - y) * s.first.transpose()) * s.weight;
                }
                for &k in &self.targets[r] {
                    let t = &constraints.targets[k as usize];
                    let now = map(c, &t.from);
                    let to = targets_to[k as usize].component_mul(&t.mask)
                        + now.component_mul(&t.mask.map(|v| 1.0 - v));
                    m += (to - y) * (t.from - z).transpose() * t.weight;
                }
                if m.iter().all(|v| *v == 0.0) {
                    return motions[c].rot;
                }
                <Dim<D> as Rigid<D>>::nearest_rotation(&m)
            })
            .collect()
    }

    /// Sets the rotating cells' rotations to `rots`, the pinned cells' positions to keep their
    /// points, and the free positions to their optimum (the global step).
    fn global(
        &self,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        positions: &Positions,
        motions: &mut [Motion<D>],
        rots: &[Mat<D>],
        targets_to: &[Vect<D>],
    ) {
        for (&c, rot) in self.rotating.iter().zip(rots) {
            let c = c as usize;
            motions[c].rot = *rot;
            if let Some(to) = self.pinned[c] {
                motions[c].pos = rot * (complex.cells[c].center - self.centers[c]) + to;
            }
        }
        positions.project(complex, constraints, motions, targets_to);
    }
}

/// Minimizes the glue energy at full load by local-global iterations from `start` (the
/// prescribed cells are set to their prescribed motions first). Returns the motions and what
/// was done. See the module docs.
pub fn minimize_local_global<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    start: &[Motion<D>],
    params: &LocalGlobalParams,
) -> (Vec<Motion<D>>, LocalGlobalInfo)
where
    Dim<D>: Rigid<D>,
{
    let clock = Instant::now();
    let mut info = LocalGlobalInfo::default();
    let mut motions = start.to_vec();
    prescribe(complex, constraints, &mut motions, 1.0);
    let targets_to = targets_at(constraints, 1.0);
    let positions = Positions::new(complex, constraints);
    info.seconds_factor = clock.elapsed().as_secs_f64();
    let layout = Layout::new(complex, constraints);
    let start_rots: Vec<Mat<D>> = layout
        .rotating
        .iter()
        .map(|&c| motions[c as usize].rot)
        .collect();
    let (global_time, energy_time) = (std::cell::Cell::new(0.0), std::cell::Cell::new(0.0));
    let step = |motions: &mut [Motion<D>], rots: &[Mat<D>]| {
        let t = Instant::now();
        layout.global(complex, constraints, &positions, motions, rots, &targets_to);
        global_time.set(global_time.get() + t.elapsed().as_secs_f64());
        let t = Instant::now();
        let e = total_energy(complex, constraints, motions, &targets_to);
        energy_time.set(energy_time.get() + t.elapsed().as_secs_f64());
        e
    };
    let mut energy = step(&mut motions, &start_rots);
    info.energies.push(energy);
    info.seconds.push(clock.elapsed().as_secs_f64());
    let loop_start = Instant::now();
    let mut history = Anderson::new(params.anderson);
    let mut x = flatten(&start_rots);
    while info.iterations < params.max_iterations && !layout.rotating.is_empty() {
        let t = Instant::now();
        let g_rots = layout.local(complex, constraints, &motions, &targets_to);
        info.seconds_local += t.elapsed().as_secs_f64();
        let g = flatten(&g_rots);
        let mut next = None;
        if let Some(candidate) = history.push(&x, &g) {
            let rots = unflatten::<D>(&candidate);
            let mut trial = motions.clone();
            let e = step(&mut trial, &rots);
            if e < energy {
                next = Some((trial, e, flatten(&rots)));
                info.accelerated += 1;
            } else {
                history.clear();
                history.push(&x, &g);
            }
        }
        let (trial, e, rots) = next.unwrap_or_else(|| {
            let mut trial = motions.clone();
            let e = step(&mut trial, &g_rots);
            (trial, e, g)
        });
        info.iterations += 1;
        let decrease = energy - e;
        // The plain step never raises the energy; a rise is rounding at the minimum.
        if e <= energy {
            motions = trial;
            x = rots;
            energy = e;
        }
        info.energies.push(energy);
        info.seconds.push(clock.elapsed().as_secs_f64());
        if decrease <= params.tolerance * energy {
            break;
        }
    }
    info.seconds_per_iteration = loop_start.elapsed().as_secs_f64() / info.iterations.max(1) as f64;
    info.seconds_global = global_time.get();
    info.seconds_energy = energy_time.get();
    (motions, info)
}

/// The rotations' entries, one after another.
fn flatten<const D: usize>(rots: &[Mat<D>]) -> Vec<f64> {
    rots.iter().flat_map(|r| r.iter().copied()).collect()
}

/// Rotations nearest to the `D × D` blocks of `x`. An accelerated iterate's blocks are near
/// rotations: Newton's iteration for the polar factor, `X ← (X + X⁻ᵀ) / 2`, converges
/// quadratically there and costs a fraction of an SVD; a block it does not bring to a rotation
/// within a few steps gets the SVD's.
fn unflatten<const D: usize>(x: &[f64]) -> Vec<Mat<D>>
where
    Dim<D>: Rigid<D>,
{
    x.par_chunks(D * D)
        .map(|c| {
            let mut r = Mat::<D>::from_column_slice(c);
            for _ in 0..6 {
                if (r.transpose() * r - Mat::<D>::identity()).norm() < 1e-13
                    && <Dim<D> as Rigid<D>>::determinant(&r) > 0.0
                {
                    return r;
                }
                let Some(inv) = r.try_inverse() else { break };
                r = (r + inv.transpose()) * 0.5;
            }
            <Dim<D> as Rigid<D>>::nearest_rotation(&Mat::<D>::from_column_slice(c))
        })
        .collect()
}

/// Anderson acceleration's history: the last iterates `x` and map values `g`.
struct Anderson {
    depth: usize,
    xs: Vec<Vec<f64>>,
    gs: Vec<Vec<f64>>,
}

impl Anderson {
    fn new(depth: usize) -> Self {
        Self {
            depth,
            xs: Vec::new(),
            gs: Vec::new(),
        }
    }

    fn clear(&mut self) {
        self.xs.clear();
        self.gs.clear();
    }

    /// Records `x` and `g = G(x)` and returns the accelerated iterate, once there are two.
    fn push(&mut self, x: &[f64], g: &[f64]) -> Option<Vec<f64>> {
        if self.depth == 0 {
            return None;
        }
        self.xs.push(x.to_vec());
        self.gs.push(g.to_vec());
        if self.xs.len() > self.depth + 1 {
            self.xs.remove(0);
            self.gs.remove(0);
        }
        let k = self.xs.len();
        if k < 2 {
            return None;
        }
        let n = x.len();
        let f = |i: usize| -> DVector<f64> {
            DVector::from_iterator(n, self.gs[i].iter().zip(&self.xs[i]).map(|(g, x)| g - x))
        };
        let fs: Vec<DVector<f64>> = (0..k).map(f).collect();
        let last = &fs[k - 1];
        let df =
            DMatrix::from_columns(&(0..k - 1).map(|i| &fs[i + 1] - &fs[i]).collect::<Vec<_>>());
        // Normal equations of the least-squares fit, lightly regularized.
        let mut normal = df.transpose() * &df;
        let scale = normal.diagonal().max().max(f64::MIN_POSITIVE);
        for i in 0..k - 1 {
            normal[(i, i)] += 1e-10 * scale;
        }
        let theta = normal.cholesky()?.solve(&(df.transpose() * last));
        let mut out = self.gs[k - 1].clone();
        for (i, t) in theta.iter().enumerate() {
            for (o, (a, b)) in out.iter_mut().zip(self.gs[i + 1].iter().zip(&self.gs[i])) {
                *o -= t * (a - b);
            }
        }
        out.iter().all(|v| v.is_finite()).then_some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::{BuildParams, build};
    use crate::memory::Budget;
    use crate::solve::{SolveParams, SolverInfo, minimize, resolve};
    use crate::spec::parse_spec;

    /// The cells of `pts` (and `triangles`) in cells of `size`, and `spec` resolved on them.
    fn edited<const D: usize>(
        pts: &[Vect<D>],
        triangles: &[[u32; 3]],
        size: f64,
        spec: &str,
    ) -> (CellComplex<D>, Constraints<D>)
    where
        Dim<D>: Rigid<D>,
    {
        let params = BuildParams {
            cell_size: Some(size),
            ..Default::default()
        };
        let complex = build(pts, triangles, &params, Budget::default()).unwrap().0;
        let spec = parse_spec::<D>(spec, ".".as_ref(), "t.toml".as_ref()).unwrap();
        let constraints = resolve(&complex, &spec, pts, None).unwrap();
        (complex, constraints)
    }

    /// Newton's minimum from rest at full load, to rounding.
    fn newton_minimum<const D: usize>(complex: &CellComplex<D>, constraints: &Constraints<D>) -> f64
    where
        Dim<D>: Rigid<D>,
    {
        let mut motions: Vec<Motion<D>> = complex
            .cells
            .iter()
            .map(|c| Motion::rest(&c.center))
            .collect();
        let params = SolveParams {
            max_iterations: 100,
            tolerance: 1e-14,
            move_tolerance: 0.0,
            ..Default::default()
        };
        let mut info = SolverInfo::default();
        minimize(complex, constraints, &mut motions, 1.0, &params, &mut info).unwrap();
        *info.energies.last().unwrap()
    }

    /// The energy never rises, plain or accelerated, and both reach Newton's minimum within
    /// 1e-3 of it and not below it; the accelerated iteration in fewer iterations.
    fn reaches_the_newton_minimum<const D: usize>(
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
    ) where
        Dim<D>: Rigid<D>,
    {
        assert!(
            constraints
                .roles
                .iter()
                .filter(|r| **r == Role::Free)
                .count()
                > 100
        );
        let best = newton_minimum(complex, constraints);
        assert!(best > 0.0);
        let rest: Vec<Motion<D>> = complex
            .cells
            .iter()
            .map(|c| Motion::rest(&c.center))
            .collect();
        let mut reached = Vec::new();
        for anderson in [0, 5] {
            let params = LocalGlobalParams {
                max_iterations: 3000,
                tolerance: 0.0,
                anderson,
            };
            let (motions, info) = minimize_local_global(complex, constraints, &rest, &params);
            for w in info.energies.windows(2) {
                assert!(
                    w[1] <= w[0],
                    "{D}D m = {anderson}: the energy rose from {} to {}",
                    w[0],
                    w[1]
                );
            }
            let last = *info.energies.last().unwrap();
            let to = targets_at(constraints, 1.0);
            assert_eq!(last, total_energy(complex, constraints, &motions, &to));
            assert!(
                last <= best * (1.0 + 1e-3),
                "{D}D m = {anderson}: {last} after {} iterations, Newton {best}",
                info.iterations
            );
            // Not below Newton's minimum by more than rounding: the same energy is minimized.
            assert!(
                last >= best * (1.0 - 1e-9),
                "{D}D m = {anderson}: {last} below {best}"
            );
            let first = info.energies.iter().position(|&e| e <= best * (1.0 + 1e-3));
            reached.push(first.unwrap());
        }
        assert!(
            reached[1] < reached[0],
            "{D}D iterations to 1e-3: {reached:?}"
        );
    }

    /// A 4 × 1 × 1 bar in cells of 0.25, its first 0.5 fixed, its last 0.5 turned by 30° about
    /// y and moved, and a point in its middle pinned and moved.
    #[test]
    fn monotone_and_reaches_the_newton_minimum_3d() {
        let mesh = data_gen::bar([4.0, 1.0, 1.0], 12.0);
        let pts: Vec<Vect<3>> = mesh.vertices.iter().map(|v| Vect::<3>::from(*v)).collect();
        let spec = "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
                    [[handle]]\nbox = { min = [3.5, -0.1, -0.1], max = [4.1, 1.1, 1.1] }\n\
                    rotate = { axis = [0.0, 1.0, 0.0], degrees = 30.0 }\n\
                    translate = [0.0, 0.3, 0.5]\n\
                    [[pin]]\npoint = [2.0, 0.5, 1.0]\nto = [2.0, 0.6, 1.3]\n";
        let (complex, constraints) = edited(&pts, &mesh.triangles, 0.25, spec);
        assert!(constraints.roles.iter().any(|r| matches!(r, Role::Pin(_))));
        reaches_the_newton_minimum(&complex, &constraints);
    }

    /// A filled 4 × 1 rectangle in cells of 0.125, its first 0.5 fixed and its last 0.5 turned
    /// by 30° and moved.
    #[test]
    fn monotone_and_reaches_the_newton_minimum_2d() {
        let pts: Vec<Vect<2>> = (0..=160)
            .flat_map(|i| (0..=40).map(move |j| Vect::<2>::new(i as f64 * 0.025, j as f64 * 0.025)))
            .collect();
        let spec = "[[fixed]]\nbox = { min = [-0.1, -0.1], max = [0.5, 1.1] }\n\
                    [[handle]]\nbox = { min = [3.5, -0.1], max = [4.1, 1.1] }\n\
                    rotate = { degrees = 30.0 }\ntranslate = [0.0, 0.5]\n";
        let (complex, constraints) = edited(&pts, &[], 0.125, spec);
        reaches_the_newton_minimum(&complex, &constraints);
    }
}
