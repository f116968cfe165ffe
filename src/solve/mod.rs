//! Minimizing the glue energy under the user's constraints (paper §4–5).
//!
//! [`solve`] runs load steps: each handle's transform (and each pin's and target's destination)
//! is interpolated from the identity in steps of at most [`SolveParams::max_step_degrees`] of
//! rotation, and each step is solved by Gauss-Newton from the previous step's result. Solved
//! straight from rest, a symmetric edit such as a 180° twist leaves Gauss-Newton at a saddle
//! where the middle never turns; the paper's interactive setting avoids this because handles move
//! a little per frame, and load steps do the same for a batch tool.
//!
//! **Staying on the branch.** A rotation matrix cannot tell a cell turned by 270° from one
//! turned by −90°, so a twist past a half turn has two answers near every load step: the part
//! carrying the turn, and the part untwisted the short way round. Each load step therefore
//! starts from a predictor (`predict`): every free cell turns on by what it turned over the
//! last step, not only the handles, and the free cells' positions are then the optimum for
//! those rotations (on the 10 × 1 × 1 bar twisted 360° and 720°, 22 and 34 iterations instead
//! of 37 and 73; the 480k-vertex tube's bend 12 instead of 11). After each step the solver
//! follows, along chains of cells, the turn the cells carry from the fixed cells to each
//! turning handle ([`turns`]: their rotations lifted along the chain, exact for bends that are
//! not planar too); a step that leaves that turn a quarter turn off the handle's, or ends a
//! cell a quarter turn from its prediction, is taken again in halves, down to a sixteenth of a
//! step (about 2°). A turn that still gives way there is refused ([`Error::TurnNotHeld`], exit
//! 4) rather than returned untwisted; a large complex's coarse cells refuse it before the
//! cells themselves are solved where the turn asked is far past what they held (the `coarse`
//! module).
//!
//! **Half turns.** A bend by a half turn has two answers too: the part bent one way round or
//! the other, both reaching the handle's pose. Written as `rotate`, the sign says which; a
//! `matrix` cannot say ([`crate::spec::HandleMotion::undirected`]). Its axis comes from the
//! matrix's symmetric part (the antisymmetric part, `2 sin θ` times the axis, is rounding
//! there: a half turn rounded to single precision, as Blender's are, read as 179.99999° about
//! an axis of noise, bent the bar of the tests the wrong way round and gave way at 154°, a
//! bust at 129°), and the solver turns it the way the handle moves, seen from the fixed cells
//! (`Constraints::directed`), and where the shape gives way that way, the other way round
//! (`from_rest_either_way`). Both are needed: the bar bent into a U gives way at 167° bent the
//! other way, and the dragon's head bent about its neck gives way at 163° turned the way it
//! moves (its pivot lies almost on the line from the fixed cells to the head, so that rule
//! hardly decides there), where the other way holds.
//!
//! It gives way on short, thick parts, because the glue energy has no twisted minimum there:
//! like as-rigid-as-possible energies it charges a bounded amount for collapsing a
//! cross-section, and a collapsed neck untwists for free. Measured by `tools/src/bin/twist.rs`
//! on closed cylinders of diameter 1 with their end tenths fixed and turned by 720°: the turn
//! gives way past 189° when the turned span is 0.8 diameters long, 315° at 1.8, 510° at 2.8 and
//! 718° at 4.8, and holds 720° at 7.8 — some 130° to 200° more per diameter of length — and on
//! the span of 0.8 at 180°–195° for every cell size from 0.3 to 0.05 (solved to convergence in
//! steps of 2°, 160°–190° down to cells of 0.02). No cell size holds a whole turn of a part as
//! short as it is wide (a bust's neck, a bunny or a dragon twisted about its middle give way
//! at 189°–191°), and no barrier between face neighbors changes that (BENCHMARKS.md §13).
//! Turning in several runs, each deforming the last output, does carry the turn (the rest shape
//! then holds the turn so far).
//!
//! **Newton's curvature.** The glue energy is not a small-residual problem once a shape is
//! bent: the pairs' residuals stay large at the minimum, and Gauss-Newton, which leaves out
//! their second-order term, converges only linearly (the 480k-vertex tube bent by 90°: 9, 17
//! and 16 iterations for its three load steps, the last ones each lowering the energy by 1e-5
//! of it). From a load step's second iteration on, each free cell's rotation block therefore
//! also gets `Σ a · ∂²(r · R(ω) y)/∂ω²` over its quadrature points (`r` the residual, `y` the
//! rotated arm; `System::step`), which makes the iteration Newton's on the rotations and
//! quadratically convergent. Where that matrix is indefinite (far from the minimum) its
//! factorization fails and the step falls back to the term's positive part per cell, which
//! keeps the matrix positive definite (the multilevel path, whose conjugate gradients then
//! fail, falls back to plain Gauss-Newton). The first iteration of each load step, which starts
//! where the handles jumped, uses the positive part too. A load step before the last only
//! has to bring the motions near the path's minimum (so that the next starts on the right
//! side of a saddle): it stops at `INTERMEDIATE_TOLERANCE` or after
//! `INTERMEDIATE_ITERATIONS`. On the tube: 42 iterations and 5.6 s became 11 iterations and
//! 1.8 s, to a slightly lower energy (BENCHMARKS.md). Each step factors its own matrix: an
//! older step's factor as a preconditioner is no faster (BENCHMARKS.md §13).
//!
//! Every Gauss-Newton step is followed by a line search along the step (halving from the full
//! step, or doubling up to 8× while a full step keeps lowering the energy), and every trial has
//! its free positions replaced by their optimum for its rotations (variable projection, see
//! `positions`). The energy never increases across accepted iterations; a step that cannot
//! decrease the energy ends the load step. With `refine_strain`, cells whose strain exceeds the threshold are split after the last
//! load step (children inherit motion and constraint) and the solve continues.
//!
//! [`minimize_local_global`] minimizes the same energy by local-global iterations on one constant
//! matrix (the `local_global` module); `solve` does not use it yet (BENCHMARKS.md: where it wins).

mod auto;
mod blocks;
mod coarse;
pub mod constraints;
pub mod energy;
mod forecast;
mod iteration;
mod local_global;
mod multilevel;
mod positions;
mod selections;
mod session;
mod sight;
mod steps;
mod system;
pub mod trend;
pub mod turns;

use std::time::Instant;

pub use coarse::{COARSE_FROM, COARSE_STAGE, MAX_COARSE_LEVELS};
pub use constraints::{
    Constraints, LooseParts, Role, carry_loose, coarsen, inherit, resolve, resolve_selected,
    sample_cell, seen,
};
pub use energy::{cell_strain, glue_energy, pair_energy};
pub use forecast::forecast;
use iteration::largest_corner_move;
pub use iteration::{IterationLog, IterationMethod, MOVE_TOLERANCE};
pub use local_global::{
    LOCAL_GLOBAL_PER_ITERATION, LocalGlobalInfo, LocalGlobalParams, minimize_local_global,
};
pub use selections::Selections;
pub use session::{
    DRAG_COARSE_FROM, DRAG_FACTOR_MOST, DRAG_LOCAL_GLOBAL, IDLE_LOCAL_GLOBAL, Session,
};
pub use sight::Sight;

use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::{Dim, Motion, Rigid, Vect};
pub use steps::MAX_TRAVEL;
use steps::{load_steps, predict, prescribe, targets_at};
use system::System;
use turns::TurnGauge;
pub use turns::{HandleTurn, TurnKind, TurnRefusal};

/// Parameters of [`solve`].
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
    /// times ([`coarsen`]). Default 0. See [`adaptive`].
    pub coarsen_levels: u8,
    /// Levels refinement may add below the finest static level. Default 2.
    pub refine_levels: u8,
    /// Rounds of refinement at most. Default 4.
    pub max_refinements: usize,
    /// Coarse stages before the cells themselves are solved (the `coarse` module): 0 solves
    /// them from rest; `None` (default): as many as the cells call for (none below
    /// [`COARSE_FROM`] cells).
    pub coarse_levels: Option<u8>,
    /// How each Gauss-Newton system is solved, or local-global iterations instead. Default
    /// [`Method::Auto`].
    pub method: Method,
    /// Parts of the shape without any constraint ride along rigidly with the nearest cell of
    /// a constrained part ([`carry_loose`]); `false` keeps them at rest. Default `true`.
    pub carry_loose: bool,
    /// After a load step's first iteration, add the rotations' second-order term to the
    /// Gauss-Newton matrix (Newton's method; see the module docs). Default `true`.
    pub newton: bool,
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
            carry_loose: true,
        }
    }
}

/// Refinement stops before the complex grows past this many times the cells it started from
/// (without a bound, a tiny `--refine-strain` splits every cell, round after round, for
/// minutes).
pub const REFINE_GROWTH: usize = 8;

/// What [`solve`] did.
#[derive(Debug, Clone, Default, PartialEq)]
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
    pub refinement_stopped: Option<String>,
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
    /// Every turning handle's turn, asked and carried by the cells ([`turns`]).
    pub turns: Vec<HandleTurn>,
    /// What the solve was estimated to take before it started ([`forecast()`]).
    pub estimate: Option<crate::estimate::Estimate>,
    /// The control points' trend ([`trend`]; `None` without one).
    pub trend: Option<crate::spec::Trend>,
    /// Whether a load step or stage stopped its local-global iterations where Gauss-Newton
    /// was estimated to finish sooner ([`Method::Auto`]): the steps and stages after it take
    /// Gauss-Newton from their start (a strip that converges slowly on its coarse cells
    /// converges more slowly on its finer ones).
    pub newton_sooner: bool,
}

impl SolverInfo {
    /// What the user should hear about the solve: refinement that stopped early, and handles
    /// whose turn the cells did not carry.
    pub fn warnings(&self) -> Vec<String> {
        let turns = self.turns.iter().filter_map(HandleTurn::warning);
        self.refinement_stopped
            .iter()
            .cloned()
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
    /// The role of the cell holding the world point `p`, if a cell holds it.
    pub fn role_at(&self, p: &Vect<D>) -> Option<Role> {
        let c = self.complex.locate(&(p - self.constraints.origin))?;
        Some(self.constraints.roles[c])
    }
}

/// Solves for the rigid motions of `complex` under `constraints`, with load steps and optional
/// refinement, within the memory `budget`.
pub fn solve<const D: usize>(
    complex: CellComplex<D>,
    constraints: Constraints<D>,
    params: &SolveParams,
    budget: Budget,
    observer: &dyn Observer,
) -> Result<Solution<D>>
where
    Dim<D>: Rigid<D>,
{
    let start = Instant::now();
    let (mut complex, mut constraints) = match params.coarsen_levels {
        0 => (complex, constraints),
        levels => coarsen(&complex, &constraints, levels),
    };
    let estimate = forecast::announce(&complex, &constraints, params, budget, observer)?;
    let (mut system, mut motions, mut info) =
        from_rest_either_way(&complex, &mut constraints, params, budget, observer)?;
    info.estimate = Some(estimate);
    info.trend = (!constraints.trend.is_identity()).then_some(constraints.trend_kind);
    if params.refine_strain.is_some() || params.refine_fraction.is_some() {
        let limit = complex.grid.max_level + params.refine_levels;
        observer.stage("refining", params.max_refinements as u64);
        for _ in 0..params.max_refinements {
            observer.advance(1);
            let strain = cell_strain(&complex, &motions);
            let tau = params.refine_strain.unwrap_or_else(|| {
                let largest = strain.iter().cloned().fold(0.0, f64::max);
                // A complex with no strain anywhere (a rigid edit) needs no cell split.
                params.refine_fraction.unwrap_or(1.0) * largest.max(f64::MIN_POSITIVE)
            });
            let split: Vec<bool> = complex
                .cells
                .iter()
                .zip(&strain)
                .map(|(c, &s)| s > tau && c.key.level < limit)
                .collect();
            if !split.iter().any(|&s| s) {
                break;
            }
            let more = split.iter().filter(|&&s| s).count() * ((1 << D) - 1);
            if complex.len() + more > REFINE_GROWTH * info.cells_initial.max(1) {
                info.refinement_stopped = Some(format!(
                    "refinement stopped at {} cells: splitting on would pass {REFINE_GROWTH}× \
                     the {} cells it started from; raise --refine-strain or use a smaller \
                     --cell-size",
                    complex.len(),
                    info.cells_initial
                ));
                break;
            }
            check_solver_memory(complex.len() + more, params.method, budget, REFINE_ADVICE)?;
            let (fine, parent) = complex.split(&split);
            motions = fine
                .cells
                .iter()
                .zip(&parent)
                .map(|(cell, &p)| {
                    let old = &complex.cells[p as usize];
                    let m = &motions[p as usize];
                    Motion {
                        rot: m.rot,
                        pos: m.apply(&old.center, &cell.center),
                    }
                })
                .collect();
            constraints = inherit(&constraints, &fine, &parent);
            complex = fine;
            info.refinements.push(complex.len());
            system = timed(&mut info.seconds_symbolic, || {
                System::new(&complex, &constraints, params.method, budget, REFINE_ADVICE)
            })?;
            let it = minimize_with(
                &mut system,
                &complex,
                &constraints,
                &mut motions,
                1.0,
                params,
                &mut info,
                observer,
            )?;
            info.iterations_per_step.push(it);
        }
    }
    observer.finish();
    info.turns = TurnGauge::new(&complex).turns(&complex, &constraints, &motions);
    if params.carry_loose {
        carry_loose(&complex, &mut constraints, &mut motions);
    }
    info.cells_final = complex.len();
    info.unknowns = system.unknowns();
    info.seconds = start.elapsed().as_secs_f64();
    Ok(Solution {
        complex,
        motions,
        constraints,
        info,
    })
}

/// Refuses parameters no solve can take.
fn check_params(params: &SolveParams) -> Result<()> {
    if !(params.move_tolerance >= 0.0 && params.move_tolerance.is_finite()) {
        return Err(Error::Param(format!(
            "the solver's move tolerance must be a number of cells, 0 or more (got {})",
            params.move_tolerance
        )));
    }
    Ok(())
}

/// [`from_rest`], and where the shape gives way under a half turn that its matrix leaves
/// undirected ([`crate::spec::HandleMotion::undirected`]), the same solve with that handle
/// turned the other way round (which reaches the same pose): the turn `constraints` end with
/// is the one solved. The first way's refusal on coarse cells is final, so that the other way
/// is tried at once: the dragon's head bent by a half turn about its neck gives way at 163°
/// one way round and holds the other, solved in 3 s instead of 12 s when the cells
/// themselves had to give way first.
#[allow(clippy::type_complexity)]
fn from_rest_either_way<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &mut Constraints<D>,
    params: &SolveParams,
    budget: Budget,
    observer: &dyn Observer,
) -> Result<(System<D>, Vec<Motion<D>>, SolverInfo)>
where
    Dim<D>: Rigid<D>,
{
    // The handles still to be tried the other way round: their coarse stages' refusals are
    // final (the other way round may hold where this one gives way).
    let mut either_way: Vec<bool> = constraints
        .handles
        .iter()
        .map(|h| h.motion.undirected())
        .collect();
    loop {
        match from_rest(complex, constraints, params, budget, observer, &either_way) {
            Err(Error::TurnNotHeld(r)) if either_way[r.handle] => {
                either_way[r.handle] = false;
                let h = &mut constraints.handles[r.handle];
                h.motion = h.motion.the_other_way();
            }
            done => return done,
        }
    }
}

/// The solve from rest through its load steps: the sparse system, the motions and what was
/// done so far. A coarse stage's refusal of the turn of a handle marked in `either_way` is
/// final ([`coarse::coarse_to_fine`]).
#[allow(clippy::type_complexity)]
fn from_rest<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    params: &SolveParams,
    budget: Budget,
    observer: &dyn Observer,
    either_way: &[bool],
) -> Result<(System<D>, Vec<Motion<D>>, SolverInfo)>
where
    Dim<D>: Rigid<D>,
{
    check_params(params)?;
    let steps = load_steps(complex, constraints, params)?;
    check_solver_memory(complex.len(), params.method, budget, CELLS_ADVICE)?;
    let levels = coarse::levels(complex.len(), params);
    if levels > 0
        && let Some(staged) = coarse::coarse_to_fine(
            complex,
            constraints,
            levels,
            params,
            budget,
            observer,
            either_way,
        )?
    {
        return Ok(staged);
    }
    let mut info = SolverInfo {
        cells_initial: complex.len(),
        load_steps: steps,
        ..Default::default()
    };
    let mut motions: Vec<Motion<D>> = complex
        .cells
        .iter()
        .map(|c| Motion::rest(&c.center))
        .collect();
    let mut system = timed(&mut info.seconds_symbolic, || {
        System::new(complex, constraints, params.method, budget, CELLS_ADVICE)
    })?;
    load_stepped(
        &mut system,
        complex,
        constraints,
        &mut motions,
        params,
        &mut info,
        observer,
    )?;
    Ok((system, motions, info))
}

/// The load steps `1/steps, 2/steps, …, 1` of `info.load_steps`, each minimized from the
/// last, on the branch the path is on (see the module docs): each step starts from the
/// [`predict`]ed motions, and a step that leaves the branch is taken again in halves, at most
/// [`MAX_HALVINGS`] times in a row. A turn that still gives way at the smallest step is
/// [`Error::TurnNotHeld`].
fn load_stepped<const D: usize>(
    system: &mut System<D>,
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    motions: &mut [Motion<D>],
    params: &SolveParams,
    info: &mut SolverInfo,
    observer: &dyn Observer,
) -> Result<()>
where
    Dim<D>: Rigid<D>,
{
    let steps = info.load_steps as u64;
    observer.stage("solving", steps);
    // Fractions are counted in the smallest step's units, so that the unhalved steps are
    // exactly `k / steps`.
    let total = steps << MAX_HALVINGS;
    let gauge = TurnGauge::new(complex);
    let turning: Vec<usize> = turns::turning(constraints).collect();
    let (mut at, mut halvings, mut accepted, mut reported) = (0u64, 0u32, 0usize, 0u64);
    let mut previous: Option<(f64, Vec<Motion<D>>)> = None;
    while at < total {
        let to_units = (at + (1 << (MAX_HALVINGS - halvings))).min(total);
        let (f, to) = (at as f64 / total as f64, to_units as f64 / total as f64);
        let start = motions.to_vec();
        if let Some((f0, before)) = &previous {
            predict(constraints, motions, before, (to - f) / (f - f0));
            // The free cells' positions are the optimum for the predicted rotations.
            prescribe(complex, constraints, motions, to);
            system.project_positions(complex, constraints, motions, &targets_at(constraints, to));
        }
        let predicted = (!turning.is_empty()).then(|| motions.to_vec());
        // A step before the last only has to bring the motions near the path's minimum, so
        // that the next step starts on the right side of any saddle: it stops at a looser
        // tolerance (on the 480k-vertex tube bend, the three steps took 9, 17 and 16
        // iterations at 1e-6, the last ones each lowering the energy by 1e-5 of it).
        let last = to_units == total;
        let step_params = SolveParams {
            tolerance: if last {
                params.tolerance
            } else {
                params.tolerance.max(INTERMEDIATE_TOLERANCE)
            },
            max_iterations: if last {
                params.max_iterations
            } else {
                params.max_iterations.min(INTERMEDIATE_ITERATIONS)
            },
            ..*params
        };
        let marks = (info.energies.len(), info.step_starts.len(), info.log.len());
        let it = minimize_with(
            system,
            complex,
            constraints,
            motions,
            to,
            &step_params,
            info,
            observer,
        )?;
        let lost = turning.iter().find_map(|&k| {
            let taken = gauge.taken(constraints, motions, k)?;
            let asked = constraints.handles[k].motion.turn.1;
            ((taken - to * asked).abs() > BRANCH_JUMP).then_some((k, f))
        });
        let jumped = predicted.as_ref().is_some_and(|p| {
            constraints.roles.iter().enumerate().any(|(c, role)| {
                matches!(role, Role::Free | Role::Pin(_))
                    && <Dim<D> as Rigid<D>>::angle(&(motions[c].rot * p[c].rot.transpose()))
                        > BRANCH_JUMP
            })
        });
        if (lost.is_some() || jumped) && halvings < MAX_HALVINGS {
            motions.copy_from_slice(&start);
            info.energies.truncate(marks.0);
            info.step_starts.truncate(marks.1);
            info.log.truncate(marks.2);
            info.halvings += 1;
            halvings += 1;
            continue;
        }
        if let Some((k, held)) = lost {
            let refusal = TurnRefusal::new(complex, constraints, k, held);
            return Err(Error::TurnNotHeld(refusal));
        }
        info.iterations_per_step.push(it);
        accepted += 1;
        previous = Some((f, start));
        at = to_units;
        // Back to longer steps once the path is past the place that needed short ones.
        if halvings > 0 && at % (1 << (MAX_HALVINGS - halvings + 1)) == 0 {
            halvings -= 1;
        }
        let done = at * steps / total;
        observer.advance(done - reported);
        reported = done;
    }
    info.load_steps = accepted;
    Ok(())
}

/// Load steps are taken again in halves at most this many times in a row (a 30° step down to
/// about 2°).
const MAX_HALVINGS: u32 = 4;

/// A load step has left its branch when the turn the cells carry to a handle is off the
/// handle's by more than this, or a cell ends more than this away from its predicted rotation
/// (a quarter turn, in radians).
const BRANCH_JUMP: f64 = std::f64::consts::FRAC_PI_2;

/// Levels an adaptive solve ([`adaptive`]) starts above its smallest cells.
pub const ADAPTIVE_LEVELS: u8 = 3;
/// An adaptive solve splits the cells whose strain exceeds this fraction of the largest.
pub const ADAPTIVE_FRACTION: f64 = 0.25;

/// The parameters of an adaptive solve down to cells of `min_cell_size` (the paper's §5 at
/// scale). The complex is built at `min_cell_size` and the constraints resolved
/// there, so every region ends where it ends on uniform cells of that size; then sibling cells
/// of one role are merged up to [`ADAPTIVE_LEVELS`] times ([`coarsen`]: cells along a
/// region's border stay small), the coarse complex is solved, and the cells whose strain
/// exceeds [`ADAPTIVE_FRACTION`] of the round's largest are split, one level a round, and the
/// solve goes on. A local edit in a large scan then costs small cells only where it bends
/// (BENCHMARKS.md). An error for a size that is not positive.
pub fn adaptive(
    min_cell_size: f64,
    build: &crate::cells::BuildParams,
    solve: &SolveParams,
) -> Result<(crate::cells::BuildParams, SolveParams)> {
    crate::cells::check_size(min_cell_size, "minimum cell size")?;
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

/// The tolerance of the load steps before the last.
const INTERMEDIATE_TOLERANCE: f64 = 1e-3;
/// Iterations at most of a load step before the last.
const INTERMEDIATE_ITERATIONS: usize = 3;

/// Runs Gauss-Newton at load fraction `f` from the given `motions` (prescribed cells are set to
/// their prescribed motions first). Returns the accepted iterations. This is the whole solver
/// without load steps: the robustness tests start it from collapsed, randomly rotated cells.
pub fn minimize<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    motions: &mut [Motion<D>],
    f: f64,
    params: &SolveParams,
    info: &mut SolverInfo,
) -> Result<usize>
where
    Dim<D>: Rigid<D>,
{
    let mut system = timed(&mut info.seconds_symbolic, || {
        System::new(
            complex,
            constraints,
            params.method,
            Budget::default(),
            CELLS_ADVICE,
        )
    })?;
    minimize_with(
        &mut system,
        complex,
        constraints,
        motions,
        f,
        params,
        info,
        &crate::progress::Silent,
    )
}

/// Runs Gauss-Newton on `complex` under `constraints` at full load from `motions` (no load
/// steps, no refinement) and returns the motions it ends at: a warm start for a small change of
/// the constraints (the leave-one-out check of [`crate::control`]).
pub fn minimize_from<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    motions: &[Motion<D>],
    params: &SolveParams,
    budget: Budget,
) -> Result<Vec<Motion<D>>>
where
    Dim<D>: Rigid<D>,
{
    let mut system = System::new(complex, constraints, params.method, budget, CELLS_ADVICE)?;
    let mut motions = motions.to_vec();
    let mut info = SolverInfo::default();
    minimize_with(
        &mut system,
        complex,
        constraints,
        &mut motions,
        1.0,
        params,
        &mut info,
        &crate::progress::Silent,
    )?;
    Ok(motions)
}

/// The total energy: glue plus soft targets.
pub fn total_energy<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    motions: &[Motion<D>],
    targets_to: &[Vect<D>],
) -> f64 {
    let glue = glue_energy(complex, motions, &constraints.stiffness);
    let soft: f64 = constraints
        .targets
        .iter()
        .zip(targets_to)
        .map(|(t, to)| {
            let c = t.cell as usize;
            let r = motions[c].apply(&complex.cells[c].center, &t.from) - to;
            t.weight * r.component_mul(&t.mask).norm_squared()
        })
        .sum();
    glue + soft
}

#[allow(clippy::too_many_arguments)]
fn minimize_with<const D: usize>(
    system: &mut System<D>,
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    motions: &mut [Motion<D>],
    f: f64,
    params: &SolveParams,
    info: &mut SolverInfo,
    observer: &dyn Observer,
) -> Result<usize>
where
    Dim<D>: Rigid<D>,
{
    prescribe(complex, constraints, motions, f);
    let pins_to: Vec<Vect<D>> = constraints
        .pins
        .iter()
        .map(|p| p.point + (p.to - p.point) * f)
        .collect();
    for (c, role) in constraints.roles.iter().enumerate() {
        if let Role::Pin(k) = role {
            let pin = &constraints.pins[*k as usize];
            motions[c].pos =
                motions[c].rot * (complex.cells[c].center - pin.point) + pins_to[*k as usize];
        }
    }
    let targets_to = targets_at(constraints, f);
    let mut energy = total_energy(complex, constraints, motions, &targets_to);
    info.step_starts.push(info.energies.len());
    info.energies.push(energy);
    if system.unknowns() == 0 {
        info.converged = true;
        return Ok(0);
    }
    // The energy of every pair being off by 1e-12 of a cell: rigid to rounding.
    let size = complex.grid.finest_size();
    let floor = (1e-12 * size).powi(2) * complex.pairs.iter().map(|p| p.weight).sum::<f64>();
    let to = local_global::Destinations {
        pins: &pins_to,
        targets: &targets_to,
    };
    let state = (&mut *motions, energy, floor);
    let local_global = match system::first(
        system,
        complex,
        constraints,
        state,
        &to,
        params,
        info,
        observer,
    )? {
        (it, None) => return Ok(it),
        (it, Some(e)) => {
            energy = e;
            it
        }
    };
    let mut iterations = 0;
    // Whether the last step lowered the energy by less than half: the multilevel path may
    // keep its hierarchy (coarse levels built at motions that have hardly moved since).
    let mut settled = false;
    info.converged = false;
    while iterations < params.max_iterations {
        if energy <= floor {
            info.converged = true;
            break;
        }
        let t0 = Instant::now();
        // Newton's curvature once Gauss-Newton has brought the load step near its minimum.
        let newton = params.newton && iterations > 0;
        let (delta, cost) =
            system.step(complex, constraints, motions, &targets_to, newton, settled)?;
        info.seconds_factor += t0.elapsed().as_secs_f64();
        let mut linear_iterations = 0;
        if let Some((linear, levels)) = system.multilevel_stats() {
            info.linear_iterations += linear;
            info.levels = levels;
            linear_iterations = linear;
        }
        let searching = Instant::now();
        // One trial: the step scaled by `t`, positions projected, and its energy.
        let trial = |t: f64| {
            let mut m = system.advance(complex, constraints, motions, &pins_to, &delta, t);
            system.project_positions(complex, constraints, &mut m, &targets_to);
            let e = total_energy(complex, constraints, &m, &targets_to);
            (m, e)
        };
        let mut t = 1.0;
        let mut accepted = None;
        for _ in 0..30 {
            let (m, e) = trial(t);
            if !e.is_finite() {
                return Err(Error::Solver("the energy became non-finite".into()));
            }
            if e < energy {
                accepted = Some((m, e));
                break;
            }
            t *= 0.5;
        }
        // A full step that lowers the energy may be too short (a slowly drifting vortex in
        // 2D): extrapolate while the energy keeps falling.
        if t == 1.0 {
            while let Some((_, best)) = &accepted
                && t < 8.0
            {
                let (m, e) = trial(2.0 * t);
                if e >= *best || e.is_nan() {
                    break;
                }
                t *= 2.0;
                accepted = Some((m, e));
            }
        }
        let Some((trial, e)) = accepted else {
            // No step lowers the energy: a minimum to machine precision.
            info.converged = true;
            break;
        };
        let largest_move = largest_corner_move(complex, motions, &trial) / size;
        motions.copy_from_slice(&trial);
        let decrease = energy - e;
        settled = 2.0 * decrease < energy;
        let before = energy;
        energy = e;
        iterations += 1;
        info.iterations += 1;
        info.energies.push(energy);
        let log = IterationLog {
            method: match newton {
                true => IterationMethod::Newton,
                false => IterationMethod::GaussNewton,
            },
            load_step: info.step_starts.len() - 1,
            cells: complex.len(),
            energy,
            decrease: decrease / before,
            largest_move,
            step_length: t,
            linear_iterations,
            seconds_assembly: cost.assembly,
            seconds_setup: cost.setup,
            seconds_linear: cost.linear,
            seconds_line_search: searching.elapsed().as_secs_f64(),
        };
        let previous = (iterations > 1).then(|| info.log.last().copied()).flatten();
        info.log.push(log);
        observer.message(&format!("iteration {iterations}: {log}"));
        crate::progress::stop_if_cancelled(observer)?;
        // A short step's small move says only that the line search shortened it.
        if decrease <= params.tolerance * before
            || (t >= 1.0 && largest_move <= params.move_tolerance)
            || previous.is_some_and(|p| {
                iteration::newton_converged(&p, &log, params.tolerance, params.move_tolerance)
            })
        {
            info.converged = true;
            break;
        }
    }
    Ok(local_global + iterations)
}

/// What to change when the cells do not fit the memory budget.
const CELLS_ADVICE: &str = "use a larger --cell-size (or fewer --cells)";
/// What to change when refined cells would not fit it.
const REFINE_ADVICE: &str = "use a larger --refine-strain threshold";

/// The solver's estimate for `cells` cells by `method`, checked against `budget`.
fn check_solver_memory(cells: usize, method: Method, budget: Budget, advice: &str) -> Result<()> {
    let (per_cell, by) = match method {
        Method::Multilevel => (
            crate::memory::MULTILEVEL_BYTES_PER_CELL,
            " by the multilevel solver",
        ),
        _ => (crate::memory::SOLVER_BYTES_PER_CELL, ""),
    };
    budget.check(
        &format!("solving {cells} cells{by}"),
        cells as f64 * per_cell as f64,
        advice,
    )
}

fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let r = f();
    *acc += t.elapsed().as_secs_f64();
    r
}
