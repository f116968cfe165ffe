//! The Newton loop of one load step: Gauss-Newton iterations (Newton's on the rotations from a
//! load step's second iteration), each with its line search, after the local-global iterations
//! that start a step where they win ([`super::auto`]); and the solver's memory check. The load
//! steps around it are [`super::solve`]'s.

use std::time::Instant;

use super::iteration::{self, Ask, largest_corner_move};
use super::local_global::{self, OffBranch};
use super::steps::{prescribe, targets_at};
use super::system::System;
use super::{
    Constraints, IterationLog, IterationMethod, Method, Role, SolveParams, SolverInfo, glue_energy,
    system,
};
use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::{Dim, Motion, Rigid, Vect};
use crate::said::{Opt, Said};

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
            params,
            Budget::default(),
            &cells_advice(),
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
    let mut system = System::new(complex, constraints, params, budget, &cells_advice())?;
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

/// The iterations of one load step at load fraction `f` on `system`, from `motions`: the
/// local-global iterations where they start it, then Gauss-Newton's. Returns the iterations
/// taken.
#[allow(clippy::too_many_arguments)]
pub(super) fn minimize_with<const D: usize>(
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
    let at = (complex, constraints);
    minimize_watched(system, at, motions, f, (params, &|_| false), info, observer)
}

/// [`minimize_with`], stopped early where `off_branch` says the iterate left its load path's
/// branch (checked after every Gauss-Newton iteration and every few local-global ones): the
/// load steps then take the step again in halves, and the iterations that would carry the
/// part over to the other branch — on a short bar twisted past what it holds, 39 of them at
/// 0.4 s each — are not spent. What the system keeps only from one iteration to the next is
/// freed at the end ([`System::release_spare`]): a session holds its system between poses.
pub(super) fn minimize_watched<const D: usize>(
    system: &mut System<D>,
    at: (&CellComplex<D>, &Constraints<D>),
    motions: &mut [Motion<D>],
    f: f64,
    watch: (&SolveParams, OffBranch<D>),
    info: &mut SolverInfo,
    observer: &dyn Observer,
) -> Result<usize>
where
    Dim<D>: Rigid<D>,
{
    let result = iterate(system, at, motions, f, watch, info, observer);
    system.release_spare();
    result
}

/// [`minimize_watched`]'s iterations.
fn iterate<const D: usize>(
    system: &mut System<D>,
    (complex, constraints): (&CellComplex<D>, &Constraints<D>),
    motions: &mut [Motion<D>],
    f: f64,
    (params, off_branch): (&SolveParams, OffBranch<D>),
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
        (params, off_branch),
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
    // The last Newton step was no descent direction: the next is Gauss-Newton's.
    let mut newton_failed = false;
    info.converged = false;
    while iterations < params.max_iterations {
        if energy <= floor {
            info.converged = true;
            break;
        }
        let t0 = Instant::now();
        // Newton's curvature once Gauss-Newton has brought the load step near its minimum
        // (or from the start, where it starts there).
        let newton = params.newton && (iterations > 0 || params.newton_at_start) && !newton_failed;
        // How loosely the multilevel path may solve a step expected to move the cells by
        // little: the last two iterations' moves say how far.
        let enough = match (iterations, info.log.len()) {
            (0, _) => 0.0,
            (1, n) => iteration::enough_residual(None, &info.log[n - 1], params.move_tolerance),
            (_, n) => iteration::enough_residual(
                Some(&info.log[n - 2]),
                &info.log[n - 1],
                params.move_tolerance,
            ),
        };
        let ask = Ask { settled, enough };
        let (delta, cost) = system.step(complex, constraints, motions, &targets_to, newton, ask)?;
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
            system.project_positions(complex, constraints, &mut m, &targets_to)?;
            let e = total_energy(complex, constraints, &m, &targets_to);
            Ok::<_, Error>((m, e))
        };
        let mut t = 1.0;
        let mut accepted = None;
        for _ in 0..30 {
            let (m, e) = trial(t)?;
            if !e.is_finite() {
                return Err(Error::solver("the energy became non-finite"));
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
                let (m, e) = trial(2.0 * t)?;
                if e >= *best || e.is_nan() {
                    break;
                }
                t *= 2.0;
                accepted = Some((m, e));
            }
        }
        let Some((trial, e)) = accepted else {
            // A Newton step along which the energy rises at once: its matrix was indefinite
            // and the solve did not say so (the multilevel path's factor of a small level, or
            // conjugate gradients that met no negative curvature), so the step is no descent
            // direction and says nothing of a minimum. The iteration is taken again with
            // Gauss-Newton's matrix, which is positive definite: on the dragon twisted by 360°
            // at cells of 3 (`--solver multilevel`), six load steps each ended after one such
            // step, the cells carrying the predictor's twist, and the finest stage untwisted.
            if cost.newton {
                newton_failed = true;
                continue;
            }
            // No step lowers the energy: a minimum to machine precision.
            info.converged = true;
            break;
        };
        newton_failed = false;
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
            method: match cost.newton {
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
        if off_branch(motions) {
            break;
        }
    }
    Ok(local_global + iterations)
}

/// What to change when the cells do not fit the memory budget.
pub(crate) fn cells_advice() -> Said {
    Said::from("use a larger ")
        .opt(Opt::CellSize)
        .text(" (or fewer ")
        .opt(Opt::Cells)
        .text(")")
}

/// What to change when refined cells would not fit it.
pub(super) fn refine_advice() -> Said {
    Said::from("use a larger ")
        .opt(Opt::RefineStrain)
        .text(" threshold")
}

/// The solver's estimate for `cells` cells by `method`, checked against `budget`.
pub(super) fn check_solver_memory(
    cells: usize,
    method: Method,
    budget: Budget,
    advice: &Said,
) -> Result<()> {
    let (per_cell, by) = match method {
        Method::Multilevel => (
            crate::memory::MULTILEVEL_BYTES_PER_CELL,
            " by the multilevel solver",
        ),
        _ => (crate::memory::SOLVER_BYTES_PER_CELL, ""),
    };
    budget.check(
        format!("solving {cells} cells{by}"),
        cells as f64 * per_cell as f64,
        advice,
    )
}

pub(super) fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let r = f();
    *acc += t.elapsed().as_secs_f64();
    r
}
