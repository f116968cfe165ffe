//! What a solve is asked and what it gives: [`SolveParams`] and the solver [`Method`], the
//! [`SolverInfo`] of a run, the [`Solution`], the parameters of an adaptive solve.

use super::constraints::{Constraints, Role};
use super::iteration::{self, IterationLog, IterationMethod, MOVE_TOLERANCE};
use super::local_global::LOCAL_GLOBAL_PER_ITERATION;
use super::turns::{HandleTurn, TurnRefusal};
use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::rigid::{Motion, Vect};
use crate::said::{Opt, Said};

/// Parameters of [`super::solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveParams {
    /// Gauss-Newton iterations per load step at most. Default 50.
    pub max_iterations: usize,
    /// Local-global iterations a load step may take for each of `max_iterations` (an
    /// accelerated one costs a fifteenth to a twentieth of a factored Gauss-Newton iteration:
    /// BENCHMARKS.md). Default [`LOCAL_GLOBAL_PER_ITERATION`].
    pub local_global_per_iteration: usize,
    /// Stop a load step when an iteration lowers the energy by less than this fraction of it.
    /// Default 1e-6.
    pub tolerance: f64,
    /// Also stop a load step at a full Gauss-Newton step that moves no corner of any cell by
    /// more than this many finest cell sizes (see [`IterationLog::largest_move`]); 0 keeps
    /// only the energy test. Default [`MOVE_TOLERANCE`].
    pub move_tolerance: f64,
    /// Most rotation of any handle per load step, in degrees. Default 30.
    pub max_step_degrees: f64,
    /// Most handle, pin or target displacement per load step, as a fraction of the longest
    /// extent of the cells. Default 0.25.
    pub max_step_fraction: f64,
    /// Split cells whose strain exceeds this; `None` (default): no refinement.
    pub refine_strain: Option<f64>,
    /// Split cells whose strain exceeds this fraction of the largest cell strain of the round
    /// (when `refine_strain` is `None`); `None` (default): no refinement. See [`adaptive`].
    pub refine_fraction: Option<f64>,
    /// Before solving, merge sibling cells of one role into their parent up to this many
    /// times ([`super::coarsen`]). Default 0. See [`adaptive`].
    pub coarsen_levels: u8,
    /// Levels refinement may add below the finest static level. Default 2.
    pub refine_levels: u8,
    /// Rounds of refinement at most. Default 4.
    pub max_refinements: usize,
    /// Coarse stages before the cells themselves are solved (the `coarse` module): 0 solves
    /// them from rest; `None` (default): as many as the cells call for (none below
    /// [`super::COARSE_FROM`] cells).
    pub coarse_levels: Option<u8>,
    /// How each Gauss-Newton system is solved, or local-global iterations instead. Default
    /// [`Method::Auto`].
    pub method: Method,
    /// Parts of the shape without any constraint ride along rigidly with the nearest cell of
    /// a constrained part ([`super::carry_loose`]); `false` keeps them at rest. Default `true`.
    pub carry_loose: bool,
    /// After a load step's first iteration, add the rotations' second-order term to the
    /// Gauss-Newton matrix (Newton's method; see the module docs). Default `true`.
    pub newton: bool,
    /// Newton's curvature from a load step's first iteration on (with `newton`): for motions
    /// already near this step's minimum (a session converging its pose in place, where a first
    /// Gauss-Newton step lowers the energy by less than `tolerance` some hundredths of a cell
    /// short of the minimum along a long twist). Default `false`; coarse to fine sets it for
    /// every finer stage, which starts at its parents' minimum carried down.
    pub newton_at_start: bool,
    /// Local-global iterations with the global step solved by this many subdomains
    /// ([`super::schwarz`]): what a solve spread over processes does. 0 (default): as
    /// `method` says. Past 0 it takes the place of `method`'s Gauss-Newton systems.
    pub subdomains: usize,
    /// Who factors and solves the subdomains' blocks ([`super::schwarz::register`]); `None`
    /// (default): this process.
    pub workers: Option<super::schwarz::WorkersId>,
    /// The scale of the inside's stiffness that the constraints carry by default
    /// (`--interior-stiffness` at its default): where a turn gives way under it, the solve
    /// starts over with the inside a solid's (1), which holds turns a soft inside cannot (a
    /// soft inside resists a part's section folding in as little as it resists a twist), and
    /// says so ([`SolverInfo::inside_stiffened`]); a complex with no inside refuses the turn
    /// as it is. `None` (default): the stiffness is as asked.
    pub soft_inside: Option<f64>,
}

/// How the Gauss-Newton normal equations are solved.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Method {
    /// [`Method::Multilevel`] for cells of one size (a scan, a shell) past 100,000 free cells,
    /// or where their Cholesky factor would hold more than 200 entries per unknown (its work
    /// grows as their square: thick or closed shapes); otherwise [`Method::Direct`] where its
    /// factor fits the memory budget and its 32-bit indices, else [`Method::Multilevel`]
    /// (BENCHMARKS.md: which is faster where).
    #[default]
    Auto,
    /// faer's supernodal sparse Cholesky (memory grows faster than the cells: its fill).
    Direct,
    /// Conjugate gradients preconditioned by a rigid-motion aggregation multigrid
    /// (`multilevel` module; memory and work per iteration linear in the cells).
    Multilevel,
    /// No Gauss-Newton system: local-global iterations on the constant position Laplacian,
    /// factored once, with Anderson acceleration (the `local_global` module).
    LocalGlobal,
}

impl Default for SolveParams {
    fn default() -> Self {
        Self {
            max_iterations: 50,
            local_global_per_iteration: LOCAL_GLOBAL_PER_ITERATION,
            tolerance: 1e-6,
            move_tolerance: MOVE_TOLERANCE,
            max_step_degrees: 30.0,
            max_step_fraction: 0.25,
            refine_strain: None,
            refine_fraction: None,
            coarsen_levels: 0,
            refine_levels: 2,
            max_refinements: 4,
            coarse_levels: None,
            method: Method::Auto,
            newton: true,
            newton_at_start: false,
            carry_loose: true,
            subdomains: 0,
            workers: None,
            soft_inside: None,
        }
    }
}

/// Refinement stops before the complex grows past this many times the cells it started from
/// (without a bound, a tiny `--refine-strain` splits every cell, round after round, for
/// minutes).
pub const REFINE_GROWTH: usize = 8;

/// What [`super::solve`] did.
#[derive(Debug, Clone, Default, PartialEq)]
#[non_exhaustive]
pub struct SolverInfo {
    /// Accepted iterations (Gauss-Newton and local-global) over all load steps and refinements.
    pub iterations: usize,
    /// Load steps.
    pub load_steps: usize,
    /// The energy at the start of every load step (and coarse-to-fine stage, and refinement
    /// round) and after every accepted iteration. A coarse stage's energy is that of its own
    /// cells: it falls by a stage's refinement, not only by iterations.
    pub energies: Vec<f64>,
    /// Where each load step (and stage, and refinement round) starts in `energies`. Within a
    /// step the energy never increases; between steps it jumps as the handles move on.
    pub step_starts: Vec<usize>,
    /// Iterations in each load step, then in each finer stage of a solve coarse to fine
    /// ([`SolveParams::coarse_levels`]; the load steps are those of the coarsest cells), then
    /// in each refinement round.
    pub iterations_per_step: Vec<usize>,
    /// Cells before refinement (of the complex given, not of a coarse stage).
    pub cells_initial: usize,
    /// Cells after refinement.
    pub cells_final: usize,
    /// Cell counts after each refinement round.
    pub refinements: Vec<usize>,
    /// Why refinement stopped before every cell over the threshold was split, if it did (the
    /// bound it hit).
    pub refinement_stopped: Option<Said>,
    /// The turn the inside's default soft stiffness gave way under, where the solve started
    /// over with a solid inside ([`SolveParams::soft_inside`]), and that scale.
    pub inside_stiffened: Option<(TurnRefusal, f64)>,
    /// Unknowns of the last system.
    pub unknowns: usize,
    /// Seconds spent in symbolic analysis.
    pub seconds_symbolic: f64,
    /// Seconds spent assembling, factoring and solving the normal equations.
    pub seconds_factor: f64,
    /// Every accepted iteration, in order (those of a load step taken again in halves are
    /// dropped, as from `energies`).
    pub log: Vec<IterationLog>,
    /// Seconds in total.
    pub seconds: f64,
    /// Whether the last load step stopped on the tolerance (not on the iteration limit).
    pub converged: bool,
    /// Conjugate-gradient iterations over all Gauss-Newton steps (multilevel path; 0 when every
    /// system was factored directly).
    pub linear_iterations: usize,
    /// Levels of the last multilevel hierarchy (0: the direct path).
    pub levels: usize,
    /// Load steps taken again in halves because they left the branch of the load path.
    pub halvings: usize,
    /// Every turning handle's turn, asked and carried by the cells ([`super::turns`]).
    pub turns: Vec<HandleTurn>,
    /// What the solve was estimated to take before it started ([`super::forecast()`]).
    pub estimate: Option<crate::estimate::Estimate>,
    /// The control points' trend ([`super::trend`]; `None` without one).
    pub trend: Option<crate::spec::Trend>,
    /// Whether a load step or stage stopped its local-global iterations where Gauss-Newton
    /// was estimated to finish sooner ([`Method::Auto`]): the steps and stages after it take
    /// Gauss-Newton from their start (a strip that converges slowly on its coarse cells
    /// converges more slowly on its finer ones).
    pub newton_sooner: bool,
    /// What the solve's forecast found of its stages ([`super::forecast::StageFits`]).
    pub(crate) newton_fits: super::forecast::StageFits,
}

impl SolverInfo {
    /// What the user should hear about the solve: refinement that stopped early, and handles
    /// whose turn the cells did not carry.
    pub fn warnings(&self) -> Vec<Said> {
        let turns = self.turns.iter().filter_map(HandleTurn::warning);
        let stiffened = self.inside_stiffened.map(|(r, scale)| {
            // A drag knows that the pose gave way, not where.
            let held = match (r.held_degrees - r.asked_degrees).abs() < 0.5 {
                true => String::new(),
                false => format!("past {} ", crate::human::degrees(r.held_degrees)),
            };
            Said::new()
                .entry("handle", r.handle, r.line)
                .text(format!(
                    " {}s by {}, {held}where the inside at its default stiffness gives way: \
                     solved with a solid inside, as ",
                    r.kind.name(),
                    crate::human::degrees(r.asked_degrees),
                ))
                .set(Opt::InteriorStiffness, 1)
                .text(format!(
                    " does (the default, {scale}, twists a thin neck as a surface does)"
                ))
        });
        self.refinement_stopped
            .iter()
            .cloned()
            .chain(stiffened)
            .chain(turns)
            .collect()
    }

    /// How the last iterations were solved: `direct` or `multilevel` (Gauss-Newton's linear
    /// systems), or `local-global`.
    pub fn linear_solver(&self) -> &'static str {
        match self.log.last().map(|l| l.method) {
            Some(IterationMethod::LocalGlobal | IterationMethod::Anderson) => "local-global",
            _ if self.levels > 0 => "multilevel",
            _ => "direct",
        }
    }

    /// The iterations in words, by kind (`34 local-global iterations`).
    pub fn iterations_in_words(&self) -> String {
        iteration::iterations_in_words(self.iterations, &self.log)
    }

    /// Mean seconds per iteration, of either kind.
    pub fn seconds_per_iteration(&self) -> f64 {
        self.seconds / self.iterations.max(1) as f64
    }
}

/// A solved cell complex.
#[derive(Debug, Clone)]
pub struct Solution<const D: usize> {
    /// The cells (after refinement).
    pub complex: CellComplex<D>,
    /// One rigid motion per cell (local frame).
    pub motions: Vec<Motion<D>>,
    /// The constraints on the final cells.
    pub constraints: Constraints<D>,
    /// What the solver did.
    pub info: SolverInfo,
}

impl<const D: usize> Solution<D> {
    /// The constraint that holds the world point `p` as the field does, if a cell holds it: a
    /// cell held whole holds the points in it (a pin's, a carried part's, a selection's of
    /// samples, a region's beyond its border), else a region with a border
    /// ([`super::Shapes`]) holds the points inside it whatever cell holds them, else
    /// [`Role::Free`].
    pub fn role_at(&self, p: &Vect<D>) -> Option<Role> {
        let c = self.complex.locate(&(p - self.constraints.origin))?;
        let constraints = &self.constraints;
        let role = constraints.roles[c];
        let center = self.complex.cells[c].center + constraints.origin;
        let bordered = constraints
            .shape_of(role)
            .is_some_and(|s| s.contains(&center));
        if role != Role::Free && !bordered {
            return Some(role);
        }
        for role in constraints.region_roles() {
            if constraints.shape_of(role).is_some_and(|s| s.contains(p)) {
                return Some(role);
            }
        }
        Some(Role::Free)
    }
}

/// Refuses parameters no solve can take.
pub(crate) fn check_params(params: &SolveParams) -> Result<()> {
    if params.subdomains > 0 && matches!(params.method, Method::Direct | Method::Multilevel) {
        return Err(Error::param(
            Said::new()
                .set(Opt::Subdomains, params.subdomains)
                .text(" solves by local-global iterations, not by ")
                .set(Opt::Solver, params.method)
                .text(": give one"),
        ));
    }
    if !(params.move_tolerance >= 0.0 && params.move_tolerance.is_finite()) {
        return Err(Error::param(format!(
            "the solver's move tolerance must be a number of cells, 0 or more (got {})",
            params.move_tolerance
        )));
    }
    Ok(())
}

/// Levels an adaptive solve ([`adaptive`]) starts above its smallest cells.
pub const ADAPTIVE_LEVELS: u8 = 3;
/// An adaptive solve splits the cells whose strain exceeds this fraction of the largest.
pub const ADAPTIVE_FRACTION: f64 = 0.25;

/// The parameters of an adaptive solve down to cells of `min_cell_size` (the paper's §5 at
/// scale). The complex is built at `min_cell_size` and the constraints resolved
/// there, so every region ends where it ends on uniform cells of that size; then sibling cells
/// of one role are merged up to [`ADAPTIVE_LEVELS`] times ([`super::coarsen`]: cells along a
/// region's border stay small), the coarse complex is solved, and the cells whose strain
/// exceeds [`ADAPTIVE_FRACTION`] of the round's largest are split, one level a round, and the
/// solve goes on. A local edit in a large scan then costs small cells only where it bends
/// (BENCHMARKS.md). An error for a size that is not positive.
pub fn adaptive(
    min_cell_size: f64,
    build: &crate::cells::BuildParams,
    solve: &SolveParams,
) -> Result<(crate::cells::BuildParams, SolveParams)> {
    crate::cells::check_size(min_cell_size, Some(Opt::MinCellSize))?;
    let build = crate::cells::BuildParams {
        cell_size: Some(min_cell_size),
        target_cells: None,
        ..*build
    };
    let solve = SolveParams {
        coarsen_levels: ADAPTIVE_LEVELS,
        refine_fraction: Some(ADAPTIVE_FRACTION),
        refine_levels: 0,
        max_refinements: ADAPTIVE_LEVELS as usize,
        ..*solve
    };
    Ok((build, solve))
}
