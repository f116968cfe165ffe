//! Which path a [`System`] takes: local-global iterations first under [`Method::Auto`], and
//! Gauss-Newton's system set up (factored or multilevel) where their rate says it finishes
//! sooner.

use super::{Buffers, System};
use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::rigid::Motion;
use crate::rigid::{Dim, Rigid};
use crate::said::Said;
use crate::solve::constraints::Constraints;
use crate::solve::local_global::{self, Destinations, Layout, OffBranch};
use crate::solve::multilevel::COARSEST;
use crate::solve::positions::Positions;
use crate::solve::total_energy;
use crate::solve::{Method, auto};

impl<const D: usize> System<D>
where
    Dim<D>: Rigid<D>,
{
    /// What [`Method::Auto`] takes for Gauss-Newton's system: cells of one size (a scan, a
    /// shell) past `MULTILEVEL_FROM` free cells, the multilevel path (BENCHMARKS.md, "Which
    /// solver `auto` takes": faster from there, in half the memory); otherwise the
    /// factorization where it fits, else the multilevel path (memory linear in the cells).
    pub(super) fn set_up_auto(
        &mut self,
        complex: &CellComplex<D>,
        budget: Budget,
        advice: &Said,
    ) -> Result<()> {
        let level = complex.cells.first().map(|c| c.key.level);
        let uniform = complex.cells.iter().all(|c| Some(c.key.level) == level);
        let multilevel = |system: &mut Self| {
            let cells = complex.len();
            crate::solve::check_solver_memory(cells, Method::Multilevel, budget, advice)?;
            system.buffers = Buffers::default();
            system.set_up_multilevel(complex);
            Ok::<_, Error>(())
        };
        let cells = self.free_cells.len();
        if uniform && cells > auto::MULTILEVEL_FROM {
            return multilevel(self);
        }
        let most_fill = (uniform && cells > COARSEST).then_some(auto::MULTILEVEL_FILL);
        match self.set_up_direct(complex, budget, advice, most_fill) {
            Ok(true) => Ok(()),
            Ok(false) | Err(Error::Memory { .. } | Error::Solver(_)) => multilevel(self),
            Err(e) => Err(e),
        }
    }

    /// Whether Gauss-Newton's system can still be set up in place of local-global iterations
    /// ([`Method::Auto`] took those first).
    pub fn can_switch(&self) -> bool {
        self.local_global && self.deferred.is_some()
    }

    /// Gauss-Newton steps from here on, its system set up as [`Method::Auto`] sets it up.
    pub fn switch_to_gauss_newton(&mut self, complex: &CellComplex<D>) -> Result<()> {
        if let Some((budget, advice)) = self.deferred.take() {
            self.set_up_auto(complex, budget, &advice)?;
        }
        self.local_global = false;
        Ok(())
    }

    /// The factored position Laplacian and the constant parts of local-global iterations on
    /// `complex` under `constraints` (which must be of the structure this system was made for:
    /// the same roles, pins and targets' cells), or `None` where the Laplacian is singular.
    pub fn local_global_parts(
        &self,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
    ) -> Option<(&Positions, &Layout<D>)> {
        self.positions.is_factored().then(|| {
            let layout = self
                .layout
                .get_or_init(|| Layout::new(complex, constraints));
            (&self.positions, layout)
        })
    }

    /// Whether this system takes local-global iterations ([`Method::LocalGlobal`]).
    pub fn is_local_global(&self) -> bool {
        self.local_global
    }
}

/// The local-global iterations of a load step, where `system` takes them: to convergence
/// (`(iterations, None)`: the step is done), or until Gauss-Newton is estimated to finish
/// sooner (`Method::Auto`; then `system` is switched to it for this step and the next, and the
/// answer is the iterations and the energy the motions are left at).
#[allow(clippy::too_many_arguments)]
pub(in crate::internal::solve) fn first<const D: usize>(
    system: &mut System<D>,
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    state: (&mut [Motion<D>], f64, f64),
    to: &Destinations<D>,
    (params, off_branch): (&crate::solve::SolveParams, OffBranch<D>),
    info: &mut crate::solve::SolverInfo,
    observer: &dyn crate::progress::Observer,
) -> Result<(usize, Option<f64>)>
where
    Dim<D>: Rigid<D>,
{
    let switch = |system: &mut System<D>, info: &mut crate::solve::SolverInfo| {
        crate::solve::timed(&mut info.seconds_symbolic, || {
            system.switch_to_gauss_newton(complex)
        })
    };
    // Whether Gauss-Newton's system fits the budget, checked before a switch its iterations'
    // rate did not ask for: where it does not, local-global iterations to the end. The
    // solve's forecast counted it already for its stages.
    let known = info
        .newton_fits
        .iter()
        .find(|(cells, _)| *cells == complex.len())
        .map(|&(_, fits)| fits);
    let fits = |system: &mut System<D>| {
        let fits = system.deferred.as_ref().is_some_and(|(budget, _)| {
            known.unwrap_or_else(|| {
                crate::solve::forecast::newton_fits(complex, constraints, *budget)
            })
        });
        if !fits {
            system.deferred = None;
        }
        fits
    };
    // A strip that converged slowly on coarser cells converges more slowly on these.
    if info.newton_sooner && system.can_switch() && fits(system) {
        switch(system, info)?;
    }
    let (motions, energy, floor) = state;
    if !system.is_local_global() {
        return Ok((0, Some(energy)));
    }
    let budget = system.deferred.as_ref().map(|(budget, _)| *budget);
    let Some(parts) = system.local_global_parts(complex, constraints) else {
        return Ok((0, Some(energy)));
    };
    // Infinite where Gauss-Newton's system does not fit the budget: no rate is slower.
    let newton =
        |budget| crate::solve::forecast::newton_in_local_global(complex, constraints, budget);
    let newton = budget.map(|budget| move || newton(budget));
    let newton = newton.as_ref().map(|f| f as &dyn Fn() -> f64);
    let run = (&mut *motions, energy, floor);
    let watched = (params, newton, off_branch);
    let (it, outcome) = local_global::logged(
        parts,
        complex,
        constraints,
        run,
        to,
        watched,
        info,
        observer,
    )?;
    if outcome != local_global::Outcome::Slower {
        return Ok((it, None));
    }
    info.newton_sooner = true;
    switch(system, info)?;
    Ok((
        it,
        Some(total_energy(complex, constraints, motions, to.targets)),
    ))
}
