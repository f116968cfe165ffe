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

use rayon::prelude::*;

use super::anderson::Anderson;
use super::constraints::{Constraints, Role};
use super::energy::quadrature;
use super::positions::Positions;
use super::{prescribe, targets_at, total_energy};
use crate::cells::CellComplex;
use crate::error::{Error, Result};
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
    /// Solve the global step by this many subdomains ([`super::schwarz`]) instead of one
    /// factor; 0 factors it whole. Default 0.
    pub subdomains: usize,
}

impl Default for LocalGlobalParams {
    fn default() -> Self {
        Self {
            max_iterations: 1000,
            tolerance: 1e-9,
            anderson: 5,
            subdomains: 0,
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
pub(crate) struct Layout<const D: usize> {
    /// Center of rotation of every cell (the rest center, or the pinned point).
    centers: Vec<Vect<D>>,
    /// The pin of each pinned cell (`None` for the other cells).
    pinned: Vec<Option<u32>>,
    /// Rotating cells (free or pinned).
    rotating: Vec<u32>,
    /// Sides of each rotating cell, in the order of `rotating`.
    sides: Vec<Vec<Side<D>>>,
    /// Targets of each rotating cell.
    targets: Vec<Vec<u32>>,
}

impl<const D: usize> Layout<D> {
    /// The centers of rotation, the rotating cells and their sides' moments: what no motion
    /// changes (nor a handle, pin or target moved).
    pub(crate) fn new(complex: &CellComplex<D>, constraints: &Constraints<D>) -> Self {
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
                    pinned[c] = Some(*k);
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

    /// Sets the rotating cells' rotations to `rots`, the pinned cells' positions to send their
    /// points to `to.pins`, and the free positions to their optimum (the global step).
    fn global(
        &self,
        (complex, constraints, positions): (&CellComplex<D>, &Constraints<D>, &Positions),
        motions: &mut [Motion<D>],
        rots: &[Mat<D>],
        to: &Destinations<D>,
    ) -> Result<()> {
        for (&c, rot) in self.rotating.iter().zip(rots) {
            let c = c as usize;
            motions[c].rot = *rot;
            if let Some(k) = self.pinned[c] {
                motions[c].pos =
                    rot * (complex.cells[c].center - self.centers[c]) + to.pins[k as usize];
            }
        }
        positions.project(complex, constraints, motions, to.targets)
    }
}

/// Where the pins and the soft targets pull at a load step.
pub(crate) struct Destinations<'a, const D: usize> {
    pub pins: &'a [Vect<D>],
    pub targets: &'a [Vect<D>],
}

/// How a run of local-global iterations stops.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Stop {
    /// Iterations at most.
    pub max_iterations: usize,
    /// Stop once the energy left to gain, estimated from how fast the decreases shrink, is
    /// below this fraction of the energy; 0 runs all `max_iterations`.
    pub tolerance: f64,
    /// And once the distance any cell corner has left to move, estimated as the energy left
    /// is, is below this many finest cell sizes; 0 keeps only the energy test.
    pub move_tolerance: f64,
    /// Stop at this energy or below (the cells rigid to rounding).
    pub floor: f64,
    /// Previous iterates of Anderson acceleration; 0 turns it off.
    pub anderson: usize,
}

/// One iteration as [`iterate`] hands it to its caller.
pub(crate) struct Iterate {
    pub energy_before: f64,
    pub energy: f64,
    /// The largest distance a cell corner moved, in finest cell sizes.
    pub largest_move: f64,
    /// Whether Anderson's candidate was taken.
    pub accelerated: bool,
    /// Seconds in the local step (the Procrustes fits, and Anderson's fit).
    pub seconds_local: f64,
    /// Seconds in the global steps (back substitutions).
    pub seconds_global: f64,
    /// Seconds evaluating the energy.
    pub seconds_energy: f64,
    /// The run's rate of convergence so far, this iteration included.
    pub rate: Rate,
}

/// Local-global iterations from `motions` (the prescribed cells already where the load step
/// puts them, `energy` theirs) until `stop` says so or `each`, told of every iteration,
/// answers `true`. Returns the iterations and whether they converged: stopped by the
/// tolerance, the floor, a minimum to rounding or `each`. The energy never rises.
///
/// **The stopping rule.** The iteration converges linearly: the decrease over a window of
/// [`RATE_WINDOW`] iterations is about `r` times the last window's, so the energy left to gain
/// is about `S r / (1 − r)` after a window's decrease `S` ([`Rate`]). Windows, not single
/// iterations: accelerated iterations' decreases jump by orders of magnitude from one to the
/// next, and a ratio of two of them said the vegetation strip had converged while it was 5e-4
/// above its minimum. A rule on the last decrease alone (Gauss-Newton's) stops a slowly
/// converging run far from its minimum. The distance the cells have left to move is estimated
/// the same way from the largest corner moves; a small energy left does not bound it (the
/// energy is flat along a long part's soft modes).
#[allow(clippy::too_many_arguments)]
pub(crate) fn iterate<const D: usize>(
    parts: (&CellComplex<D>, &Constraints<D>, &Positions, &Layout<D>),
    motions: &mut [Motion<D>],
    to: &Destinations<D>,
    mut energy: f64,
    stop: &Stop,
    each: &mut dyn FnMut(&Iterate, &[Motion<D>]) -> Result<bool>,
) -> Result<(usize, bool)>
where
    Dim<D>: Rigid<D>,
{
    let (complex, constraints, positions, layout) = parts;
    if layout.rotating.is_empty() {
        return Ok((0, true));
    }
    let fixed = (complex, constraints, positions);
    let (global_time, energy_time) = (std::cell::Cell::new(0.0), std::cell::Cell::new(0.0));
    let step = |motions: &mut [Motion<D>], rots: &[Mat<D>]| -> Result<f64> {
        let t = Instant::now();
        layout.global(fixed, motions, rots, to)?;
        global_time.set(global_time.get() + t.elapsed().as_secs_f64());
        let t = Instant::now();
        let e = total_energy(complex, constraints, motions, to.targets);
        energy_time.set(energy_time.get() + t.elapsed().as_secs_f64());
        Ok(e)
    };
    let mut history = Anderson::new(stop.anderson);
    let rots: Vec<Mat<D>> = layout
        .rotating
        .iter()
        .map(|&c| motions[c as usize].rot)
        .collect();
    let mut x = flatten(&rots);
    let (mut decreases, mut moves): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
    let size = complex.grid.finest_size();
    let mut iterations = 0;
    while iterations < stop.max_iterations {
        if energy <= stop.floor {
            return Ok((iterations, true));
        }
        let (global0, energy0) = (global_time.get(), energy_time.get());
        let t = Instant::now();
        let g_rots = layout.local(complex, constraints, motions, to.targets);
        let g = flatten(&g_rots);
        let candidate = history.push(&x, &g);
        let mut next = None;
        if let Some(candidate) = candidate {
            let rots = unflatten::<D>(&candidate);
            let mut trial = motions.to_vec();
            let e = step(&mut trial, &rots)?;
            if e < energy {
                next = Some((trial, e, flatten(&rots), true));
            } else {
                history.clear();
                history.push(&x, &g);
            }
        }
        let (trial, e, rots, accelerated) = match next {
            Some(next) => next,
            None => {
                let mut trial = motions.to_vec();
                let e = step(&mut trial, &g_rots)?;
                (trial, e, g, false)
            }
        };
        if !e.is_finite() {
            return Err(Error::solver("the energy became non-finite"));
        }
        // The plain step never raises the energy: a rise, or no fall, is rounding at the
        // minimum.
        if e >= energy {
            return Ok((iterations, true));
        }
        iterations += 1;
        decreases.push(energy - e);
        let rate = Rate::of(&decreases);
        let largest_move = super::largest_corner_move(complex, motions, &trial) / size;
        moves.push(largest_move);
        let (global, energy_spent) = (global_time.get() - global0, energy_time.get() - energy0);
        let enough = each(
            &Iterate {
                energy_before: energy,
                energy: e,
                largest_move,
                accelerated,
                seconds_local: t.elapsed().as_secs_f64() - global - energy_spent,
                seconds_global: global,
                seconds_energy: energy_spent,
                rate,
            },
            &trial,
        )?;
        motions.copy_from_slice(&trial);
        x = rots;
        energy = e;
        let still =
            stop.move_tolerance > 0.0 && Rate::of(&moves).left_to_gain() > stop.move_tolerance;
        if enough || (rate.left_to_gain() <= stop.tolerance * energy && !still) {
            return Ok((iterations, true));
        }
    }
    Ok((iterations, false))
}

/// A run of local-global iterations at a load step of [`super::solve`] (or a session's
/// update): at most `params.max_iterations` times `params.local_global_per_iteration` of them,
/// stopped once
/// the energy left to gain is below [`GAP_FRACTION`] of `params.tolerance` (the last
/// Gauss-Newton step's rule leaves less than that ungained); each is logged in `info`
/// and told to `observer`. With `newton`, what Gauss-Newton is estimated to take from here in
/// local-global iterations, the run also stops where its rate says it would take more than
/// half of that (then [`Outcome::Slower`]). Returns the iterations and how the run ended.
#[allow(clippy::too_many_arguments)]
pub(super) fn logged<const D: usize>(
    (positions, layout): (&Positions, &Layout<D>),
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    (motions, energy, floor): (&mut [Motion<D>], f64, f64),
    to: &Destinations<D>,
    (params, newton, off_branch): (&super::SolveParams, Option<&dyn Fn() -> f64>, OffBranch<D>),
    info: &mut super::SolverInfo,
    observer: &dyn crate::progress::Observer,
) -> Result<(usize, Outcome)>
where
    Dim<D>: Rigid<D>,
{
    let stop = Stop {
        max_iterations: params
            .max_iterations
            .saturating_mul(params.local_global_per_iteration),
        tolerance: params.tolerance * GAP_FRACTION,
        move_tolerance: params.move_tolerance,
        floor,
        anderson: ANDERSON_DEPTH,
    };
    let load_step = info.step_starts.len() - 1;
    let (mut done, mut newton_estimate) = (0usize, None);
    let mut slower = false;
    let mut each = |it: &Iterate, motions: &[Motion<D>]| {
        let log = super::IterationLog {
            method: match it.accelerated {
                true => super::IterationMethod::Anderson,
                false => super::IterationMethod::LocalGlobal,
            },
            load_step,
            cells: complex.len(),
            energy: it.energy,
            decrease: (it.energy_before - it.energy) / it.energy_before,
            largest_move: it.largest_move,
            step_length: 1.0,
            linear_iterations: 0,
            seconds_assembly: it.seconds_local,
            seconds_setup: 0.0,
            seconds_linear: it.seconds_global,
            seconds_line_search: it.seconds_energy,
        };
        info.iterations += 1;
        info.energies.push(it.energy);
        info.seconds_factor += it.seconds_local + it.seconds_global;
        info.log.push(log);
        let n = info.log.len();
        // A line every tenth iteration: a run takes tens to hundreds.
        if n.is_multiple_of(10) {
            observer.message(&format!("iteration {n}: {log}"));
        }
        crate::progress::stop_if_cancelled(observer)?;
        done += 1;
        // A load step that left its branch is taken again in halves: no use converging it.
        if done.is_multiple_of(RATE_WINDOW) && off_branch(motions) {
            return Ok(true);
        }
        // Once the rate is known, and then every window: would Gauss-Newton be sooner?
        if let Some(newton) = newton
            && done >= 2 * RATE_WINDOW
            && done.is_multiple_of(RATE_WINDOW)
        {
            let left = it.rate.iterations_to(stop.tolerance * it.energy);
            // Half: the early windows' rate is the fastest the run will see.
            slower = left > 0.5 * *newton_estimate.get_or_insert_with(newton);
        }
        Ok(slower)
    };
    let parts = (complex, constraints, positions, layout);
    let (iterations, converged) = iterate(parts, motions, to, energy, &stop, &mut each)?;
    let outcome = match (slower, converged) {
        (true, _) => Outcome::Slower,
        (false, true) => Outcome::Converged,
        (false, false) => Outcome::Unconverged,
    };
    info.converged = outcome == Outcome::Converged;
    Ok((iterations, outcome))
}

/// Whether a load step's iterate has left the branch its load path is on (the caller takes
/// the step again in halves, so the step's iterations stop there); `|_| false` where nothing
/// watches.
pub(in crate::internal::solve) type OffBranch<'a, const D: usize> =
    &'a dyn Fn(&[Motion<D>]) -> bool;

/// How a run of [`logged`] iterations ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(in crate::solve) enum Outcome {
    /// At the tolerance (or a minimum to rounding).
    Converged,
    /// At the iteration limit.
    Unconverged,
    /// Stopped where Gauss-Newton was estimated to finish sooner.
    Slower,
}

/// The energy left to gain at which [`logged`] stops, as a fraction of
/// [`super::SolveParams::tolerance`]: on the tube a tenth stopped 1.2e-6 of the energy above
/// Newton's minimum (the estimate of what is left is rough), a hundredth within 1e-7.
const GAP_FRACTION: f64 = 0.01;

/// The default [`super::SolveParams::local_global_per_iteration`].
pub const LOCAL_GLOBAL_PER_ITERATION: usize = 40;

/// Previous iterates Anderson acceleration keeps (Peng et al. use 5 and 6).
const ANDERSON_DEPTH: usize = 5;

/// Iterations in a window of [`Rate`].
pub(crate) const RATE_WINDOW: usize = 8;

/// How fast a linearly converging run's energy falls: the decrease `last` over its last
/// [`RATE_WINDOW`] iterations and its ratio `ratio` to the window's before.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rate {
    last: f64,
    ratio: f64,
}

impl Rate {
    /// The rate of a run of `decreases` (`ratio` infinite until there are two windows).
    pub(crate) fn of(decreases: &[f64]) -> Self {
        let k = decreases.len();
        if k < 2 * RATE_WINDOW {
            return Self {
                last: f64::INFINITY,
                ratio: f64::INFINITY,
            };
        }
        let last: f64 = decreases[k - RATE_WINDOW..].iter().sum();
        let before: f64 = decreases[k - 2 * RATE_WINDOW..k - RATE_WINDOW].iter().sum();
        Self {
            last,
            ratio: last / before,
        }
    }

    /// The energy left to gain: infinite while the windows' decreases do not shrink.
    pub(crate) fn left_to_gain(&self) -> f64 {
        match self.ratio.is_finite() && self.ratio < 1.0 {
            true => self.last * self.ratio / (1.0 - self.ratio),
            false => f64::INFINITY,
        }
    }

    /// Iterations more until the energy left to gain is `goal` (infinite where the decreases
    /// do not shrink).
    pub(crate) fn iterations_to(&self, goal: f64) -> f64 {
        let left = self.left_to_gain();
        if left <= goal {
            return 0.0;
        }
        match left.is_finite() && goal > 0.0 {
            true => RATE_WINDOW as f64 * (goal / left).ln() / self.ratio.ln(),
            false => f64::INFINITY,
        }
    }
}

/// Minimizes the glue energy at full load by local-global iterations from `start` (the
/// prescribed cells are set to their prescribed motions first, the free positions to their
/// optimum). Returns the motions and what was done; an error where the energy stops being a
/// number or the global step by subdomains fails. See the module docs.
pub fn minimize_local_global<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    start: &[Motion<D>],
    params: &LocalGlobalParams,
) -> Result<(Vec<Motion<D>>, LocalGlobalInfo)>
where
    Dim<D>: Rigid<D>,
{
    let clock = Instant::now();
    let mut info = LocalGlobalInfo::default();
    let mut motions = start.to_vec();
    prescribe(complex, constraints, &mut motions, 1.0);
    let targets = targets_at(constraints, 1.0);
    let pins: Vec<Vect<D>> = constraints.pins.iter().map(|p| p.to).collect();
    let to = Destinations {
        pins: &pins,
        targets: &targets,
    };
    let positions = match params.subdomains {
        0 => Positions::new(complex, constraints),
        k => Positions::by_subdomains(complex, constraints, k, None)?,
    };
    info.seconds_factor = clock.elapsed().as_secs_f64();
    let layout = Layout::new(complex, constraints);
    let rots: Vec<Mat<D>> = layout
        .rotating
        .iter()
        .map(|&c| motions[c as usize].rot)
        .collect();
    layout.global((complex, constraints, &positions), &mut motions, &rots, &to)?;
    let energy = total_energy(complex, constraints, &motions, &targets);
    info.energies.push(energy);
    info.seconds.push(clock.elapsed().as_secs_f64());
    let loop_start = Instant::now();
    let stop = Stop {
        max_iterations: params.max_iterations,
        tolerance: 0.0,
        move_tolerance: 0.0,
        floor: 0.0,
        anderson: params.anderson,
    };
    let mut last = energy;
    let mut each = |it: &Iterate, _: &[Motion<D>]| {
        info.energies.push(it.energy);
        info.seconds.push(clock.elapsed().as_secs_f64());
        info.accelerated += it.accelerated as usize;
        info.seconds_local += it.seconds_local;
        info.seconds_global += it.seconds_global;
        info.seconds_energy += it.seconds_energy;
        let stalled = last - it.energy <= params.tolerance * it.energy;
        last = it.energy;
        Ok(stalled)
    };
    let parts = (complex, constraints, &positions, &layout);
    iterate(parts, &mut motions, &to, energy, &stop, &mut each)?;
    info.iterations = info.energies.len() - 1;
    info.seconds_per_iteration = loop_start.elapsed().as_secs_f64() / info.iterations.max(1) as f64;
    Ok((motions, info))
}

/// The rotations' entries, one after another.
fn flatten<const D: usize>(rots: &[Mat<D>]) -> Vec<f64> {
    rots.iter().flat_map(|r| r.iter().copied()).collect()
}

/// Rotations nearest to the `D × D` blocks of `x` (an accelerated iterate's blocks are near
/// rotations: [`Rigid::nearest_rotation`]'s polar iteration settles them in one or two steps).
fn unflatten<const D: usize>(x: &[f64]) -> Vec<Mat<D>>
where
    Dim<D>: Rigid<D>,
{
    x.par_chunks(D * D)
        .map(|c| <Dim<D> as Rigid<D>>::nearest_rotation(&Mat::<D>::from_column_slice(c)))
        .collect()
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
        // Plain, accelerated, and accelerated with the global step solved by four subdomains
        // (the solve spread over processes, in one).
        for (anderson, subdomains) in [(0, 0), (5, 0), (5, 4)] {
            let params = LocalGlobalParams {
                max_iterations: 3000,
                tolerance: 0.0,
                anderson,
                subdomains,
            };
            let (motions, info) =
                minimize_local_global(complex, constraints, &rest, &params).unwrap();
            for w in info.energies.windows(2) {
                assert!(
                    w[1] <= w[0],
                    "{D}D m = {anderson}, {subdomains} subdomains: the energy rose from {} to {}",
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
            if subdomains > 0 {
                assert!(
                    last <= best * (1.0 + 1e-6),
                    "{D}D by {subdomains} subdomains: {last} after {} iterations, Newton {best}",
                    info.iterations
                );
            }
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

    /// `solve` of `complex` under `constraints` by `method`.
    fn solved<const D: usize>(
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        method: crate::solve::Method,
    ) -> crate::solve::Solution<D>
    where
        Dim<D>: Rigid<D>,
    {
        let params = SolveParams {
            method,
            ..Default::default()
        };
        let (complex, constraints) = (complex.clone(), constraints.clone());
        let silent = &crate::progress::Silent;
        crate::solve::solve(complex, constraints, &params, Budget::default(), silent).unwrap()
    }

    /// Solved by local-global iterations through load steps, the bar ends within 1e-6 of
    /// Newton's energy, its prescribed cells where they are sent, every iteration logged as
    /// local-global; `auto` takes the same iterations here (a short bar), the same every run.
    #[test]
    fn a_solve_by_local_global_ends_at_newtons_minimum() {
        use crate::solve::{IterationMethod, Method};
        let mesh = data_gen::bar([4.0, 1.0, 1.0], 12.0);
        let pts: Vec<Vect<3>> = mesh.vertices.iter().map(|v| Vect::<3>::from(*v)).collect();
        let spec = "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
                    [[handle]]\nbox = { min = [3.5, -0.1, -0.1], max = [4.1, 1.1, 1.1] }\n\
                    rotate = { axis = [0.0, 1.0, 0.0], degrees = 60.0 }\n\
                    translate = [0.0, 0.3, 0.5]\n";
        let (complex, constraints) = edited(&pts, &mesh.triangles, 0.25, spec);
        let newton = solved(&complex, &constraints, Method::Direct);
        let lg = solved(&complex, &constraints, Method::LocalGlobal);
        let energy = |s: &crate::solve::Solution<3>| *s.info.energies.last().unwrap();
        let (en, el) = (energy(&newton), energy(&lg));
        assert!(
            (el - en).abs() <= 1e-6 * en,
            "local-global {el}, Newton {en}"
        );
        assert!(lg.info.converged && lg.info.load_steps > 1, "{:?}", lg.info);
        assert!(lg.info.log.iter().all(|l| matches!(
            l.method,
            IterationMethod::LocalGlobal | IterationMethod::Anderson
        )));
        assert!(newton.info.log.iter().all(|l| matches!(
            l.method,
            IterationMethod::GaussNewton | IterationMethod::Newton
        )));
        assert_eq!(lg.info.linear_solver(), "local-global");
        let mut want = lg.motions.clone();
        prescribe(&complex, &lg.constraints, &mut want, 1.0);
        assert_eq!(want, lg.motions, "prescribed cells moved");
        let auto = solved(&complex, &constraints, Method::Auto);
        assert_eq!(auto.motions, lg.motions);
        assert_eq!(
            auto.motions,
            solved(&complex, &constraints, Method::Auto).motions
        );
    }

    /// On a strip 40 cells long `auto` starts with local-global iterations, finds Gauss-Newton
    /// sooner and ends at its minimum.
    #[test]
    fn auto_takes_newton_where_local_global_would_be_slower() {
        use crate::solve::{IterationMethod, Method};
        let pts: Vec<Vect<2>> = (0..=400)
            .flat_map(|i| (0..=10).map(move |j| Vect::<2>::new(i as f64 * 0.05, j as f64 * 0.05)))
            .collect();
        let spec = "[[fixed]]\nbox = { min = [-0.1, -0.1], max = [1.0, 1.1] }\n\
                    [[handle]]\nbox = { min = [19.0, -0.1], max = [20.1, 1.1] }\n\
                    translate = [0.0, 3.0]\n";
        let (complex, constraints) = edited(&pts, &[], 0.5, spec);
        let auto = solved(&complex, &constraints, Method::Auto);
        assert!(auto.info.newton_sooner, "{:?}", auto.info.log);
        let first = auto.info.log.first().unwrap().method;
        assert_eq!(first, IterationMethod::LocalGlobal);
        assert!(matches!(
            auto.info.log.last().unwrap().method,
            IterationMethod::Newton | IterationMethod::GaussNewton
        ));
        let newton = solved(&complex, &constraints, Method::Direct);
        let energy = |s: &crate::solve::Solution<2>| *s.info.energies.last().unwrap();
        let (ea, en) = (energy(&auto), energy(&newton));
        assert!((ea - en).abs() <= 1e-6 * en, "auto {ea}, Newton {en}");
    }
}
