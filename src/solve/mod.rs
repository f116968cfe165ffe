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
//! step (about 2°). A step that will be taken again stops as soon as it leaves the branch
//! (checked after every Gauss-Newton iteration and every eighth local-global one), instead of
//! iterating on while the part untwists: a 2 × 1 × 1 bar twisted 247° at its default cells,
//! a little past where it gives way, is refused in 12.5 s instead of 33.6 s, at 221° in 19 s
//! instead of 76 s. A turn that still gives way at the smallest step is refused
//! ([`Error::TurnNotHeld`], exit 4) rather than returned untwisted; a large complex's coarse
//! cells refuse it before the cells themselves are solved where the turn asked is far past
//! what they held, and a finer stage that loses a turn its coarse cells carried sends the
//! cells to be solved from rest (the `coarse` module).
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
//! **A soft inside gives way sooner.** The inside's default stiffness is a twentieth of the
//! surface's ([`crate::DEFAULT_INTERIOR_STIFFNESS`]: a turned head twists a neck as a surface
//! does), and the inside is also what keeps a twisted part's section from folding in: the
//! 10 × 1 × 1 bar in cells of 0.25 twisted by 720° gives way past about 705° with it, and holds
//! with a solid inside (in cells of 0.125, past 690°; a solid holds from an inside of 0.3 on).
//! Where a turn gives way under the default ([`SolveParams::soft_inside`]), the solve starts
//! over from rest with the inside a solid's and says so ([`SolverInfo::inside_stiffened`]): a
//! step that leaves its branch again at half its length gives the soft inside up at once,
//! since near where it gives way each try takes tens of iterations, and a coarse stage that
//! gives way gives it up at once. The 720° bar then takes 4.9 s instead of 1.0 s, and a turn
//! the solid refuses too is refused after both, up to a second later (BENCHMARKS.md, "Half
//! turns, and refusing early"). A session's drag that loses a turn stiffens its inside the same
//! way (`Session`), and takes the pose again from the last pose whose turn its cells held. An
//! inside's stiffness other than the default is kept, and a shape with no inside (an open
//! surface, `--shell`) refuses a turn as it always has.
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
//! fail, falls back to plain Gauss-Newton). A Newton step along which the energy rises at once
//! (an indefinite matrix that no solve reported) is taken again with Gauss-Newton's matrix
//! rather than read as a minimum (BENCHMARKS.md §3, "Newton steps that are no descent
//! direction"). The first iteration of each load step, which starts
//! where the handles jumped, uses the positive part alone. Motions near the minimum already
//! take the whole term from the first ([`SolveParams::newton_at_start`]): a session converging
//! its pose in place (its release, an idle refinement), where a first Gauss-Newton step lowered
//! the energy by less than the tolerance 0.07 cells short of the minimum along a twist, and
//! each finer stage of coarse to fine, which starts at its parents' minimum carried down (the
//! `coarse` module). A load step before the last only
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

mod anderson;
mod auto;
mod blocks;
mod coarse;
pub mod constraints;
pub mod energy;
mod forecast;
mod iteration;
pub mod laplacian;
mod local_global;
mod loose;
mod merge;
mod multilevel;
mod newton;
mod params;
mod positions;
pub mod schwarz;
mod selections;
mod session;
mod sight;
mod steps;
mod system;
pub mod trend;
pub mod turns;
mod workers;

use std::time::Instant;

pub use coarse::{COARSE_FROM, COARSE_STAGE, MAX_COARSE_LEVELS};
pub use constraints::{Constraints, Role, Shapes, resolve, resolve_selected, sample_cell};
pub use energy::{cell_strain, glue_energy, pair_energy};
pub use forecast::forecast;
use iteration::largest_corner_move;
pub use iteration::{IterationLog, IterationMethod, MOVE_TOLERANCE};
pub use local_global::{
    LOCAL_GLOBAL_PER_ITERATION, LocalGlobalInfo, LocalGlobalParams, minimize_local_global,
};
pub use loose::{LooseParts, carry_loose};
pub use merge::{coarsen, coarsen_stage, inherit};
pub use selections::Selections;
pub use session::{
    DRAG_COARSE_FROM, DRAG_FACTOR_MOST, DRAG_LOCAL_GLOBAL, IDLE_LOCAL_GLOBAL, Session,
};
pub use sight::{Sight, seen};

use crate::cells::{CellComplex, CellKind};
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::{Dim, Motion, Rigid};
use crate::said::{Opt, Said};
use newton::{
    cells_advice, check_solver_memory, minimize_watched, minimize_with, refine_advice, timed,
};
pub use newton::{minimize, minimize_from, total_energy};
pub(crate) use params::check_params;
pub use params::{
    ADAPTIVE_FRACTION, ADAPTIVE_LEVELS, Method, REFINE_GROWTH, Solution, SolveParams, SolverInfo,
    adaptive,
};
pub use steps::MAX_TRAVEL;
use steps::{load_steps, predict, prescribe, targets_at};
use system::System;
use turns::TurnGauge;
pub use turns::{HandleTurn, TurnKind, TurnRefusal};

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
    let (estimate, fits) = forecast::announce(&complex, &constraints, params, budget, observer)?;
    let (mut system, mut motions, mut info) =
        from_rest_either_way(&complex, &mut constraints, params, budget, observer, &fits)?;
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
                info.refinement_stopped = Some(
                    Said::from(format!(
                        "refinement stopped at {} cells: splitting on would pass \
                         {REFINE_GROWTH}× the {} cells it started from; raise ",
                        complex.len(),
                        info.cells_initial
                    ))
                    .opt(Opt::RefineStrain)
                    .text(" or use a smaller ")
                    .opt(Opt::CellSize),
                );
                break;
            }
            check_solver_memory(
                complex.len() + more,
                params.method,
                budget,
                &refine_advice(),
            )?;
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
                System::new(&complex, &constraints, params, budget, &refine_advice())
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

/// [`from_rest`], and where the shape gives way under a half turn that its matrix leaves
/// undirected ([`crate::spec::HandleMotion::undirected`]), the same solve with that handle
/// turned the other way round (which reaches the same pose): the turn `constraints` end with
/// is the one solved. The first way's refusal on coarse cells is final, so that the other way
/// is tried at once: the dragon's head bent by a half turn about its neck gives way at 163°
/// one way round and holds the other, solved in 3 s instead of 12 s when the cells
/// themselves had to give way first. `fits`: what a forecast found of the stages, or none.
#[allow(clippy::type_complexity)]
fn from_rest_either_way<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &mut Constraints<D>,
    params: &SolveParams,
    budget: Budget,
    observer: &dyn Observer,
    fits: &[(usize, bool)],
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
    let mut params = *params;
    if !complex.cells.iter().any(|c| c.kind == CellKind::Interior) {
        // No inside to stiffen: a turn that gives way is refused as it always is.
        params.soft_inside = None;
    }
    let mut stiffened = None;
    loop {
        match from_rest(
            complex,
            constraints,
            &params,
            budget,
            observer,
            (&either_way, fits),
        ) {
            // A soft inside by default gives way: the solid's may hold the turn (tried before
            // the other way round, which is then tried with the solid inside too).
            Err(Error::TurnNotHeld(r)) if params.soft_inside.is_some() => {
                let scale = params.soft_inside.take().expect("soft");
                constraints.scale_interior(complex, 1.0 / scale);
                stiffened = Some((r, scale));
            }
            Err(Error::TurnNotHeld(r)) if either_way[r.handle] => {
                either_way[r.handle] = false;
                let h = &mut constraints.handles[r.handle];
                h.motion = h.motion.the_other_way();
            }
            Ok((system, motions, mut info)) => {
                info.inside_stiffened = stiffened;
                return Ok((system, motions, info));
            }
            failed => return failed,
        }
    }
}

/// The solve from rest through its load steps: the sparse system, the motions and what was
/// done so far. A coarse stage's refusal of the turn of a handle marked in `either_way` is
/// final ([`coarse::coarse_to_fine`]); `fits` is what a forecast found of the stages
/// ([`SolverInfo::newton_fits`]).
#[allow(clippy::type_complexity)]
fn from_rest<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    params: &SolveParams,
    budget: Budget,
    observer: &dyn Observer,
    (either_way, fits): (&[bool], &[(usize, bool)]),
) -> Result<(System<D>, Vec<Motion<D>>, SolverInfo)>
where
    Dim<D>: Rigid<D>,
{
    check_params(params)?;
    let steps = load_steps(complex, constraints, params)?;
    check_solver_memory(complex.len(), params.method, budget, &cells_advice())?;
    let levels = coarse::levels(complex.len(), params);
    if levels > 0
        && let Some(staged) = coarse::coarse_to_fine(
            complex,
            constraints,
            levels,
            params,
            budget,
            observer,
            (either_way, fits),
        )?
    {
        return Ok(staged);
    }
    let mut info = SolverInfo {
        cells_initial: complex.len(),
        load_steps: steps,
        newton_fits: fits.to_vec(),
        ..Default::default()
    };
    let mut motions: Vec<Motion<D>> = complex
        .cells
        .iter()
        .map(|c| Motion::rest(&c.center))
        .collect();
    let mut system = timed(&mut info.seconds_symbolic, || {
        System::new(complex, constraints, params, budget, &cells_advice())
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
            system.project_positions(
                complex,
                constraints,
                motions,
                &targets_at(constraints, to),
            )?;
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
        // The turning handle whose turn the cells no longer carry, if any.
        let lost = |motions: &[Motion<D>]| turns::lost_turn(&gauge, constraints, motions, to);
        // The turning handle whose turn the cells carry farthest from the step's.
        let farthest = |motions: &[Motion<D>]| {
            let off = |k: usize| {
                gauge.taken(constraints, motions, k).map_or(0.0, |taken| {
                    (taken - to * constraints.handles[k].motion.turn.1).abs()
                })
            };
            turning
                .iter()
                .copied()
                .max_by(|&a, &b| off(a).total_cmp(&off(b)))
        };
        // Whether a cell ended far from its predicted rotation. Any cell: a few cells of a thin
        // feature flipping over make the steps near where a part gives way creep at their
        // smallest, but counting only a share of the cells refused sooner in some runs and
        // later in others (BENCHMARKS.md §13, "A few flipping cells").
        let jumped = |motions: &[Motion<D>]| {
            predicted.as_ref().is_some_and(|p| {
                constraints.roles.iter().enumerate().any(|(c, role)| {
                    matches!(role, Role::Free | Role::Pin(_))
                        && <Dim<D> as Rigid<D>>::angle(&(motions[c].rot * p[c].rot.transpose()))
                            > BRANCH_JUMP
                })
            })
        };
        // A step that will be taken again in halves stops as soon as it leaves the branch;
        // the smallest step runs to its end, which decides a refusal.
        let retried = halvings < MAX_HALVINGS;
        let off_branch = |m: &[Motion<D>]| retried && (lost(m).is_some() || jumped(m));
        let it = minimize_watched(
            system,
            (complex, constraints),
            motions,
            to,
            (&step_params, &off_branch),
            info,
            observer,
        )?;
        let (lost, jumped) = (lost(motions).map(|k| (k, f)), jumped(motions));
        // A soft inside by default whose step leaves the branch again at half its length is
        // given up for the solid's at once ([`SolveParams::soft_inside`]), not halved down to
        // its smallest step: near where it gives way each try takes tens of iterations.
        if params.soft_inside.is_some()
            && halvings >= SOFT_HALVINGS
            && let Some(k) = lost
                .map(|l| l.0)
                .or(jumped.then(|| farthest(motions)).flatten())
        {
            let refusal = TurnRefusal::new(complex, constraints, k, f);
            return Err(Error::TurnNotHeld(refusal));
        }
        if (lost.is_some() || jumped) && retried {
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

/// The halvings in a row after which a soft inside by default whose step still leaves its branch
/// is given up for a solid one: a step that leaves its branch once may only have been too long.
const SOFT_HALVINGS: u32 = 1;

/// The tolerance of the load steps before the last.
const INTERMEDIATE_TOLERANCE: f64 = 1e-3;
/// Iterations at most of a load step before the last.
const INTERMEDIATE_ITERATIONS: usize = 3;

/// Load steps are taken again in halves at most this many times in a row (a 30° step down to
/// about 2°).
const MAX_HALVINGS: u32 = 4;

/// A load step has left its branch when the turn the cells carry to a handle is off the
/// handle's by more than this, or a cell ends more than this away from its predicted rotation
/// (a quarter turn, in radians).
const BRANCH_JUMP: f64 = std::f64::consts::FRAC_PI_2;
