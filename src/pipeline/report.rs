//! The machine-readable report of a deformation (`deform --report R.json`), or of a solve over
//! tiles (`solve --report R.json`: the same keys, with the tiles as `inputs`, the field as
//! `output`, and a `write` time of 0; every figure what `deform` reports for the tiles merged).
//!
//! Scripts rely on these top-level keys, which keep their names and meanings: `points`,
//! `cells`, `cells_initial`, `iterations`, `energy`, `residual_max`, `foldovers` and
//! `timings_s` with `read`, `voxelize`, `solve`, `transfer`, `write`, `total`. Keys may be
//! added; none is renamed or removed.
//!
//! The residual is measured where the file's samples were sent: on the preview proxy (every
//! k-th sample, [`crate::pipeline::Proxy`]), each sample inside a fixed cell should stay where
//! it was and each inside a handle's cell should follow the handle's motion; `residual_max` is
//! the largest distance of such a sample from there, in input units (zero when the proxy holds
//! none). `residual_fixed_max` and `residual_handle_max` split it by role. Every transfer makes
//! fixed and handle samples exact ([`crate::field::FieldMap`]), so these are zero up to the
//! rounding of the handle's transform. Soft targets are reported apart, as the distance of each
//! target's point under its cell's motion (and the control points' trend) from the target
//! (`target_residual_max`): a soft target is not met exactly by design.

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;
use serde::Serialize;

use super::{DeformInfo, FileInfo};
use crate::error::{Error, Result};
use crate::rigid::Vect;
use crate::said::Said;
use crate::solve::{Role, Solution};

/// The report; see the module docs for the stable keys.
#[derive(Debug, Clone, Serialize)]
#[non_exhaustive]
pub struct Report {
    /// The input file (for a solve over tiles, the files, joined by `, `).
    pub input: String,
    /// The input files: one for `deform`, the tiles in their order for `solve`.
    pub inputs: Vec<String>,
    /// The output file (for a solve, the field).
    pub output: String,
    /// Samples deformed.
    pub points: u64,
    /// Cells after refinement.
    pub cells: usize,
    /// Cells before refinement.
    pub cells_initial: usize,
    /// The finest cells' edge length, in input units.
    pub cell_size: f64,
    /// Cells per octree level (level 0 the finest), after refinement.
    pub cell_levels: BTreeMap<u8, usize>,
    /// Cells of each role: `free`, `fixed`, `handle`, `pin`, `rest`.
    pub cell_roles: BTreeMap<&'static str, usize>,
    /// Gauss-Newton iterations over all load steps and refinements.
    pub iterations: usize,
    /// Load steps.
    pub load_steps: usize,
    /// Load steps taken again in halves because they left the branch of the load path (a
    /// part untwisting the short way round).
    pub load_step_halvings: usize,
    /// Per turning handle: its spec line, the turn asked (`turn_asked_degrees`) and the turn
    /// the cells carry from the fixed cells to it (`turn_taken_degrees`, null when no chain of
    /// cells joins it to a fixed cell); see [`crate::solve::turns`].
    pub handle_turns: Vec<HandleTurnReport>,
    /// How the cells' last iterations were solved: `direct` or `multilevel` (Gauss-Newton's
    /// linear systems), or `local-global`.
    pub linear_solver: &'static str,
    /// Conjugate-gradient iterations over all Gauss-Newton steps (multilevel; 0 when direct).
    pub linear_iterations: usize,
    /// Levels of the multilevel hierarchy (0 when direct).
    pub levels: usize,
    /// The energy before the first iteration of each load step and after every iteration.
    pub energy: Vec<f64>,
    /// Whether the last load step met the tolerance.
    pub converged: bool,
    /// Every iteration: its `method` (`gauss-newton`, `newton`, `local-global` or `anderson`,
    /// a local-global iteration whose accelerated rotations were kept), `load_step`, `energy`, the two stopping figures (the
    /// energy's relative `decrease` and the `largest_move` of a cell corner in finest cell
    /// sizes), the line search's `step_length`, its `linear_iterations` (conjugate gradients),
    /// and its `seconds_assembly`, `seconds_setup` (factor or hierarchy), `seconds_linear`
    /// (the linear solve) and `seconds_line_search`.
    pub iteration_log: Vec<crate::solve::IterationLog>,
    /// The largest distance of a fixed or handle sample of the proxy from where it was sent.
    pub residual_max: f64,
    /// The largest distance of a fixed sample of the proxy from its rest position.
    pub residual_fixed_max: f64,
    /// The largest distance of a handle sample of the proxy from where its handle sends it.
    pub residual_handle_max: f64,
    /// Proxy samples that `residual_max` measured.
    pub residual_samples: usize,
    /// The largest distance of a soft target's point, under its cell's motion, from its
    /// target.
    pub target_residual_max: f64,
    /// Samples where the map folds space over (Jacobian determinant not positive).
    pub foldovers: usize,
    /// Samples checked for fold-overs.
    pub foldovers_checked: usize,
    /// The samples the map folds over, by their index in the input: for points deformed in
    /// memory; a file's check is on its preview proxy, whose samples are not the file's, and
    /// lists none.
    pub foldover_samples: Vec<usize>,
    /// Seconds per stage.
    pub timings_s: Timings,
    /// The process's peak resident memory in bytes (`VmHWM`; absent where unknown).
    pub peak_memory_bytes: Option<u64>,
    /// What the solve was estimated to take before it started ([`crate::estimate`]): its
    /// `cells`, peak memory in `bytes`, `seconds` (the solve and the transfer's construction)
    /// and `solver`; beside `peak_memory_bytes` and `timings_s` it says how near the estimate
    /// came.
    pub estimate: Option<EstimateReport>,
    /// Warnings, as printed.
    pub warnings: Vec<Said>,
    /// Notes on the output (an offset moved to fit, samples beyond the margin), as printed.
    pub notes: Vec<Said>,
    /// Every control point (`[[target]]`): id, where it was given, from (after snapping),
    /// wanted, got (where the output puts it), residual, how far it was snapped, whether it is
    /// 2D, and its leave-one-out prediction error (`--check-gcp`).
    pub control_points: Vec<crate::control::ControlPoint>,
    /// What the control points' `got` was rounded to before their residuals were measured:
    /// the output's coordinates as written (`"the output's scale 0.01"`; absent where they are
    /// the field's values).
    pub control_rounding: Option<String>,
    /// The root mean square of the control points' residuals (absent without any).
    pub control_rmse: Option<f64>,
    /// The root mean square of their leave-one-out prediction errors (with `--check-gcp`).
    pub control_rmse_left_out: Option<f64>,
    /// The control points' trend (`"spline"`, `"affine"`, …; absent without one).
    pub control_trend: Option<String>,
    /// The checkpoints' accuracy (rows marked `check`: RMSE x, y, horizontal and height, and
    /// at 95 % as ASPRS and the NSSDA state it; absent without checkpoints).
    pub checkpoints: Option<crate::control::CheckAccuracy>,
    /// The options the run took, by the Python package's keywords (`cell_size`,
    /// `interior_stiffness`, …), each at the value given or `null` where the run decided
    /// ([`crate::pipeline::Options::recorded`]): with the spec, what runs it again.
    pub options: BTreeMap<String, serde_json::Value>,
}

/// The solve's estimate in the report.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct EstimateReport {
    /// Cells.
    pub cells: usize,
    /// Peak memory, in bytes.
    pub bytes: u64,
    /// Seconds of the solve and the transfer's construction.
    pub seconds: f64,
    /// The linear solver: `direct` or `multilevel`.
    pub solver: &'static str,
}

impl From<&crate::estimate::Estimate> for EstimateReport {
    fn from(e: &crate::estimate::Estimate) -> Self {
        Self {
            cells: e.cells,
            bytes: e.bytes,
            seconds: e.seconds,
            solver: e.solver.name(),
        }
    }
}

/// One turning handle's turn in the report.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct HandleTurnReport {
    /// The handle's line in the edit spec.
    pub line: usize,
    /// The turn asked, in degrees.
    pub turn_asked_degrees: f64,
    /// The turn the cells carry from the fixed cells to the handle, in degrees.
    pub turn_taken_degrees: Option<f64>,
}

impl From<&crate::solve::HandleTurn> for HandleTurnReport {
    fn from(t: &crate::solve::HandleTurn) -> Self {
        Self {
            line: t.line,
            turn_asked_degrees: t.asked_degrees,
            turn_taken_degrees: t.taken_degrees,
        }
    }
}

/// Seconds per stage of [`crate::pipeline::deform_file`].
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Timings {
    /// Pass 1, less the cells' construction: reading the samples, bounds and selections.
    pub read: f64,
    /// Building the cell complex (occupancy, octree, inside classification).
    pub voxelize: f64,
    /// The Gauss-Newton solve, refinements included.
    pub solve: f64,
    /// Building the transfer (the RBF's factorization, the blend's index), the proxy's
    /// deformation and the fold-over check.
    pub transfer: f64,
    /// Pass 2: every sample read, moved through the transfer and written (0 for a solve, which
    /// writes only the field).
    pub write: f64,
    /// The control points' leave-one-out check (`--check-gcp`; 0 without it): one solve per
    /// point.
    pub check_gcp: f64,
    /// From the start of the deformation to the output's rename.
    pub total: f64,
}

impl Timings {
    /// The stages' seconds of a deformation: `read` and `write` are a file's passes (0 for
    /// samples in memory; the read less the cells' construction, which is `voxelize`), `total`
    /// the wall time the caller measured.
    pub fn of(deform: &super::DeformInfo, read: f64, write: f64, total: f64) -> Self {
        Self {
            read: (read - deform.build.seconds).max(0.0),
            voxelize: deform.build.seconds,
            solve: deform.solver.seconds,
            transfer: (deform.seconds_transfer - write).max(0.0),
            write,
            check_gcp: deform.seconds_check,
            total,
        }
    }
}

impl Report {
    /// The report of `deform_file`'s result, or of `solve_files`' over the files `inputs`
    /// (whose output is the field); `total` is the wall time the caller measured.
    pub fn new(
        inputs: &[&Path],
        output: &Path,
        solution: &Solution<3>,
        file: &FileInfo,
        total: f64,
    ) -> Self {
        let proxy = &file.proxy;
        let inputs: Vec<String> = inputs.iter().map(|p| p.display().to_string()).collect();
        Self::of(
            (inputs, output.display().to_string()),
            Some(solution),
            &file.deform,
            (file.samples, &proxy.before, &proxy.after),
            Timings::of(&file.deform, file.seconds_read, file.seconds_write, total),
            file.notes.clone(),
        )
    }

    /// The report of a deformation of samples in memory (`deform`, a live session's release,
    /// the Python package's arrays): `before` went to `after` (both empty for a solve that
    /// moved none), every one measured for the residuals; no file in or out, and no read or
    /// write time. Without a solution (nothing was constrained yet) the cells' figures are 0.
    pub fn of_samples(
        solution: Option<&Solution<3>>,
        info: &DeformInfo,
        samples: u64,
        (before, after): (&[Vect<3>], &[Vect<3>]),
        total: f64,
    ) -> Self {
        Self::of(
            (Vec::new(), String::new()),
            solution,
            info,
            (samples, before, after),
            Timings::of(info, 0.0, 0.0, total),
            Vec::new(),
        )
    }

    fn of(
        (inputs, output): (Vec<String>, String),
        solution: Option<&Solution<3>>,
        d: &DeformInfo,
        (samples, before, after): (u64, &[Vect<3>], &[Vect<3>]),
        timings_s: Timings,
        notes: Vec<Said>,
    ) -> Self {
        let s = &d.solver;
        let mut cell_levels = BTreeMap::new();
        let mut cell_roles = BTreeMap::new();
        let (mut residual_fixed_max, mut residual_handle_max, mut residual_samples) = (0.0, 0.0, 0);
        let (mut cell_size, mut target_residual_max) = (0.0, 0.0f64);
        if let Some(solution) = solution {
            (cell_levels, cell_roles) = census(solution);
            (residual_fixed_max, residual_handle_max, residual_samples) =
                residuals(solution, before, after);
            cell_size = solution.complex.grid.finest_size();
            target_residual_max = target_residual(solution);
        }
        Self {
            input: inputs.join(", "),
            inputs,
            output,
            points: samples,
            cells: s.cells_final,
            cells_initial: s.cells_initial,
            cell_size,
            cell_levels,
            cell_roles,
            iterations: s.iterations,
            load_steps: s.load_steps,
            load_step_halvings: s.halvings,
            handle_turns: s.turns.iter().map(HandleTurnReport::from).collect(),
            linear_solver: s.linear_solver(),
            linear_iterations: s.linear_iterations,
            levels: s.levels,
            energy: s.energies.clone(),
            converged: s.converged,
            iteration_log: s.log.clone(),
            residual_max: residual_fixed_max.max(residual_handle_max),
            residual_fixed_max,
            residual_handle_max,
            residual_samples,
            target_residual_max,
            foldovers: d.foldovers.1,
            foldovers_checked: d.foldovers.0,
            foldover_samples: d.folded.clone(),
            timings_s,
            peak_memory_bytes: peak_memory(),
            estimate: s.estimate.as_ref().map(EstimateReport::from),
            warnings: d.warnings.clone(),
            notes,
            control_points: d.control_points.clone(),
            control_rounding: d.control_rounding.clone(),
            control_rmse: crate::control::rmse(&d.control_points),
            control_rmse_left_out: crate::control::rmse_left_out(&d.control_points),
            control_trend: d.solver.trend.map(|t| t.to_string()),
            checkpoints: crate::control::check_accuracy(&d.control_points),
            options: d.options.recorded(),
        }
    }

    /// Writes the report as pretty JSON to `path`, atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        crate::io::write_atomic(path, &self.json(path)?)
    }

    /// The report as pretty JSON, ending in a newline (`path` names it in errors).
    pub fn json(&self, path: &Path) -> Result<Vec<u8>> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| Error::param(format!("{}: {e}", path.display())))?;
        Ok(format!("{text}\n").into_bytes())
    }
}

/// The cells per level and per role.
fn census(solution: &Solution<3>) -> (BTreeMap<u8, usize>, BTreeMap<&'static str, usize>) {
    let mut levels = BTreeMap::new();
    for c in &solution.complex.cells {
        *levels.entry(c.key.level).or_insert(0) += 1;
    }
    let mut roles = BTreeMap::new();
    for role in &solution.constraints.roles {
        let name = match role {
            Role::Free => "free",
            Role::Fixed => "fixed",
            Role::Handle(_) => "handle",
            Role::Pin(_) => "pin",
            Role::Rest => "rest",
            Role::Carried(_) => "carried",
        };
        *roles.entry(name).or_insert(0) += 1;
    }
    (levels, roles)
}

/// The largest distance of a soft target's point, under its cell's motion and the control
/// points' trend, from where it is wanted.
fn target_residual(solution: &Solution<3>) -> f64 {
    let complex = &solution.complex;
    solution
        .constraints
        .targets
        .iter()
        .map(|t| {
            let c = t.cell as usize;
            let moved = solution.motions[c].apply(&complex.cells[c].center, &t.from);
            (solution.constraints.trend.apply(&moved) - t.wanted).norm()
        })
        .fold(0.0, f64::max)
}

/// The largest distances of a sample in a fixed cell and in a handle cell from where its cell's
/// constraint sends it (`before[i]` went to `after[i]`), and how many samples were measured.
pub fn residuals(
    solution: &Solution<3>,
    before: &[Vect<3>],
    after: &[Vect<3>],
) -> (f64, f64, usize) {
    let constraints = &solution.constraints;
    let origin = constraints.origin;
    let maps: Vec<_> = (0..constraints.handles.len())
        .map(|k| constraints.handle_map(k, 1.0))
        .collect();
    // Every sample in memory may be measured: in parallel, each thread its own maxima.
    before
        .par_iter()
        .zip(after)
        .fold(
            || (0.0f64, 0.0f64, 0usize),
            |(fixed, handle, count), (before, after)| match solution.role_at(before) {
                Some(Role::Fixed) => (fixed.max((after - before).norm()), handle, count + 1),
                Some(Role::Handle(k)) => {
                    let sent = maps[k as usize].apply(&(before - origin)) + origin;
                    (fixed, handle.max((after - sent).norm()), count + 1)
                }
                _ => (fixed, handle, count),
            },
        )
        .reduce(
            || (0.0, 0.0, 0),
            |a, b| (a.0.max(b.0), a.1.max(b.1), a.2 + b.2),
        )
}

/// `VmHWM` of `/proc/self/status`, in bytes.
fn peak_memory() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The summary `deform` and `solve` print on stdout, as a Rust or Python caller can print it
/// too: the notes, what was made, the solve, the timings, the fold-overs, the control points'
/// table and the constraints' residuals. The warnings are apart ([`Report::warnings`], on stderr).
/// Figures are in plain notation ([`crate::human`]): the residuals to a thousandth of the
/// finest cell, the energy and the time per iteration to three digits.
pub struct Summary<'a> {
    /// The report of the deformation.
    pub report: &'a Report,
    /// What [`crate::pipeline::deform_file`] returned with it.
    pub file: &'a FileInfo,
}

impl std::fmt::Display for Summary<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (r, d) = (self.report, &self.file.deform);
        let s = &d.solver;
        for n in &self.file.notes {
            writeln!(f, "note: {n}")?;
        }
        let inside = match d.build.inside {
            crate::cells::Inside::Winding => "winding number",
            crate::cells::Inside::Flood => "flood fill",
            _ => "none",
        };
        let input = match r.inputs.len() {
            1 => r.input.clone(),
            n => format!("{n} files"),
        };
        write!(
            f,
            "{input} -> {}: {} points, {} cells ({} boundary, {} interior by {inside})",
            r.output, r.points, s.cells_final, d.build.boundary_cells, d.build.interior_cells,
        )?;
        if !s.refinements.is_empty() {
            write!(
                f,
                ", refined from {} to {} cells",
                s.cells_initial, s.cells_final
            )?;
        }
        write!(
            f,
            "\n  solve: {} load steps, {}, energy {}, {:.2} s",
            s.load_steps,
            s.iterations_in_words(),
            crate::human::figure(s.energies.last().copied().unwrap_or(0.0)),
            s.seconds,
        )?;
        if s.iterations > 0 {
            let ms = crate::human::figure(1e3 * s.seconds_per_iteration());
            write!(f, " ({ms} ms/iteration)")?;
        }
        if !s.converged {
            write!(f, ", stopped at the iteration limit")?;
        }
        let t = &r.timings_s;
        write!(
            f,
            "\n  cells {:.2} s, transfer {:.2} s",
            t.voxelize, t.transfer
        )?;
        // A solve writes no samples (its pass 2 is `apply`'s).
        if self.file.seconds_write > 0.0 {
            write!(f, ", write {:.2} s", t.write)?;
        }
        if d.seconds_check > 0.0 {
            write!(f, ", leave-one-out check {:.2} s", d.seconds_check)?;
        }
        writeln!(f)?;
        let (checked, folded) = d.foldovers;
        if checked > 0 {
            writeln!(f, "  fold-overs: {folded} of {checked} samples checked")?;
        }
        let table = crate::control::table(&d.control_points, 10, d.control_rounding.as_deref());
        if !table.is_empty() {
            writeln!(f, "{table}")?;
            if let Some(trend) = d.solver.trend {
                writeln!(
                    f,
                    "  trend: {trend} (the map through the control points; the cells carry the rest)"
                )?;
            }
        }
        if r.residual_samples > 0 {
            let length = |v: f64| crate::human::length(v, r.cell_size);
            write!(
                f,
                "  constraints: fixed samples within {} of their rest positions, handle \
                 samples within {} of where they were sent ({} checked);",
                length(r.residual_fixed_max),
                length(r.residual_handle_max),
                r.residual_samples,
            )?;
        } else {
            write!(f, " ")?;
        }
        write!(f, " total {:.2} s", r.timings_s.total)?;
        if let Some(b) = r.peak_memory_bytes {
            write!(f, ", peak memory {} MB", b >> 20)?;
        }
        writeln!(f)
    }
}
