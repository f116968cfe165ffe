//! The optimal positions for given rotations: variable projection of the glue energy.
//!
//! For fixed rotations the energy is quadratic in the free cells' positions `p_i`. With
//! `T_i(x) = R_i (x − c_i) + p_i`, one pair's energy (see [`super::energy`]) is
//!
//! ```text
//! E_ij = |p_i − p_j + g_ij|² + (terms free of p),
//! g_ij = Σ_{k∈{i,j}} V_k (R_i (c_k − c_i) − R_j (c_k − c_j)) / (V_i + V_j)
//! ```
//!
//! and a soft target adds `λ |R_i (f − c_i) + p_i − t|²`. The minimizer solves `L p = b` with
//! `L` the graph Laplacian of the pair weights `s_ij w_ij` over the free cells (plus the target
//! weights on the diagonal) — one scalar matrix for all `D` coordinates, whose entries do not
//! depend on the motions (`laplacian.rs`). It is factored once per [`Positions`] (per topology)
//! and every call of [`Positions::project`] is one back substitution with `D` right-hand sides;
//! or, split into subdomains (`Positions::by_subdomains`, [`super::schwarz`]), each call is a
//! run of preconditioned conjugate gradients from the current positions.
//!
//! Why: Gauss-Newton linearizes rotations and positions together, so a step with a poor
//! rotation update also leaves the positions off. Replacing the positions of every trial by
//! their optimum for its rotations (Golub–Pereyra variable projection) never raises the energy
//! and removes the position error from the line search. On paper Fig. 4 in 2D (594 cells), where
//! a vortex of the rotation field otherwise forces ~30 shortened steps, it took the iterations
//! from 51 to 26; with the line search also extrapolating full steps, to 16 (14–20 over six
//! seeds; 3D: 15 → 10).

use faer::prelude::*;
use faer::sparse::linalg::solvers::Llt;

use super::constraints::Constraints;
use super::laplacian::{Laplacian, factor, laplacian, pair_weight};
use super::schwarz::{self, Schwarz, Subdomains, Workers};
use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::rigid::{Motion, Vect};
use crate::said::{Opt, Said};

/// The position system of one topology, ready to solve.
pub(crate) struct Positions {
    /// Row of every cell whose position is free.
    row: Vec<Option<u32>>,
    /// Free cells (rows).
    n: usize,
    solver: Option<Solver>,
}

/// How the position system is solved.
enum Solver {
    /// Factored whole, as one process holds it.
    Factor(Llt<usize, f64>),
    /// By subdomains, each factoring its own block ([`super::schwarz`]): what a solve spread
    /// over processes does, here in one.
    Subdomains(Box<Split>),
}

/// The system and its subdomains' preconditioner.
struct Split {
    matrix: Laplacian,
    preconditioner: Schwarz,
}

/// Whether a system of these lower-triangle entries has rows, one of them held (a positive
/// diagonal): without, there is nothing to solve, or nothing holds the free cells.
fn held(lower: &[faer::sparse::Triplet<usize, usize, f64>]) -> bool {
    lower.iter().any(|t| t.row == t.col && t.val > 0.0)
}

/// Relative residual to which the subdomains' conjugate gradients solve the global step: the
/// step must be a block minimization to near rounding for the energy never to rise.
const SUBDOMAIN_TOLERANCE: f64 = 1e-11;

/// Conjugate-gradient iterations at most for one global step by subdomains (from rest on the
/// 389k-cell strip the solve takes about 64 to 1e-8).
const SUBDOMAIN_ITERATIONS: usize = 1000;

impl Positions {
    /// Factors the Laplacian of the free cells. A singular system (a free part with nothing
    /// holding its translation) leaves the projection off: [`Self::project`] does nothing.
    pub fn new<const D: usize>(complex: &CellComplex<D>, constraints: &Constraints<D>) -> Self {
        let (row, n, triplets) = laplacian(complex, constraints);
        let solver = held(&triplets)
            .then(|| factor(n, &triplets).map(Solver::Factor))
            .flatten();
        Self { row, n, solver }
    }

    /// The system split into `subdomains` ([`super::schwarz`]), each block factored alone
    /// (by `workers` where given, else here), solved by preconditioned conjugate gradients.
    /// An error where the workers fail, or where free cells have nothing holding their
    /// positions (the one factor's path leaves such a system to Gauss-Newton; a split asked
    /// for is refused instead of dropped).
    pub fn by_subdomains<const D: usize>(
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        subdomains: usize,
        workers: Option<&dyn Workers>,
    ) -> Result<Self> {
        let (row, n, triplets) = laplacian(complex, constraints);
        if n == 0 {
            return Ok(Self {
                row,
                n,
                solver: None,
            });
        }
        let singular = || {
            Error::param(
                Said::new()
                    .set(Opt::Subdomains, subdomains)
                    .text(": a free part of the cells has nothing holding its position, so the ")
                    .text("global step has no single solution to split; solve without ")
                    .opt(Opt::Subdomains),
            )
        };
        if !held(&triplets) {
            return Err(singular());
        }
        let matrix = Laplacian::from_lower(n, &triplets);
        let split = Subdomains::split(complex, &row, subdomains);
        let aggregate = schwarz::aggregate_size(n);
        let preconditioner = Schwarz::new(&matrix, &split, schwarz::OVERLAP, aggregate, workers)?
            .ok_or_else(singular)?;
        let solver = Some(Solver::Subdomains(Box::new(Split {
            matrix,
            preconditioner,
        })));
        Ok(Self { row, n, solver })
    }

    /// Whether the system can be solved: it has free cells and was factored (whole, or each
    /// subdomain's block and the coarse problem); a free part with nothing holding its
    /// translation makes it singular.
    pub fn is_factored(&self) -> bool {
        self.solver.is_some()
    }

    /// Sets the position of every free cell to its optimum for the current rotations (and the
    /// positions of the other cells). Leaves `motions` unchanged if the solve is not finite.
    /// By subdomains, an error where the workers fail or the iterations do not reach the
    /// optimum to [`SUBDOMAIN_TOLERANCE`] (the step would not be the block minimization the
    /// local-global iteration relies on).
    pub fn project<const D: usize>(
        &self,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        motions: &mut [Motion<D>],
        targets_to: &[Vect<D>],
    ) -> Result<()> {
        let Some(solver) = &self.solver else {
            return Ok(());
        };
        let mut rhs = Mat::<f64>::zeros(self.n, D);
        let mut add = |r: u32, v: Vect<D>| {
            for a in 0..D {
                rhs[(r as usize, a)] += v[a];
            }
        };
        for pr in &complex.pairs {
            let (i, j) = (pr.i as usize, pr.j as usize);
            let (ri, rj) = (self.row[i], self.row[j]);
            if ri.is_none() && rj.is_none() {
                continue;
            }
            let k = pair_weight(constraints, pr.weight, i, j);
            let (ci, cj) = (&complex.cells[i], &complex.cells[j]);
            let (mi, mj) = (&motions[i], &motions[j]);
            let (vi, vj) = (ci.volume(), cj.volume());
            let g = ((mi.rot * (cj.center - ci.center)) * vj
                - (mj.rot * (ci.center - cj.center)) * vi)
                / (vi + vj);
            // Gradient of k |p_i − p_j + g|² set to zero, known positions moved to the right.
            match (ri, rj) {
                (Some(ri), Some(rj)) => {
                    add(ri, -g * k);
                    add(rj, g * k);
                }
                (Some(ri), None) => add(ri, (mj.pos - g) * k),
                (None, Some(rj)) => add(rj, (mi.pos + g) * k),
                (None, None) => {}
            }
        }
        for (t, to) in constraints.targets.iter().zip(targets_to) {
            let c = t.cell as usize;
            if let Some(r) = self.row[c] {
                let m = &motions[c];
                // Along an axis the target leaves free it asks for where the point is now.
                let now = m.apply(&complex.cells[c].center, &t.from);
                let to = to.component_mul(&t.mask) + now.component_mul(&t.mask.map(|v| 1.0 - v));
                add(
                    r,
                    (to - m.rot * (t.from - complex.cells[c].center)) * t.weight,
                );
            }
        }
        let x = match solver {
            Solver::Factor(factor) => crate::with_faer(|| factor.solve(&rhs)),
            Solver::Subdomains(split) => {
                let (l, m) = (&split.matrix, &split.preconditioner);
                let b: Vec<f64> = (0..self.n * D)
                    .map(|k| rhs[(k % self.n, k / self.n)])
                    .collect();
                // From the positions as they are: near the minimum they change little.
                let mut x = vec![0.0; self.n * D];
                for (c, r) in self.row.iter().enumerate() {
                    if let Some(r) = r {
                        for a in 0..D {
                            x[a * self.n + *r as usize] = motions[c].pos[a];
                        }
                    }
                }
                let solved =
                    schwarz::solve(l, m, &b, &mut x, SUBDOMAIN_TOLERANCE, SUBDOMAIN_ITERATIONS)?;
                let reached = solved.residual.is_finite() && solved.residual <= SUBDOMAIN_TOLERANCE;
                if !reached || x.iter().any(|v| !v.is_finite()) {
                    return Err(Error::solver(format!(
                        "the global step by {} subdomains reached a residual of {:.0e}, not \
                         {SUBDOMAIN_TOLERANCE:.0e}, in {} conjugate-gradient iterations",
                        m.subdomains(),
                        solved.residual,
                        solved.iterations
                    )));
                }
                Mat::<f64>::from_fn(self.n, D, |i, a| x[a * self.n + i])
            }
        };
        if !x.col_iter().all(|col| col.iter().all(|v| v.is_finite())) {
            return Ok(());
        }
        for (c, r) in self.row.iter().enumerate() {
            if let Some(r) = r {
                motions[c].pos = Vect::<D>::from_fn(|a, _| x[(*r as usize, a)]);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::{BuildParams, build};
    use crate::memory::Budget;
    use crate::rigid::{Dim, Rigid};
    use crate::solve::constraints::{Role, TargetLocal};
    use crate::solve::total_energy;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    /// After projection no free cell's position can be moved to lower the energy, and the
    /// energy is never above the input's; with cells of several levels, fixed cells and a target.
    #[test]
    fn projected_positions_are_optimal() {
        let mut rng = StdRng::seed_from_u64(5);
        let pts: Vec<Vect<3>> = (0..30_000)
            .map(|_| {
                let v = Vect::<3>::from_fn(|_, _| rng.random_range(-1.0..1.0));
                v.normalize().component_mul(&Vect::<3>::new(2.0, 1.0, 1.0))
            })
            .collect();
        let params = BuildParams {
            cell_size: Some(0.25),
            ..Default::default()
        };
        let complex = build(&pts, &[], &params, Budget::default()).unwrap().0;
        assert!(
            complex
                .cells
                .iter()
                .any(|c| c.key.level < complex.grid.max_level)
        );
        let n = complex.len();
        let mut roles = vec![Role::Free; n];
        roles[0] = Role::Fixed;
        roles[n - 1] = Role::Fixed;
        let target = TargetLocal {
            from: complex.cells[n / 2].center,
            to: complex.cells[n / 2].center + Vect::<3>::new(0.3, 0.0, 0.0),
            wanted: complex.cells[n / 2].center + Vect::<3>::new(0.3, 0.0, 0.0),
            weight: 2.0,
            cell: (n / 2) as u32,
            mask: Vect::<3>::repeat(1.0),
        };
        let constraints = Constraints {
            targets: vec![target],
            stiffness: (0..n).map(|k| 1.0 + (k % 3) as f64).collect(),
            ..Constraints::held(&complex, roles)
        };
        let mut motions: Vec<Motion<3>> = complex
            .cells
            .iter()
            .map(|c| Motion {
                rot: <Dim<3> as Rigid<3>>::axis_angle(
                    &Vect::<3>::from_fn(|_, _| rng.random_range(-1.0..1.0)),
                    rng.random_range(-0.5..0.5),
                ),
                pos: c.center + Vect::<3>::from_fn(|_, _| rng.random_range(-0.1..0.1)),
            })
            .collect();
        let to = [target.to];
        let before = total_energy(&complex, &constraints, &motions, &to);
        let fixed: Vec<_> = [0, n - 1].map(|c| motions[c]).to_vec();
        Positions::new(&complex, &constraints)
            .project(&complex, &constraints, &mut motions, &to)
            .unwrap();
        let after = total_energy(&complex, &constraints, &motions, &to);
        assert!(after < before);
        assert_eq!(vec![motions[0], motions[n - 1]], fixed);
        let eps = 1e-4;
        for c in [1, n / 2, n - 2] {
            for a in 0..3 {
                let mut m = motions.clone();
                m[c].pos[a] += eps;
                let plus = total_energy(&complex, &constraints, &m, &to);
                m[c].pos[a] -= 2.0 * eps;
                let minus = total_energy(&complex, &constraints, &m, &to);
                let slope = (plus - minus) / (2.0 * eps);
                assert!(slope.abs() < 1e-7, "cell {c} axis {a}: slope {slope}");
            }
        }
    }
}
