//! Warm solves on fixed cells: the editor's session.

use std::time::Instant;

use super::system::System;
use super::turns::TurnGauge;
use super::{
    CELLS_ADVICE, Constraints, Solution, SolveParams, SolverInfo, from_rest, minimize_with, timed,
};
use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::{Dim, Motion, Rigid};

/// An editing session on fixed cells: the paper's interactive case. The first solve runs from
/// rest with load steps, as [`super::solve`] does (without refinement); each [`Session::update`] then
/// starts Gauss-Newton from the current motions, without load steps, and reuses the sparse
/// system's symbolic factorization when only the handles, pins and targets moved. A handle
/// dragged a little converges in a few iterations instead of a solve from rest.
pub struct Session<const D: usize> {
    complex: CellComplex<D>,
    constraints: Constraints<D>,
    system: System<D>,
    motions: Vec<Motion<D>>,
    params: SolveParams,
    budget: Budget,
}

impl<const D: usize> Session<D>
where
    Dim<D>: Rigid<D>,
{
    /// Solves `constraints` on `complex` from rest (`params.refine_strain` is not used: a
    /// session's cells stay those of `complex`).
    pub fn new(
        complex: CellComplex<D>,
        constraints: Constraints<D>,
        params: &SolveParams,
        budget: Budget,
        observer: &dyn Observer,
    ) -> Result<(Self, SolverInfo)> {
        let start = Instant::now();
        let (system, motions, mut info) =
            from_rest(&complex, &constraints, params, budget, observer)?;
        observer.finish();
        info.turns = TurnGauge::new(&complex).turns(&constraints, &motions);
        let session = Self {
            complex,
            constraints,
            system,
            motions,
            params: *params,
            budget,
        };
        let info = session.finished(info, start);
        Ok((session, info))
    }

    /// Moves to `constraints` — the same edit with its handles, pins or targets moved, resolved
    /// on the cells the session holds — starting from the current motions. The symbolic
    /// factorization is kept unless the cells' roles, stiffness or targets' cells and weights
    /// changed.
    pub fn update(&mut self, constraints: Constraints<D>) -> Result<SolverInfo> {
        self.update_with(constraints, self.params.max_iterations)
    }

    /// [`Session::update`] with at most `max_iterations` Gauss-Newton iterations: a drag takes
    /// one per pose and goes on from there with the next (the info says whether it converged).
    pub fn update_with(
        &mut self,
        constraints: Constraints<D>,
        max_iterations: usize,
    ) -> Result<SolverInfo> {
        if constraints.roles.len() != self.complex.len() {
            return Err(Error::Solver(format!(
                "the constraints are for {} cells, the session has {}",
                constraints.roles.len(),
                self.complex.len()
            )));
        }
        let start = Instant::now();
        let mut info = SolverInfo {
            cells_initial: self.complex.len(),
            load_steps: 1,
            ..Default::default()
        };
        let same_structure = constraints.roles == self.constraints.roles
            && constraints.stiffness == self.constraints.stiffness
            && constraints.targets.len() == self.constraints.targets.len()
            && constraints
                .targets
                .iter()
                .zip(&self.constraints.targets)
                .all(|(a, b)| a.cell == b.cell && a.weight == b.weight && a.mask == b.mask);
        if !same_structure {
            self.system = timed(&mut info.seconds_symbolic, || {
                System::new(
                    &self.complex,
                    &constraints,
                    self.params.method,
                    self.budget,
                    CELLS_ADVICE,
                )
            })?;
        }
        self.constraints = constraints;
        let params = SolveParams {
            max_iterations,
            ..self.params
        };
        let it = minimize_with(
            &mut self.system,
            &self.complex,
            &self.constraints,
            &mut self.motions,
            1.0,
            &params,
            &mut info,
            &crate::progress::Silent,
        )?;
        info.iterations_per_step.push(it);
        Ok(self.finished(info, start))
    }

    fn finished(&self, mut info: SolverInfo, start: Instant) -> SolverInfo {
        info.cells_final = self.complex.len();
        info.unknowns = self.system.unknowns();
        info.seconds = start.elapsed().as_secs_f64();
        info
    }

    /// The cells.
    pub fn complex(&self) -> &CellComplex<D> {
        &self.complex
    }

    /// The constraints of the last solve.
    pub fn constraints(&self) -> &Constraints<D> {
        &self.constraints
    }

    /// The current motions, one per cell (local frame).
    pub fn motions(&self) -> &[Motion<D>] {
        &self.motions
    }

    /// The session's state as a [`Solution`] with `info`.
    pub fn solution(&self, info: SolverInfo) -> Solution<D> {
        Solution {
            complex: self.complex.clone(),
            motions: self.motions.clone(),
            constraints: self.constraints.clone(),
            info,
        }
    }
}
