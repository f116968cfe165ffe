//! The whole method on samples in memory: cells → constraints → solve → transfer.
//!
//! [`deform`] works on samples in memory; [`deform_file`] and [`apply_file`] stream files in
//! two passes and one (DESIGN §7).

use std::path::Path;
use std::sync::mpsc;
use std::time::Instant;

use crate::cells::{BuildInfo, BuildParams, CellComplex, Occupancy, build};
use crate::control::ControlPoint;
use crate::error::{Error, Result};
use crate::field::{
    Constrained, Deformer, Field, Outside, Rbf, SavedField, Transfer, Warp, apply, apply_into,
    count_foldovers,
};
use crate::io::{self, Accepted, Bounds, Chunk, Sink, Source};
use crate::progress::Observer;
use crate::rigid::{Dim, Rigid, Vect};
use crate::solve::Selections;
use crate::solve::{self, Solution, SolveParams, SolverInfo};
use crate::spec::EditSpec;

/// Parameters of [`deform`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DeformParams {
    /// The cell complex.
    pub build: BuildParams,
    /// The solver.
    pub solve: SolveParams,
    /// The transfer to the samples.
    pub transfer: Transfer,
    /// With the RBF transfer: evaluate positions through its far field, each coordinate
    /// within this length of the exact sum's ([`crate::field::Rbf::with_tolerance`]).
    pub rbf_tolerance: Option<f64>,
    /// The most samples in the preview proxy of [`deform_file`] (`None`: [`PROXY_SAMPLES`];
    /// `Some(0)`: no proxy).
    pub proxy_samples: Option<usize>,
    /// Run the control points' leave-one-out check ([`crate::control::leave_one_out`]).
    pub check_control_points: bool,
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
    /// The control points (`[[target]]` entries): where each went, its residual.
    pub control_points: Vec<ControlPoint>,
    /// Messages for the user.
    pub warnings: Vec<String>,
}

/// The control points of `spec` in `solution` as `warp` moves them, with the leave-one-out
/// check when `params` asks for it, and the seconds that check took (a stage of its own: one
/// solve per control point).
fn control_results<const D: usize>(
    spec: &EditSpec<D>,
    solution: &Solution<D>,
    warp: &impl Warp<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(Vec<ControlPoint>, f64)>
where
    Dim<D>: Rigid<D>,
{
    let mut got = crate::control::from_points(solution);
    apply(warp, &solution.constraints.origin, &mut got);
    let mut points = crate::control::control_points(spec, solution, &got);
    if !params.check_control_points {
        return Ok((points, 0.0));
    }
    let start = Instant::now();
    crate::control::leave_one_out(spec, solution, &params.solve, &mut points, observer)?;
    Ok((points, start.elapsed().as_secs_f64()))
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
        deform_oriented(points, &[], triangles, spec, params, observer)?;
    Ok((moved, solution, info))
}

/// [`deform`] of points with normals (one per point, or none): returns the moved points and
/// their normals as the map turns them (the transpose of the inverse Jacobian, DESIGN §6), each
/// with its length.
#[allow(clippy::type_complexity)]
pub fn deform_oriented<const D: usize>(
    points: &[Vect<D>],
    normals: &[Vect<D>],
    triangles: &[[u32; 3]],
    spec: &EditSpec<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(Vec<Vect<D>>, Vec<Vect<D>>, Solution<D>, DeformInfo)>
where
    Dim<D>: Rigid<D>,
{
    if !normals.is_empty() && normals.len() != points.len() {
        return Err(Error::Param(format!(
            "{} normals for {} points: give one per point, or none",
            normals.len(),
            points.len()
        )));
    }
    let Staged {
        solution,
        field,
        deformer,
        build: build_info,
        mut warnings,
        transfer_start: t,
    } = stages(points, triangles, spec, params, observer)?;
    let (mut moved, mut moved_normals) = (Vec::new(), Vec::new());
    apply_into(
        &deformer,
        &field.origin,
        points,
        normals,
        &mut moved,
        &mut moved_normals,
    );
    check_moved(0, &moved)?;
    let foldovers = check_foldovers(&deformer, &solution, points, &mut warnings);
    let (control_points, seconds_check) =
        control_results(spec, &solution, &deformer, params, observer)?;
    let info = DeformInfo {
        build: build_info,
        solver: solution.info.clone(),
        seconds_transfer: t.elapsed().as_secs_f64() - seconds_check,
        seconds_check,
        foldovers,
        control_points,
        warnings,
    };
    Ok((moved, moved_normals, solution, info))
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
        return Err(Error::Param(format!(
            "{}: a .xy point set is written as .xy",
            output.display()
        )));
    }
    let file = io::XyFile::read(input)?;
    let (moved, solution, info) = deform(file.points(), &[], spec, params, observer)?;
    file.write(output, &moved)?;
    Ok((solution, info, moved.len()))
}

/// Solves `spec` over samples in memory and returns the field (with its transfer, and the
/// RBF's coefficients when that is the transfer), to apply to these or other samples, or to
/// save: the Python package's `solve`. The info's control points are as the field moves them.
pub fn solve_points(
    points: &[Vect<3>],
    triangles: &[[u32; 3]],
    spec: &EditSpec<3>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(SavedField<3>, Solution<3>, DeformInfo)> {
    let Staged {
        solution,
        field,
        deformer,
        build,
        warnings,
        transfer_start,
    } = stages(points, triangles, spec, params, observer)?;
    let (control_points, seconds_check) =
        control_results(spec, &solution, &deformer, params, observer)?;
    // The RBF the transfer factorized is the field's: kept, not factorized again.
    let rbf = match deformer.into_inner() {
        Deformer::Rbf(r) => Some(r),
        _ => None,
    };
    let info = DeformInfo {
        build,
        solver: solution.info.clone(),
        seconds_transfer: transfer_start.elapsed().as_secs_f64() - seconds_check,
        seconds_check,
        foldovers: (0, 0),
        control_points,
        warnings,
    };
    Ok((SavedField::new(field, params.transfer, rbf), solution, info))
}

/// What [`stages`] gives.
pub(crate) struct Staged<const D: usize> {
    pub(crate) solution: Solution<D>,
    pub(crate) field: Field<D>,
    pub(crate) deformer: Constrained<D>,
    pub(crate) build: BuildInfo,
    pub(crate) warnings: Vec<String>,
    pub(crate) transfer_start: Instant,
}

/// The method's stage sequence on samples in memory, written once: the cells of `points` (and
/// `triangles`), the spec resolved onto them, the solve, the field and its transfer with exact
/// constraints. [`deform`] applies it to the samples; [`crate::image::deform_image`] to the
/// corners of a picture's pixels. (The streaming [`deform_file`] builds its cells in pass 1
/// and shares [`solve_source`].)
pub(crate) fn stages<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    spec: &EditSpec<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<Staged<D>>
where
    Dim<D>: Rigid<D>,
{
    let (complex, build_info) = build(points, triangles, &params.build)?;
    let constraints = solve::resolve(&complex, spec, points, None)?;
    check_rbf_memory::<D>(complex.len(), params)?;
    let solution = solve::solve(complex, constraints, &params.solve, observer)?;
    // The solved constraints' warnings: an adaptive solve decides its parts at rest again.
    let mut warnings = build_warnings(
        &build_info,
        &solution.complex,
        &solution.constraints.warnings,
    );
    warnings.extend(solution.info.warnings());
    let transfer_start = Instant::now();
    let (field, deformer) = transfer_of(&solution, params)?;
    Ok(Staged {
        solution,
        field,
        deformer,
        build: build_info,
        warnings,
        transfer_start,
    })
}

/// The field of `solution` and its transfer (`params.transfer`) with exact constraints, for
/// samples in memory (extrapolated outside the cells, as [`deform`] does).
pub fn transfer_of<const D: usize>(
    solution: &Solution<D>,
    params: &DeformParams,
) -> Result<(Field<D>, Constrained<D>)>
where
    Dim<D>: Rigid<D>,
{
    check_rbf_memory::<D>(solution.complex.len(), params)?;
    let field = Field::from_solution(solution);
    let inner = Deformer::new(&field, params.transfer)?.with_rbf_tolerance(params.rbf_tolerance)?;
    let deformer = Constrained::new(&field, inner, Outside::Extend)?;
    Ok((field, deformer))
}

/// [`crate::memory::check`] of the dense RBF of `cells` cells, when that is the transfer:
/// checked before the solve, and again after refinement, so that neither ends in an abort.
pub(crate) fn check_rbf_memory<const D: usize>(cells: usize, params: &DeformParams) -> Result<()> {
    if params.transfer != Transfer::Rbf {
        return Ok(());
    }
    crate::memory::check(
        &format!("the RBF transfer of {cells} cells"),
        crate::memory::rbf_bytes(cells, D),
        crate::memory::limit(params.build.memory_limit),
        "use --transfer pu (the default) or blend, or a larger --cell-size (or fewer --cells)",
    )
}

/// Samples checked for fold-overs at most: evenly strided, as the check costs a few warps (or
/// one Jacobian) per sample.
pub const FOLDOVER_SAMPLES: usize = 100_000;

/// Counts the fold-overs of `warp` at up to [`FOLDOVER_SAMPLES`] of the world-coordinate
/// `samples` (every k-th), with central differences of a tenth of the finest cell, and warns
/// when there are any. Returns `(checked, folded)`.
///
/// Why a tenth: the blend is continuous but not smooth. Its weights have kinks where neighbor
/// sets change, and at points equidistant from five or more centers (the corners of a regular
/// lattice of cells) the normalized weights depend on the direction of approach, so the map
/// steps by up to the cells' misfit there. With a thousandth of a cell those steps read as huge
/// derivatives: 326 of the 2,690 vertices of the demo bar, all on cell corners, "folded" under
/// a plain lift. Space folds over at the scale of cells, which a tenth of one resolves.
pub fn check_foldovers<const D: usize>(
    warp: &impl Warp<D>,
    solution: &Solution<D>,
    samples: &[Vect<D>],
    warnings: &mut Vec<String>,
) -> (usize, usize) {
    let stride = samples.len().div_ceil(FOLDOVER_SAMPLES).max(1);
    let checked: Vec<Vect<D>> = samples.iter().step_by(stride).copied().collect();
    let h = 0.1 * solution.complex.grid.finest_size();
    let folded = count_foldovers(warp, &solution.complex.grid.origin, &checked, h);
    if folded > 0 {
        warnings.push(format!(
            "the deformation folds space over at {folded} of {} samples checked (the Jacobian \
             determinant is not positive there): the shape passes through itself; a smaller \
             edit, more load steps or stiffer cells avoid it",
            checked.len()
        ));
    }
    (checked.len(), folded)
}

/// The warnings of the cell construction followed by those of the constraints.
fn build_warnings<const D: usize>(
    build: &BuildInfo,
    complex: &CellComplex<D>,
    constraints: &[String],
) -> Vec<String> {
    let mut out = Vec::new();
    if build.glued_cells > 0 {
        let size = complex.grid.finest_size();
        let decimals = (5 - size.log10().floor() as i32).max(0) as usize;
        out.push(format!(
            "{} cells hold parts of the mesh that are not connected but lie closer than the finest \
             cell size ({size:.decimals$}): the parts move together there; a smaller --cell-size \
             keeps them apart",
            build.glued_cells,
        ));
    }
    out.extend_from_slice(constraints);
    out
}

/// Samples per streamed chunk by default: measured on a 20M-point LAS, 64k-sample chunks ran
/// 3.8 s against 6.5 s for 1M (the chunk in flight stays in cache) and LAZ was the same either
/// way, with a peak RSS of 45 MB instead of 370 MB.
pub const CHUNK: usize = 1 << 16;

/// What [`deform_file`] and [`apply_file`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FileInfo {
    /// Samples read and written.
    pub samples: u64,
    /// Cells, solve and transfer (empty for [`apply_file`]).
    pub deform: DeformInfo,
    /// Notes on the output (moved offsets, dropped indices, header fixes).
    pub notes: Vec<String>,
    /// Seconds of the first pass (bounds, occupancy, selections).
    pub seconds_read: f64,
    /// Seconds of the second pass (transfer and writing).
    pub seconds_write: f64,
    /// The preview proxy (empty for [`apply_file`], or when none was asked for).
    pub proxy: Proxy,
    /// Samples beyond the field's margin (kept or extended as [`ApplyParams::outside`] says;
    /// for [`deform_file`], extended, and said in a note).
    pub outside: u64,
}

/// Parameters of [`apply_file`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ApplyParams {
    /// The transfer (`None`: the one the field was saved with).
    pub transfer: Option<Transfer>,
    /// With the RBF transfer: the far field's tolerance ([`DeformParams::rbf_tolerance`]).
    pub rbf_tolerance: Option<f64>,
    /// What happens to samples beyond the field's margin (default: refused).
    pub outside: Outside,
    /// The memory budget in bytes ([`crate::memory`]), for an RBF that must be factored.
    pub memory_limit: Option<u64>,
}

/// Deforms the file `input` into `output` in two streaming passes (DESIGN §7): pass 1 builds
/// the cells from occupancy and gathers what the spec's regions select, never holding all
/// samples (meshes excepted: their triangles need the vertices); the solve runs on the cells;
/// pass 2 streams chunks of `chunk` samples through the field, in file order, into the output.
/// With `save_field`, the solved field (with its transfer, and the RBF's coefficients when that
/// is the transfer) is written there too; [`apply_file`] with it writes the same bytes.
pub fn deform_file(
    input: &Path,
    output: &Path,
    spec: &EditSpec<3>,
    params: &DeformParams,
    chunk: usize,
    save_field: Option<&Path>,
    observer: &dyn Observer,
) -> Result<(Solution<3>, FileInfo)> {
    let mut source = io::open(input)?;
    let mut info = FileInfo::default();
    let Solved {
        solution,
        saved,
        build: build_info,
        proxy,
        mut warnings,
        transfer_start: t1,
    } = solve_source(
        source.as_mut(),
        spec,
        params,
        chunk,
        save_field,
        &mut info,
        observer,
    )?;
    // The field is written before the output; should the output fail, the field goes too (a
    // run that fails leaves no file under any name it was given).
    let mut saved_guard = RemoveOnDrop(save_field);
    let origin = saved.field.origin;
    // Every sample made the cells, so none lies beyond the margin.
    let deformer = saved.deformer(None, params.rbf_tolerance, Outside::Extend)?;
    observer.stage("checking", 0);
    let mut after = proxy.before.clone();
    apply(&deformer, &origin, &mut after);
    let triangles = if proxy.stride == 1 && proxy.before.len() as u64 == source.len() {
        source.triangles().to_vec()
    } else {
        Vec::new()
    };
    info.proxy = Proxy {
        after,
        triangles,
        ..proxy
    };
    let foldovers = check_foldovers(&deformer, &solution, &info.proxy.before, &mut warnings);
    observer.finish();
    let (control_points, seconds_check) =
        control_results(spec, &solution, &deformer, params, observer)?;
    let t2 = Instant::now();
    info.notes.extend(transfer_pass(
        source.as_mut(),
        output,
        &deformer,
        &origin,
        chunk,
        observer,
    )?);
    // Every sample made the cells; one beyond their margin would be extrapolated, so say so.
    let outside = deformer.outside().count;
    if outside > 0 {
        info.notes.push(format!(
            "{outside} samples lay beyond the cells' margin ({}) and were moved by the transfer \
             extended there",
            crate::human::length(deformer.margin(), deformer.margin())
        ));
    }
    info.outside = outside;
    info.seconds_write = t2.elapsed().as_secs_f64();
    info.deform = DeformInfo {
        build: build_info,
        solver: solution.info.clone(),
        seconds_transfer: t1.elapsed().as_secs_f64() - seconds_check,
        seconds_check,
        foldovers,
        control_points,
        warnings,
    };
    saved_guard.0 = None;
    Ok((solution, info))
}

/// What [`solve_source`] gives: the solution, its field (saved where asked), the cells'
/// construction, the proxy of pass 1 and the warnings so far.
struct Solved {
    solution: Solution<3>,
    saved: SavedField<3>,
    build: BuildInfo,
    proxy: Proxy,
    warnings: Vec<String>,
    /// When the field's construction began (after the solve): the start of the transfer's time.
    transfer_start: Instant,
}

/// Pass 1 over `source`, the constraints, the solve and the field (with the RBF's factorization
/// when that is the transfer), saved to `save_field` when given: what [`deform_file`] does
/// before its transfer pass, and all that [`solve_files`] does. Fills `info`'s samples, notes
/// and read time.
fn solve_source(
    source: &mut dyn Source,
    spec: &EditSpec<3>,
    params: &DeformParams,
    chunk: usize,
    save_field: Option<&Path>,
    info: &mut FileInfo,
    observer: &dyn Observer,
) -> Result<Solved> {
    let t0 = Instant::now();
    info.samples = source.len();
    let proxy_max = params.proxy_samples.unwrap_or(PROXY_SAMPLES);
    let (complex, build, selections, proxy) = first_pass_cells(
        source,
        spec,
        &params.build,
        chunk,
        proxy_max,
        &mut info.notes,
        observer,
    )?;
    info.seconds_read = t0.elapsed().as_secs_f64();
    let constraints = solve::resolve_selected(&complex, spec, &selections)?;
    check_rbf_memory::<3>(complex.len(), params)?;
    let solution = solve::solve(complex, constraints, &params.solve, observer)?;
    let mut warnings = build_warnings(&build, &solution.complex, &solution.constraints.warnings);
    warnings.extend(solution.info.warnings());
    check_rbf_memory::<3>(solution.complex.len(), params)?;
    let transfer_start = Instant::now();
    let field = Field::from_solution(&solution);
    observer.stage("factoring", 0);
    let rbf = match params.transfer {
        Transfer::Rbf => Some(Rbf::new(&field)?),
        _ => None,
    };
    let saved = SavedField::new(field, params.transfer, rbf);
    observer.finish();
    if let Some(path) = save_field {
        saved.save(path)?;
    }
    Ok(Solved {
        solution,
        saved,
        build,
        proxy,
        warnings,
        transfer_start,
    })
}

/// Solves `spec` over the files `inputs` taken as one (the tiles of a scan; pass 1 reads every
/// one, [`Tiles`](crate::io::Tiles)) and writes only the field, to `save_field`; `apply` then
/// deforms each tile on its own. The cells, and so the field, are those [`deform_file`] builds
/// for the tiles merged in this order: each tile's `apply` writes, record for record, what
/// `deform` writes for the merged file (with the union of the tiles' header bounds as its own).
/// `info.deform.control_points` holds the control points as the field moves them.
pub fn solve_files(
    inputs: &[std::path::PathBuf],
    spec: &EditSpec<3>,
    params: &DeformParams,
    chunk: usize,
    save_field: &Path,
    observer: &dyn Observer,
) -> Result<(Solution<3>, FileInfo)> {
    let mut tiles = io::Tiles::open(inputs)?;
    let mut info = FileInfo::default();
    let params = DeformParams {
        proxy_samples: Some(0),
        ..*params
    };
    let solved = solve_source(
        &mut tiles,
        spec,
        &params,
        chunk,
        Some(save_field),
        &mut info,
        observer,
    )?;
    let mut guard = RemoveOnDrop(Some(save_field));
    let deformer = solved
        .saved
        .deformer(None, params.rbf_tolerance, Outside::Extend)?;
    let (control_points, seconds_check) =
        control_results(spec, &solved.solution, &deformer, &params, observer)?;
    info.deform = DeformInfo {
        build: solved.build,
        solver: solved.solution.info.clone(),
        seconds_transfer: solved.transfer_start.elapsed().as_secs_f64() - seconds_check,
        seconds_check,
        foldovers: (0, 0),
        control_points,
        warnings: solved.warnings,
    };
    guard.0 = None;
    Ok((solved.solution, info))
}

/// Removes the file it names when dropped, unless disarmed (`.0 = None`).
struct RemoveOnDrop<'a>(Option<&'a Path>);

impl Drop for RemoveOnDrop<'_> {
    fn drop(&mut self) {
        if let Some(path) = self.0 {
            let _ = std::fs::remove_file(path);
        }
    }
}

/// Applies the field saved in `field` to the file `input`, writing `output` (one streaming
/// pass). Samples beyond the field's margin are refused by default ([`Error::Outside`], and
/// nothing is written), or kept or extended as `params.outside` says. With the PU transfer and
/// an input whose header gives its bounds (LAS/LAZ), only the part of the field those bounds
/// need is read ([`SavedField::load_window`]; not with `--outside extend`, whose samples beyond
/// the margin follow the nearest patch of the whole field); should a sample lie outside them,
/// the pass runs again with the whole field.
pub fn apply_file(
    field: &Path,
    input: &Path,
    output: &Path,
    params: &ApplyParams,
    chunk: usize,
    observer: &dyn Observer,
) -> Result<FileInfo> {
    let mut source = io::open(input)?;
    // Beyond the margin, `--outside extend` takes the nearest patch of the whole field.
    let hint = match (params.transfer, params.outside) {
        (_, Outside::Extend) => None,
        (None | Some(Transfer::Pu), _) => source.bounds_hint(),
        _ => None,
    };
    let saved = match hint {
        Some(bounds) => SavedField::<3>::load_window(field, bounds)?,
        None => SavedField::<3>::load(field)?,
    };
    if params.rbf_tolerance.is_some() && params.transfer.unwrap_or(saved.transfer) != Transfer::Rbf
    {
        return Err(Error::Param(format!(
            "--rbf-tolerance applies to the RBF transfer only, and {} was saved for another; \
             add --transfer rbf",
            field.display()
        )));
    }
    let windowed = saved.is_window();
    let info = apply_saved(saved, source.as_mut(), output, params, chunk, observer)?;
    match info {
        Applied::Done(info) => Ok(*info),
        Applied::BeyondWindow(count) => {
            let whole = SavedField::<3>::load(field)?;
            debug_assert!(windowed);
            match apply_saved(whole, source.as_mut(), output, params, chunk, observer)? {
                Applied::Done(mut info) => {
                    info.notes.push(format!(
                        "{count} samples lay outside the bounds in {}'s header; the whole \
                         field was read",
                        input.display()
                    ));
                    Ok(*info)
                }
                Applied::BeyondWindow(_) => Err(Error::Solver(
                    "a whole field reported samples outside its window".into(),
                )),
            }
        }
    }
}

/// What [`apply_saved`] did: applied the field, or met samples outside the window of the
/// field it was given (how many), whose results are not the whole field's.
enum Applied {
    Done(Box<FileInfo>),
    BeyondWindow(usize),
}

fn apply_saved(
    field: SavedField<3>,
    source: &mut dyn Source,
    output: &Path,
    params: &ApplyParams,
    chunk: usize,
    observer: &dyn Observer,
) -> Result<Applied> {
    let t = Instant::now();
    let origin = field.field.origin;
    if params.transfer == Some(Transfer::Rbf) && !field.has_rbf() {
        crate::memory::check(
            &format!("the RBF transfer of {} cells", field.field.centers.len()),
            crate::memory::rbf_bytes(field.field.centers.len(), 3),
            crate::memory::limit(params.memory_limit),
            "apply the field with the transfer it was saved with (no --transfer rbf)",
        )?;
    }
    observer.stage("transfer", 0);
    let deformer = field.tile_deformer(params.transfer, params.rbf_tolerance, params.outside)?;
    observer.finish();
    let mut notes = transfer_pass(source, output, &deformer, &origin, chunk, observer)?;
    if deformer.beyond_window() > 0 {
        return Ok(Applied::BeyondWindow(deformer.beyond_window()));
    }
    if let Deformer::Pu(pu) = deformer.inner() {
        let (made, all, failed) = pu.fits();
        notes.push(format!(
            "the PU transfer fitted {made} of its {all} patches (those the samples reached)"
        ));
        if failed > 0 {
            notes.push(format!(
                "{failed} of the PU's patch fits failed; the samples there were blended from \
                 the patches around them"
            ));
        }
    }
    let outside = deformer.outside().count;
    let margin = crate::human::length(deformer.margin(), deformer.margin());
    match params.outside {
        Outside::Keep if outside > 0 => notes.push(format!(
            "{outside} samples beyond the field's margin ({margin}) kept their coordinates"
        )),
        Outside::Extend if outside > 0 => notes.push(format!(
            "{outside} samples beyond the field's margin ({margin}) were moved by the \
             transfer extended there"
        )),
        _ => {}
    }
    Ok(Applied::Done(Box::new(FileInfo {
        samples: source.len(),
        notes,
        seconds_write: t.elapsed().as_secs_f64(),
        outside,
        ..Default::default()
    })))
}

/// Pass 1 of [`deform_file`]: the cell complex of `source` (rerunning the pass with the
/// samples' own bounds when they overflow the header's) and what the spec's regions select.
fn first_pass_cells(
    source: &mut dyn Source,
    spec: &EditSpec<3>,
    build: &BuildParams,
    chunk: usize,
    proxy_max: usize,
    notes: &mut Vec<String>,
    observer: &dyn Observer,
) -> Result<(CellComplex<3>, BuildInfo, Selections<3>, Proxy)> {
    let (lo, hi) = match source.bounds_hint() {
        Some(b) => b,
        None => scan_bounds(source, chunk)?,
    };
    let sized;
    let target = build.target_cells;
    let build = match target {
        Some(n) => {
            observer.stage("sizing", 0);
            let size = proxy_cell_size(source, build, (lo, hi), n, chunk)?;
            observer.finish();
            notes.push(format!(
                "--cells {n}: finest cell size {}",
                crate::human::length(size, size)
            ));
            sized = BuildParams {
                cell_size: Some(size),
                target_cells: None,
                ..*build
            };
            &sized
        }
        None => build,
    };
    let mut pass = first_pass(source, spec, build, (lo, hi), chunk, proxy_max, observer)?;
    if pass.outside > 0 {
        notes.push(format!(
            "{} samples lie outside the bounds in the file's header; the cells use the samples' own bounds",
            pass.outside
        ));
        let b = pass.bounds;
        pass = first_pass(source, spec, build, b, chunk, proxy_max, observer)?;
    }
    let FirstPass {
        mut occupancy,
        selections,
        positions,
        proxy,
        ..
    } = pass;
    observer.stage("voxelizing", 0);
    occupancy.add_triangles(&positions, source.triangles())?;
    drop(positions);
    let (complex, build_info) = occupancy.finish()?;
    observer.finish();
    if let Some(n) = target
        && complex.len().saturating_mul(2) < n
    {
        notes.push(format!(
            "--cells {n}: the shape gives only {} cells at the finest size searched (too few \
             samples, or too thin, to fill more)",
            complex.len()
        ));
    }
    Ok((complex, build_info, selections, proxy))
}

/// Voxels per longest extent of the decimated proxy that [`proxy_cell_size`] bisects on.
const PROXY_RESOLUTION: f64 = 1024.0;

/// The finest cell size giving about `target` cells for `source`, found on a proxy gathered in
/// one extra pass: meshes keep their vertices (their triangles need them), point clouds are
/// decimated to one sample per occupied voxel of 1/1024 of the longest extent.
fn proxy_cell_size(
    source: &mut dyn Source,
    build: &BuildParams,
    (lo, hi): Bounds,
    target: usize,
    chunk_len: usize,
) -> Result<f64> {
    crate::cells::check_target(target, build.memory_limit)?;
    source.rewind()?;
    let voxel = (hi - lo).max().max(f64::MIN_POSITIVE) / PROXY_RESOLUTION;
    let keep_all = !source.triangles().is_empty();
    let mut proxy = Vec::new();
    let mut seen = std::collections::HashSet::new();
    let mut chunk = Chunk::default();
    while source.read_samples(chunk_len, &mut chunk)? > 0 {
        check_finite(source.path(), &chunk)?;
        for p in &chunk.positions {
            let key = ((p - lo) / voxel).map(|v| v.floor() as i64);
            if keep_all || seen.insert((key[0], key[1], key[2])) {
                proxy.push(*p);
            }
        }
    }
    crate::cells::cell_size_for(&proxy, source.triangles(), build, target)
}

/// The cell complex of the file `input` (pass 1 of [`deform_file`]) and, with a `spec`, its
/// solution: for inspecting the cells (`rigidcells cells`).
pub fn file_cells(
    input: &Path,
    spec: Option<&EditSpec<3>>,
    params: &DeformParams,
    chunk: usize,
    observer: &dyn Observer,
) -> Result<(CellComplex<3>, BuildInfo, Option<Solution<3>>, Vec<String>)> {
    let mut source = io::open(input)?;
    let empty = EditSpec::default();
    let mut notes = Vec::new();
    let (complex, info, selections, _) = first_pass_cells(
        source.as_mut(),
        spec.unwrap_or(&empty),
        &params.build,
        chunk,
        0,
        &mut notes,
        observer,
    )?;
    let mut warnings = build_warnings(&info, &complex, &[]);
    warnings.extend(notes);
    let Some(spec) = spec else {
        return Ok((complex, info, None, warnings));
    };
    let constraints = solve::resolve_selected(&complex, spec, &selections)?;
    warnings.extend(constraints.warnings.iter().cloned());
    let solution = solve::solve(complex.clone(), constraints, &params.solve, observer)?;
    warnings.extend(solution.info.warnings());
    Ok((complex, info, Some(solution), warnings))
}

/// Writes the cells of [`file_cells`] as a PLY of boxes ([`crate::cells::write_cells_ply`]):
/// `complex` at rest, or, with a `solution`, its cells in their solved pose colored by strain,
/// with their roles; `up` is the vertical axis the header names.
pub fn write_cells(
    path: &Path,
    complex: &CellComplex<3>,
    solution: Option<&Solution<3>>,
    up: usize,
) -> Result<()> {
    let Some(s) = solution else {
        return crate::cells::write_cells_ply(path, complex, None, up);
    };
    let roles: Vec<u8> = s.constraints.roles.iter().map(|r| r.code()).collect();
    let strain = solve::cell_strain(&s.complex, &s.motions);
    let pose = crate::cells::Pose {
        motions: &s.motions,
        roles: &roles,
        strain: &strain,
    };
    crate::cells::write_cells_ply(path, &s.complex, Some(pose), up)
}

struct FirstPass {
    occupancy: Occupancy<3>,
    selections: Selections<3>,
    /// All positions, kept only when the source has triangles.
    positions: Vec<Vect<3>>,
    /// The decimated samples (none when its bound is 0).
    proxy: Proxy,
    bounds: Bounds,
    outside: usize,
}

/// Checks that every coordinate of a chunk is finite.
fn check_finite(path: &Path, chunk: &Chunk) -> Result<()> {
    match chunk
        .positions
        .iter()
        .position(|p| !p.iter().all(|v| v.is_finite()))
    {
        Some(i) => Err(Error::format(
            path,
            format!(
                "sample {} has a coordinate that is not a finite number",
                chunk.first + i as u64
            ),
        )),
        None => Ok(()),
    }
}

fn scan_bounds(source: &mut dyn Source, chunk_len: usize) -> Result<Bounds> {
    source.rewind()?;
    let mut chunk = Chunk::default();
    let mut lo = Vect::<3>::repeat(f64::INFINITY);
    let mut hi = Vect::<3>::repeat(f64::NEG_INFINITY);
    while source.read_samples(chunk_len, &mut chunk)? > 0 {
        check_finite(source.path(), &chunk)?;
        for p in &chunk.positions {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
    }
    if lo[0] > hi[0] {
        return Err(Error::format(source.path(), "the file holds no samples"));
    }
    Ok((lo, hi))
}

fn first_pass(
    source: &mut dyn Source,
    spec: &EditSpec<3>,
    build: &BuildParams,
    (lo, hi): Bounds,
    chunk_len: usize,
    proxy_max: usize,
    observer: &dyn Observer,
) -> Result<FirstPass> {
    source.rewind()?;
    let mut occupancy = Occupancy::new(&lo, &hi, build)?;
    let mut selections = Selections::new(spec, source.has_classes())?;
    let keep = !source.triangles().is_empty();
    let mut positions = Vec::new();
    let mut proxy = (proxy_max > 0).then(|| Proxy::new(source.len(), proxy_max));
    let mut bounds = (
        Vect::<3>::repeat(f64::INFINITY),
        Vect::<3>::repeat(f64::NEG_INFINITY),
    );
    let mut outside = 0;
    let mut chunk = Chunk::default();
    observer.stage("reading", source.len());
    while source.read_samples(chunk_len, &mut chunk)? > 0 {
        check_finite(source.path(), &chunk)?;
        for p in &chunk.positions {
            bounds.0 = bounds.0.inf(p);
            bounds.1 = bounds.1.sup(p);
        }
        outside += if chunk.normals.is_empty() {
            occupancy.add_points(&chunk.positions)?
        } else {
            occupancy.add_oriented_points(&chunk.positions, &chunk.normals)?
        };
        let classes = (!chunk.classes.is_empty()).then_some(&chunk.classes[..]);
        selections.add(
            spec,
            occupancy.grid(),
            chunk.first,
            &chunk.positions,
            classes,
        );
        if keep {
            positions.extend_from_slice(&chunk.positions);
        }
        if let Some(proxy) = proxy.as_mut() {
            proxy.gather(&chunk);
        }
        observer.advance(chunk.len() as u64);
    }
    observer.finish();
    Ok(FirstPass {
        occupancy,
        selections,
        positions,
        proxy: proxy.unwrap_or_default(),
        bounds,
        outside,
    })
}

/// Buffers of one chunk on its way through pass 2.
#[derive(Default)]
struct Job {
    chunk: Chunk,
    moved: Vec<Vect<3>>,
    normals: Vec<Vect<3>>,
}

/// Chunks in flight in pass 2: one being read and warped, one queued, one being written.
const IN_FLIGHT: usize = 3;

/// Pass 2: streams the source through `warp` into `output`. A sink that refuses a chunk
/// ([`Accepted`]) is dropped, with its temporary file, and the pass runs again with a sink made
/// for what the refusal showed: after an overflow of the output's encoding the pass first
/// finishes computing the moved bounds. Each refusal is allowed once: a sink framed for the
/// moved bounds fits them, and a source that has seen the records makes a header for them.
/// Samples beyond the field's margin, when `warp` refuses them, fail the pass before the output
/// is renamed into place.
fn transfer_pass(
    source: &mut dyn Source,
    output: &Path,
    warp: &Constrained<3>,
    origin: &Vect<3>,
    chunk_len: usize,
    observer: &dyn Observer,
) -> Result<Vec<String>> {
    let mut bounds = None;
    let mut restarted = false;
    loop {
        source.rewind()?;
        warp.reset_outside();
        let sink = source.sink(output, bounds)?;
        let (pass, moved_bounds) = pipelined_pass(source, sink, warp, origin, chunk_len, observer)?;
        match pass {
            Pass::Refused(Accepted::Overflow) if bounds.is_none() => bounds = Some(moved_bounds),
            Pass::Refused(Accepted::Restart) if !restarted => restarted = true,
            Pass::Refused(refusal) => {
                return Err(Error::Solver(format!(
                    "{}: the output's writer refused the samples twice ({refusal:?})",
                    output.display()
                )));
            }
            Pass::Written(mut s) => {
                if warp.beyond_window() > 0 {
                    // A window of the field met samples outside it: the caller reads the whole
                    // field and starts again; the abandoned output is removed.
                    return Ok(Vec::new());
                }
                refuse_outside(source.path(), warp)?;
                let loose: Vec<Vect<3>> = source
                    .loose_normals()
                    .iter()
                    .map(|(at, n)| warp.warp_normal(&(at - origin), n))
                    .collect();
                s.loose_normals(loose);
                // Finishing may be long (a COPC sorts and compresses every point there).
                observer.stage("finishing", 0);
                let finished = s.finish();
                observer.finish();
                return finished;
            }
        }
    }
}

/// How one attempt of pass 2 ended.
enum Pass {
    /// Every chunk went into the sink, to be finished.
    Written(Box<dyn Sink>),
    /// The sink refused a chunk (and was dropped).
    Refused(Accepted),
}

/// [`Error::Outside`] when `warp` refuses samples beyond its margin and met some.
fn refuse_outside(input: &Path, warp: &Constrained<3>) -> Result<()> {
    let tally = warp.outside();
    if warp.outside_policy() != Outside::Refuse || tally.count == 0 {
        return Ok(());
    }
    Err(Error::Outside {
        path: input.to_path_buf(),
        count: tally.count,
        margin: warp.margin(),
        farthest: tally.farthest,
        at: crate::human::point(
            (tally.at + warp.origin()).as_slice(),
            warp.margin() / 1000.0,
        ),
    })
}

/// Refuses a transfer's result that is not finite, before it is written: the last guard
/// against writing NaN (the solve, the spec and field files are checked before; a field whose
/// RBF frame was damaged to 5e-324 reached the output as NaN).
pub(crate) fn check_moved<const D: usize>(first: u64, moved: &[Vect<D>]) -> Result<()> {
    match moved.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        Some(i) => Err(Error::Solver(format!(
            "the transfer moved sample {} to a position that is not finite",
            first + i as u64
        ))),
        None => Ok(()),
    }
}

/// Reads and warps chunks on this thread while a second thread writes the previous ones, so
/// the sink's encoding, compression and system calls overlap the transfer. Returns how the
/// sink took the chunks and the moved bounds: of every sample, also after an overflow (the
/// reader goes on), but not after a [`Accepted::Restart`] (the reader stops).
fn pipelined_pass(
    source: &mut dyn Source,
    sink: Box<dyn Sink>,
    warp: &impl Warp<3>,
    origin: &Vect<3>,
    chunk_len: usize,
    observer: &dyn Observer,
) -> Result<(Pass, Bounds)> {
    let mut moved_bounds = (
        Vect::<3>::repeat(f64::INFINITY),
        Vect::<3>::repeat(f64::NEG_INFINITY),
    );
    observer.stage("writing", source.len());
    let raw = sink.needs_raw();
    let pass = std::thread::scope(|scope| -> Result<Pass> {
        let (full, queued) = mpsc::sync_channel::<Job>(1);
        let (done, empty) = mpsc::channel::<Job>();
        for _ in 0..IN_FLIGHT {
            done.send(Job::default()).expect("the receiver is alive");
        }
        let writer = scope.spawn(move || -> Result<Pass> {
            let mut pass = Pass::Written(sink);
            for job in queued {
                if let Pass::Written(s) = &mut pass {
                    match s.write(&job.chunk, &job.moved, &job.normals)? {
                        Accepted::Yes => {}
                        // Dropping the receiver stops the reader.
                        Accepted::Restart => return Ok(Pass::Refused(Accepted::Restart)),
                        Accepted::Overflow => pass = Pass::Refused(Accepted::Overflow),
                    }
                }
                // The reader may have stopped early on an error of its own.
                let _ = done.send(job);
            }
            Ok(pass)
        });
        // `recv` fails only when the writer stopped on an error, which `join` returns.
        while let Ok(mut job) = empty.recv() {
            let read = if raw {
                source.read(chunk_len, &mut job.chunk)?
            } else {
                source.read_samples(chunk_len, &mut job.chunk)?
            };
            if read == 0 {
                break;
            }
            let Job {
                chunk,
                moved,
                normals,
            } = &mut job;
            apply_into(
                warp,
                origin,
                &chunk.positions,
                &chunk.normals,
                moved,
                normals,
            );
            check_moved(chunk.first, moved)?;
            for p in moved.iter() {
                moved_bounds.0 = moved_bounds.0.inf(p);
                moved_bounds.1 = moved_bounds.1.sup(p);
            }
            observer.advance(chunk.len() as u64);
            if full.send(job).is_err() {
                break;
            }
        }
        drop(full);
        writer.join().expect("the writer thread does not panic")
    })?;
    observer.finish();
    Ok((pass, moved_bounds))
}
