//! The method on samples in memory ([`deform`], [`solve_points`]) and on files streamed in
//! passes ([`deform_file`], [`apply_file`], [`solve_files`]); every face calls these, with
//! the parameters its user's [`Options`] make.
//!
//! The stage sequence itself — cells, constraints, solve, field, exact transfer — is written
//! once, in `stages`; the files here differ only in where the samples come from and go.

mod checks;
mod files;
mod first_pass;
mod grid;
pub mod live;
mod options;
mod outputs;
pub mod preview;
pub mod report;
pub(crate) mod stages;
mod transfer_pass;

pub(crate) use checks::check_moved;
pub use checks::{FOLDOVER_SAMPLES, check_foldovers};
pub use files::{
    ApplyParams, CHUNK, FileInfo, MAX_CHUNK, apply_file, check_chunk, deform_file, file_cells,
    write_cells,
};
pub use grid::grid_file;
pub use live::{Live, Step};
pub use options::{DEFAULT_INTERIOR_STIFFNESS, OPTION_NAMES, Options};
pub use outputs::{Outputs, deform_file_with, solve_files};

use std::path::Path;
use std::time::Instant;

use crate::cells::{BuildInfo, BuildParams};
use crate::control::ControlPoint;
use crate::error::{Error, Result};
use crate::field::{Deformer, Outside, SavedField, Transfer, apply_into};
use crate::io::{self, Chunk};
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::{Dim, Rigid, Vect};
use crate::said::{Opt, Said};
use crate::solve::{Solution, SolveParams, SolverInfo};
use crate::spec::EditSpec;

use stages::{Cells, Staged, control_results};

/// Parameters of [`deform`] and the other stage sequences, made only from a user's
/// [`Options`] ([`Options::params`], which checks them), so every face runs with checked
/// parameters; the default is the default options' ([`DeformParams::default`]). What a run
/// needs beyond them (a proxy for previews) its own function sets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeformParams {
    /// The cell complex.
    pub(crate) build: BuildParams,
    /// The solver.
    pub(crate) solve: SolveParams,
    /// The transfer to the samples.
    pub(crate) transfer: Transfer,
    /// With the RBF transfer: evaluate positions through its far field, each coordinate
    /// within this length of the exact sum's ([`crate::field::Rbf::with_tolerance`]).
    pub(crate) rbf_tolerance: Option<f64>,
    /// The stiffness of the cells inside the shape against the surface's
    /// ([`crate::solve::Constraints::scale_interior`]).
    pub(crate) interior_stiffness: f64,
    /// The most samples in the proxy of [`deform_file`], for its fold-over check, its report's
    /// residuals and a preview (`None`: [`FOLDOVER_SAMPLES`], as the command line checks a
    /// run without a preview; `Some(0)`: no proxy, for a run that moves no samples).
    pub(crate) proxy_samples: Option<usize>,
    /// Run the control points' leave-one-out check ([`crate::control::leave_one_out`]).
    pub(crate) check_control_points: bool,
    /// The memory budget of every stage: the cells, the solver, the RBF.
    pub(crate) memory: Budget,
    /// The options these parameters were made of, as the user gave them (the report's
    /// `options`).
    pub(crate) options: Options,
}

impl Default for DeformParams {
    /// The parameters of the default [`Options`]: what `rigidcells deform` runs without flags.
    fn default() -> Self {
        Options::default().unchecked()
    }
}

impl DeformParams {
    /// The cell complex's parameters.
    pub fn build(&self) -> &BuildParams {
        &self.build
    }

    /// The solver's parameters.
    pub fn solve(&self) -> &SolveParams {
        &self.solve
    }

    /// The transfer to the samples.
    pub fn transfer(&self) -> Transfer {
        self.transfer
    }

    /// The RBF's far-field tolerance, when given.
    pub fn rbf_tolerance(&self) -> Option<f64> {
        self.rbf_tolerance
    }

    /// The stiffness of the cells inside the shape against the surface's (1: the paper's
    /// volumetric solid).
    pub fn interior_stiffness(&self) -> f64 {
        self.interior_stiffness
    }

    /// Whether the control points' leave-one-out check runs.
    pub fn check_control_points(&self) -> bool {
        self.check_control_points
    }

    /// The memory budget.
    pub fn memory(&self) -> Budget {
        self.memory
    }

    /// [`crate::estimate::check_forecast`] of `forecast` for these parameters' solver and
    /// budget: what a build of cells to be solved checks before it classifies them.
    pub(crate) fn check_forecast(&self, forecast: &crate::cells::Forecast) -> Result<()> {
        let direct = self.solve.method == crate::solve::Method::Direct;
        crate::estimate::check_forecast(forecast, direct, self.memory)
    }

    /// These parameters with the subdomains' blocks given to `workers`
    /// ([`crate::solve::schwarz::register`]; with the option `subdomains`).
    pub fn with_workers(self, workers: Option<crate::solve::schwarz::WorkersId>) -> Self {
        Self {
            solve: SolveParams {
                workers,
                ..self.solve
            },
            ..self
        }
    }

    /// These parameters with at most `samples` samples in [`deform_file`]'s preview proxy
    /// (the fold-over check's and the report's samples among them): 1 or more.
    pub fn with_proxy_samples(self, samples: usize) -> Result<Self> {
        if samples == 0 {
            return Err(Error::param(
                "the proxy needs 1 sample or more (the fold-over check runs on it)",
            ));
        }
        Ok(Self {
            proxy_samples: Some(samples),
            ..self
        })
    }
}

/// The default bound on the samples of a [`Proxy`].
pub const PROXY_SAMPLES: usize = 1 << 20;

/// A decimated copy of a file's samples for previews, gathered in pass 1: every `stride`-th
/// sample (the stride is the smallest that keeps at most the bound), before and after the
/// deformation. `after[i]` is what the output holds for sample `i · stride`, before the
/// output's own rounding (LAS scale, text digits).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Proxy {
    /// Samples from one to the next.
    pub stride: u64,
    /// Rest positions (world coordinates).
    pub before: Vec<Vect<3>>,
    /// Deformed positions.
    pub after: Vec<Vect<3>>,
    /// The input's triangles, when it has some and the proxy holds every sample.
    pub triangles: Vec<[u32; 3]>,
}

impl Proxy {
    /// An empty proxy for `len` samples keeping at most `max` (`max > 0`).
    fn new(len: u64, max: usize) -> Self {
        Self {
            stride: len.div_ceil(max as u64).max(1),
            ..Default::default()
        }
    }

    /// Keeps the chunk's samples whose index is a multiple of the stride.
    fn gather(&mut self, chunk: &Chunk) {
        let skip = (self.stride - chunk.first % self.stride) % self.stride;
        let kept = chunk.positions.iter().skip(skip as usize);
        self.before.extend(kept.step_by(self.stride as usize));
    }
}

/// What [`deform`] did.
#[derive(Debug, Clone, Default, PartialEq)]
#[non_exhaustive]
pub struct DeformInfo {
    /// The cell complex's construction.
    pub build: BuildInfo,
    /// The solver.
    pub solver: SolverInfo,
    /// Seconds spent in the transfer (building it and applying it).
    pub seconds_transfer: f64,
    /// Seconds of the control points' leave-one-out check (not part of `seconds_transfer`).
    pub seconds_check: f64,
    /// Samples checked for fold-overs and how many of them the map folds over (Jacobian
    /// determinant not positive): at most [`FOLDOVER_SAMPLES`], evenly strided over the samples
    /// of [`deform`] or the proxy of [`deform_file`].
    pub foldovers: (usize, usize),
    /// The samples of [`deform`] the map folds over, among those checked: their indices, in
    /// order (what an editor shows). Empty for [`deform_file`], whose check is on its proxy.
    pub folded: Vec<usize>,
    /// The control points (`[[target]]` entries): where each went, its residual.
    pub control_points: Vec<ControlPoint>,
    /// What the control points' `got` was rounded to, as the output file stores its samples
    /// ([`deform_file`]: `"the output's scale 0.01"`); `None` where they are the field's values.
    pub control_rounding: Option<String>,
    /// Messages for the user.
    pub warnings: Vec<Said>,
    /// The options of the run, as given ([`Options::recorded`] in the report).
    pub options: Options,
}

impl DeformInfo {
    /// What a run did: the cells' construction, the solver, the transfer's seconds since
    /// `transfer_start` (less those of the control points' check), the fold-overs, the control
    /// points with the seconds of their check, and the warnings.
    fn of(
        params: &DeformParams,
        build: BuildInfo,
        solver: &SolverInfo,
        transfer_start: Instant,
        foldovers: (usize, usize),
        (control_points, seconds_check): (Vec<ControlPoint>, f64),
        warnings: Vec<Said>,
    ) -> Self {
        Self {
            build,
            solver: solver.clone(),
            seconds_transfer: transfer_start.elapsed().as_secs_f64() - seconds_check,
            seconds_check,
            foldovers,
            folded: Vec::new(),
            control_points,
            control_rounding: None,
            warnings,
            options: params.options,
        }
    }
}

/// Deforms `points` (with `triangles` over them, or none) under `spec`; returns the moved
/// points, the solution, and what was done.
pub fn deform<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    spec: &EditSpec<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(Vec<Vect<D>>, Solution<D>, DeformInfo)>
where
    Dim<D>: Rigid<D>,
{
    let (moved, _, solution, info) =
        deform_oriented(points, &[], triangles, &[], spec, params, observer)?;
    Ok((moved, solution, info))
}

/// [`deform`] of points with normals (one per point, or none) and LAS classes (one per point,
/// or none; what the spec's classification regions select): returns the moved points and
/// their normals as the map turns them (the transpose of the inverse Jacobian), each
/// with its length.
#[allow(clippy::type_complexity)]
pub fn deform_oriented<const D: usize>(
    points: &[Vect<D>],
    normals: &[Vect<D>],
    triangles: &[[u32; 3]],
    classes: &[u8],
    spec: &EditSpec<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(Vec<Vect<D>>, Vec<Vect<D>>, Solution<D>, DeformInfo)>
where
    Dim<D>: Rigid<D>,
{
    check_normals(points.len(), normals)?;
    let samples = Cells::Samples {
        points,
        triangles,
        classes: classes_of(points.len(), classes)?,
    };
    let staged = stages::run(samples, spec, params, observer)?;
    stages::transfer_samples(staged, (points, normals), spec, params, observer)
}

/// Refuses `normals` unless there is one for each of `points` samples, or none.
pub(crate) fn check_normals<const D: usize>(points: usize, normals: &[Vect<D>]) -> Result<()> {
    if !normals.is_empty() && normals.len() != points {
        return Err(Error::param(format!(
            "{} normals for {points} points: give one per point, or none",
            normals.len(),
        )));
    }
    Ok(())
}

/// The LAS classes of `samples` samples in memory, one each or none (`None`): a count that
/// is neither is refused.
fn classes_of(samples: usize, classes: &[u8]) -> Result<Option<&[u8]>> {
    match classes.len() {
        0 => Ok(None),
        n if n == samples => Ok(Some(classes)),
        n => Err(Error::param(format!(
            "{n} LAS classes for {samples} points: give one per point, or none"
        ))),
    }
}

/// `deform` of a 2D point set file (`.xy`, read whole): the points deformed in memory under the
/// 2D `spec`, written to `output` (which must be `.xy`) with every other byte as read.
/// Returns the solution, what was done and the number of points.
pub fn deform_xy_file(
    input: &Path,
    output: &Path,
    spec: &EditSpec<2>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(Solution<2>, DeformInfo, usize)> {
    if io::extension(output).as_deref() != Some("xy") {
        return Err(Error::param(format!(
            "{}: a .xy point set is written as .xy",
            output.display()
        )));
    }
    files::refuse_clobbering(&[input], &[("the output", output)])?;
    let file = io::XyFile::read(input)?;
    let (moved, solution, info) = deform(file.points(), &[], spec, params, observer)?;
    file.write(output, &moved)?;
    Ok((solution, info, moved.len()))
}

/// Moves samples in memory (and their `normals`, one each or none) through a solved field, as
/// `rigidcells apply` moves a file's: samples beyond the field's margin are refused unless
/// `outside` keeps or extends them; a coordinate that is not finite is refused. `name` names
/// the samples in errors. The Python package's `Field.apply`.
pub fn apply_points(
    saved: &SavedField<3>,
    points: &[Vect<3>],
    normals: &[Vect<3>],
    outside: Outside,
    name: &Path,
) -> Result<(Vec<Vect<3>>, Vec<Vect<3>>)> {
    if !points.is_empty() {
        crate::cells::bounds(points)?;
    }
    if !normals.is_empty() && normals.len() != points.len() {
        return Err(Error::param(format!(
            "{} normals for {} samples",
            normals.len(),
            points.len()
        )));
    }
    let deformer = saved.deformer_of(None, None, outside)?;
    let (mut moved, mut turned) = (Vec::new(), Vec::new());
    apply_into(
        &deformer,
        &saved.field.origin,
        points,
        normals,
        &mut moved,
        &mut turned,
    );
    let beyond = deformer.outside();
    if outside == Outside::Refuse && beyond.count > 0 {
        let margin = deformer.margin();
        return Err(Error::param(
            Said::from(format!(
                "{}: {} samples lie beyond the field's margin of {} (the farthest {} from it); \
                 pass ",
                name.display(),
                beyond.count,
                crate::human::length(margin, margin),
                crate::human::length(beyond.farthest, margin)
            ))
            .set(Opt::Outside, "keep")
            .text(" or ")
            .set(Opt::Outside, "extend")
            .text(", or solve a field over them"),
        ));
    }
    Ok((moved, turned))
}

/// Solves `spec` over samples in memory (with their LAS `classes`, one per point, or none)
/// and returns the field (with its transfer, and the RBF's coefficients when that is the
/// transfer), to apply to these or other samples, or to save: the Python package's `solve`.
/// The info's control points are as the field moves them.
pub fn solve_points(
    points: &[Vect<3>],
    triangles: &[[u32; 3]],
    classes: &[u8],
    spec: &EditSpec<3>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(SavedField<3>, Solution<3>, DeformInfo)> {
    let samples = Cells::Samples {
        points,
        triangles,
        classes: classes_of(points.len(), classes)?,
    };
    let Staged {
        solution,
        saved,
        build,
        warnings,
        transfer_start,
    } = stages::run(samples, spec, params, observer)?;
    // The map applied for the control points is made from the field and then taken apart
    // again: the RBF it factored is the field's, kept rather than factored twice.
    let field = saved.field.clone();
    let deformer = saved.deformer(None, params.rbf_tolerance, Outside::Extend)?;
    let controls = control_results(spec, &solution, &deformer, params, observer)?;
    let rbf = match deformer.into_inner() {
        Deformer::Rbf(r) => Some(r),
        _ => None,
    };
    let saved = SavedField::new(field, params.transfer, rbf);
    let info = DeformInfo::of(
        params,
        build,
        &solution.info,
        transfer_start,
        (0, 0),
        controls,
        warnings,
    );
    Ok((saved, solution, info))
}

/// What deforming `points` (with `triangles`, and their LAS `classes`, one per point or
/// none) under `spec` with `params` will take, without solving it ([`crate::estimate`]): the
/// cells are built and the spec resolved on them, the solve's stages are counted and priced,
/// not run. Its seconds are the whole run's: the build's as it took them, the solve's and the
/// transfer's as estimated. Cells that cannot fit the budget by any path are not built: the
/// estimate is then their forecast's least ([`crate::estimate::Estimate::floor`], `complete`
/// false), made in about the time the occupied cells take to find. What the Python package's
/// `estimate` returns; a caller compares [`crate::estimate::Estimate::fits`].
pub fn estimate(
    points: &[Vect<3>],
    triangles: &[[u32; 3]],
    classes: &[u8],
    spec: &EditSpec<3>,
    params: &DeformParams,
) -> Result<crate::estimate::Estimate> {
    let classes = classes_of(points.len(), classes)?;
    crate::solve::Selections::new(spec, classes.is_some(), points.len() as u64)?;
    let start = Instant::now();
    let seen = std::cell::Cell::new(None);
    let check = |forecast: &crate::cells::Forecast| {
        seen.set(Some(*forecast));
        params.check_forecast(forecast)
    };
    let built =
        crate::cells::build_checked(points, triangles, &params.build, params.memory, &check);
    let (complex, _) = match (built, seen.get()) {
        (Ok(built), _) => built,
        (Err(Error::Memory { .. }), Some(forecast)) => {
            let direct = params.solve.method == crate::solve::Method::Direct;
            return Ok(crate::estimate::Estimate::floor(
                &forecast,
                direct,
                params.memory,
            ));
        }
        (Err(e), _) => return Err(e),
    };
    // The stiffness as the run sets it: coarsening merges only cells of one stiffness.
    let selected = stages::Selected::Samples { points, classes };
    let constraints = stages::resolved(&complex, spec, selected, params)?;
    let (complex, constraints) = match params.solve.coarsen_levels {
        0 => (complex, constraints),
        levels => crate::solve::coarsen(&complex, &constraints, levels),
    };
    let mut estimate =
        crate::solve::forecast(&complex, &constraints, &params.solve, params.memory)?;
    if params.transfer == Transfer::Rbf {
        let rbf = crate::memory::rbf_bytes(complex.len(), 3);
        estimate.bytes = estimate.bytes.max(rbf as u64);
    }
    estimate.seconds += start.elapsed().as_secs_f64();
    Ok(estimate)
}
