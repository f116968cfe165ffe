//! Files streamed.

use std::path::Path;
use std::time::Instant;

use crate::cells::{BuildInfo, CellComplex};
use crate::control::ControlPoint;
use crate::error::{Error, Result};
use crate::field::{Deformer, FieldMap, Outside, SavedField, Transfer, apply};
use crate::io::{self, ResultSet, Source};
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::Vect;
use crate::said::{Opt, Said};
use crate::solve::{self, Solution};
use crate::spec::EditSpec;

use super::checks::check_foldovers;
use super::first_pass::first_pass_cells;
use super::stages::{self, Cells, Selected, Staged, control_results};
use super::transfer_pass::transfer_pass;
use super::{DeformInfo, DeformParams, FOLDOVER_SAMPLES, Proxy};

/// Samples per streamed chunk by default: measured on a 20M-point LAS, 64k-sample chunks ran
/// 3.8 s against 6.5 s for 1M (the chunk in flight stays in cache) and LAZ was the same either
/// way, with a peak RSS of 45 MB instead of 370 MB.
pub const CHUNK: usize = 1 << 16;

/// The largest chunk a caller may ask for: a chunk's buffers are sized by what it holds, but
/// 2⁶⁴ − 1 overflowed the index arithmetic of the readers.
pub const MAX_CHUNK: usize = 1 << 24;

/// A chunk's length checked: 1 sample or more (more than [`MAX_CHUNK`] is taken as that
/// many).
pub fn check_chunk(chunk: usize) -> Result<usize> {
    if chunk == 0 {
        return Err(Error::param(
            Said::new()
                .set(Opt::Chunk, 0)
                .text(": a chunk holds 1 to 16,777,216 samples"),
        ));
    }
    Ok(chunk.min(MAX_CHUNK))
}

/// What [`deform_file`] and [`apply_file`] did.
#[derive(Debug, Clone, Default, PartialEq)]
#[non_exhaustive]
pub struct FileInfo {
    /// Samples read and written.
    pub samples: u64,
    /// Cells, solve and transfer (empty for [`apply_file`]).
    pub deform: DeformInfo,
    /// Notes on the output (moved offsets, dropped indices, header fixes).
    pub notes: Vec<Said>,
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
    /// The memory budget, for an RBF that must be factored.
    pub memory: Budget,
    /// Take the input to be in the coordinate system the field was solved in, whatever the
    /// two declare (`--same-crs`); else a field and an input that declare different systems
    /// are refused ([`crate::crs::check`]).
    pub same_crs: bool,
}

impl ApplyParams {
    /// Refuses a far-field tolerance that is not a length, or that comes with a transfer
    /// other than the RBF (without a transfer, the field's own decides, when it is read).
    pub fn check(&self) -> Result<()> {
        super::options::check_rbf_tolerance(self.rbf_tolerance, self.transfer)
    }
}

/// Deforms the file `input` into `output` in two streaming passes: pass 1 builds
/// the cells from occupancy and gathers what the spec's regions select, never holding all
/// samples (meshes excepted: their triangles need the vertices); the solve runs on the cells;
/// pass 2 streams chunks of [`CHUNK`] samples through the field, in file order, into the
/// output. The output appears at the end, or, on an error, not at all; an output that names
/// the input is refused before any work. [`super::deform_file_with`] writes the field, the
/// report and the preview beside it, and streams chunks of another size.
pub fn deform_file(
    input: &Path,
    output: &Path,
    spec: &EditSpec<3>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(Solution<3>, FileInfo)> {
    let outputs = super::Outputs::default();
    let (solution, info, _) =
        super::deform_file_with(input, output, spec, params, &outputs, observer)?;
    Ok((solution, info))
}

/// Refuses, before any work and in every face, `outputs` (each with what it is, for the
/// message) that would replace one of `inputs` or each other, or whose folder is missing.
pub(super) fn refuse_clobbering(inputs: &[&Path], outputs: &[(&str, &Path)]) -> Result<()> {
    io::check_folders(outputs.iter().map(|(_, path)| *path))?;
    for (_, output) in outputs {
        for input in inputs {
            io::refuse_overwrite(input, output)?;
        }
    }
    io::refuse_same_outputs(outputs)
}

/// [`deform_file`] with its outputs handed to `set` (renamed into place by the caller).
pub(super) fn deform_in(
    set: &ResultSet,
    input: &Path,
    (output, save_field): (&Path, Option<&Path>),
    spec: &EditSpec<3>,
    params: &DeformParams,
    chunk: usize,
    observer: &dyn Observer,
) -> Result<(Solution<3>, FileInfo)> {
    let mut outputs = vec![("the output", output)];
    outputs.extend(save_field.map(|f| ("the saved field", f)));
    refuse_clobbering(&[input], &outputs)?;
    io::check_output_format(input, output)?;
    let chunk = check_chunk(chunk)?;
    set.last(output);
    let mut source = io::open(input)?;
    let mut info = FileInfo::default();
    let Solved {
        solution,
        deformer,
        build,
        warnings,
        transfer_start,
        foldovers,
        controls,
        proxy_outside,
        origin,
    } = solve_checked(
        source.as_mut(),
        spec,
        params,
        chunk,
        save_field.map(|f| (f, set)),
        &mut info,
        observer,
    )?;
    let t2 = Instant::now();
    // A proxy of every sample (a mesh's vertices, a small file) was moved above: the pass
    // writes those positions.
    let moved = (info.proxy.after.len() as u64 == source.len()).then_some(&info.proxy.after[..]);
    let (mut controls, seconds_check) = controls;
    let mut got: Vec<crate::rigid::Vect<3>> = controls
        .iter()
        .map(|p| crate::rigid::Vect::<3>::from_column_slice(&p.got))
        .collect();
    let (notes, rounding) = transfer_pass(
        source.as_mut(),
        (output, set),
        &deformer,
        &origin,
        moved,
        &mut got,
        chunk,
        observer,
    )?;
    info.notes.extend(notes);
    // The residuals of the coordinates as written, not of the field's values.
    crate::control::as_written(&mut controls, &got);
    let controls = (controls, seconds_check);
    // Every sample made the cells; one beyond their margin would be extrapolated, so say so.
    let outside = match moved {
        Some(_) => proxy_outside,
        None => deformer.outside().count,
    };
    if outside > 0 {
        info.notes.push(Said::from(format!(
            "{outside} samples lay beyond the cells' margin ({}) and were moved by the transfer \
             extended there",
            crate::human::length(deformer.margin(), deformer.margin())
        )));
    }
    info.outside = outside;
    info.seconds_write = t2.elapsed().as_secs_f64();
    info.deform = DeformInfo::of(
        params,
        build,
        &solution.info,
        transfer_start,
        foldovers,
        controls,
        warnings,
    );
    info.deform.control_rounding = rounding;
    Ok((solution, info))
}

/// What a file's run holds once it is solved and checked, before anything is written but the
/// field: what [`deform_file`] then streams through, and all that [`solve_files`] reports.
struct Solved {
    solution: Solution<3>,
    /// The field's map (the chosen transfer with its exact regions), extended beyond the margin.
    deformer: FieldMap<3>,
    /// The local frame's origin in world coordinates.
    origin: Vect<3>,
    build: BuildInfo,
    warnings: Vec<Said>,
    /// When the field's construction began (the transfer's seconds count from there).
    transfer_start: Instant,
    /// Samples checked for fold-overs, and those folded.
    foldovers: (usize, usize),
    /// The control points as the map moves them, and the seconds of their leave-one-out check.
    controls: (Vec<ControlPoint>, f64),
    /// Samples of the proxy beyond the cells' margin.
    proxy_outside: u64,
}

/// Pass 1 over `source`, the stages after it ([`solve_source`]), and the checks on what they
/// made: the proxy moved through the field's map (into `info.proxy`, with the source's
/// triangles when it holds every sample), the fold-over check on it and the control points'
/// results ([`control_results`], with the leave-one-out check when `params` asks for it). The
/// sequence [`deform_file`] runs before its transfer pass and [`solve_files`] runs whole, so
/// that a solve over tiles reports what a deformation of the merged file reports.
fn solve_checked(
    source: &mut dyn Source,
    spec: &EditSpec<3>,
    params: &DeformParams,
    chunk: usize,
    save_field: Option<(&Path, &ResultSet)>,
    info: &mut FileInfo,
    observer: &dyn Observer,
) -> Result<Solved> {
    let (
        Staged {
            solution,
            saved,
            build,
            mut warnings,
            transfer_start,
        },
        proxy,
    ) = solve_source(source, spec, params, chunk, save_field, info, observer)?;
    let origin = saved.field.origin;
    // Every sample made the cells, so none lies beyond the margin.
    let deformer = saved.deformer(None, params.rbf_tolerance, Outside::Extend)?;
    observer.stage("checking", 0);
    let mut after = proxy.before.clone();
    apply(&deformer, &origin, &mut after);
    // When the proxy holds every sample, these are the output's positions, and the samples
    // beyond the margin among them are all the output's (the checks below warp more points).
    let proxy_outside = deformer.outside().count;
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
    // The proxy's samples are no file's: only their count is said.
    let (checked, folded) =
        check_foldovers(&deformer, &solution, &info.proxy.before, &mut warnings);
    let foldovers = (checked, folded.len());
    observer.finish();
    let controls = control_results(spec, &solution, &deformer, params, observer)?;
    Ok(Solved {
        solution,
        deformer,
        origin,
        build,
        warnings,
        transfer_start,
        foldovers,
        controls,
        proxy_outside,
    })
}

/// Pass 1 over `source` and the stages after it ([`stages::run`]): the field (with the RBF's
/// factorization when that is the transfer), saved to `save_field` (staged in its set) when
/// given, and the proxy
/// of pass 1. What [`deform_file`] does before its transfer pass, and all that [`solve_files`]
/// does. Fills `info`'s samples, notes and read time.
fn solve_source(
    source: &mut dyn Source,
    spec: &EditSpec<3>,
    params: &DeformParams,
    chunk: usize,
    save_field: Option<(&Path, &ResultSet)>,
    info: &mut FileInfo,
    observer: &dyn Observer,
) -> Result<(Staged<3>, Proxy)> {
    let t0 = Instant::now();
    info.samples = source.len();
    let crs = source.crs();
    let crs_warnings = spec.check_geojson_crs(crs.as_ref(), source.path())?;
    let proxy_max = params.proxy_samples.unwrap_or(FOLDOVER_SAMPLES);
    let (complex, build, selections, proxy) = first_pass_cells(
        source,
        spec,
        params,
        chunk,
        proxy_max,
        true,
        &mut info.notes,
        observer,
    )?;
    info.seconds_read = t0.elapsed().as_secs_f64();
    let cells = Cells::Built {
        complex,
        build,
        selections,
    };
    let mut staged = stages::run(cells, spec, params, observer)?;
    staged
        .warnings
        .splice(0..0, crs_warnings.into_iter().map(Said::from));
    staged.saved.crs = crs;
    if let Some((path, set)) = save_field {
        set.write(path, &staged.saved.to_bytes()?)?;
    }
    Ok((staged, proxy))
}

/// Solves `spec` over the files `inputs` taken as one (the tiles of a scan; pass 1 reads every
/// one, [`Tiles`](crate::io::Tiles)) and writes only the field, to `save_field` (handed to
/// `set`, renamed into place by the caller). The cells, and so the field, are those
/// [`deform_file`] builds for the tiles merged in this order: each tile's `apply` writes, record
/// for record, what `deform` writes for the merged file (with the union of the tiles' header
/// bounds as its own); and what it reports — the proxy moved through the field, the fold-overs,
/// the control points as the field moves them, the leave-one-out check — is what `deform`
/// reports for the merged file. Tiles that declare different coordinate systems are refused
/// before any pass, unless `same_crs` (the user's `--same-crs`; [`io::Tiles::check_crs`]); the
/// field records the system. The public face is [`super::solve_files`].
pub(super) fn solve_in(
    set: &ResultSet,
    inputs: &[std::path::PathBuf],
    spec: &EditSpec<3>,
    params: &DeformParams,
    chunk: usize,
    (save_field, same_crs): (&Path, bool),
    observer: &dyn Observer,
) -> Result<(Solution<3>, FileInfo)> {
    let chunk = check_chunk(chunk)?;
    let mut tiles = io::Tiles::open(inputs)?;
    let crs_warnings = tiles.check_crs(same_crs)?;
    let mut info = FileInfo::default();
    let solved = solve_checked(
        &mut tiles,
        spec,
        params,
        chunk,
        Some((save_field, set)),
        &mut info,
        observer,
    )?;
    let mut warnings = solved.warnings;
    warnings.splice(0..0, crs_warnings);
    info.deform = DeformInfo::of(
        params,
        solved.build,
        &solved.solution.info,
        solved.transfer_start,
        solved.foldovers,
        solved.controls,
        warnings,
    );
    Ok((solved.solution, info))
}

/// Applies the field saved in `field` to the file `input`, writing `output` (one streaming
/// pass). Samples beyond the field's margin are refused by default ([`Error::Outside`], and
/// nothing is written), or kept or extended as `params.outside` says. With the PU transfer and
/// an input whose header gives its bounds (LAS/LAZ), only the part of the field those bounds
/// need is read ([`SavedField::load_window`]; not with `--outside extend`, whose samples beyond
/// the margin follow the nearest patch of the whole field); should a sample lie outside them,
/// the pass runs again with the whole field. A field solved in one coordinate system is
/// refused on an input that declares another, before the pass, unless `params.same_crs`
/// ([`crate::crs::check`]); when only one of the two declares a system, the warning is in
/// `info.deform.warnings`.
pub fn apply_file(
    field: &Path,
    input: &Path,
    output: &Path,
    params: &ApplyParams,
    chunk: usize,
    observer: &dyn Observer,
) -> Result<FileInfo> {
    params.check()?;
    refuse_clobbering(&[input, field], &[("the output", output)])?;
    io::check_output_format(input, output)?;
    let chunk = check_chunk(chunk)?;
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
        return Err(Error::param(
            Said::new()
                .opt(Opt::RbfTolerance)
                .text(format!(
                    " applies to the RBF transfer only, and {} was saved for another; add ",
                    field.display()
                ))
                .set(Opt::Transfer, "rbf"),
        ));
    }
    let crs_warning = crate::crs::check(
        "the field's coordinate system differs from the input's",
        (saved.crs.as_ref(), field),
        (source.crs().as_ref(), input),
        params.same_crs,
        Said::from("apply the field to files in the system it was solved in, or pass ")
            .opt(Opt::SameCrs)
            .text(" if both describe the same one"),
    )?;
    let windowed = saved.is_window();
    let set = ResultSet::new();
    let to = (output, &set);
    let info = apply_saved(saved, source.as_mut(), to, params, chunk, observer)?;
    let info = match info {
        Applied::Done(info) => *info,
        Applied::BeyondWindow(count) => {
            let whole = SavedField::<3>::load(field)?;
            debug_assert!(windowed);
            match apply_saved(whole, source.as_mut(), to, params, chunk, observer)? {
                Applied::Done(mut info) => {
                    info.notes.push(Said::from(format!(
                        "{count} samples lay outside the bounds in {}'s header; the whole \
                         field was read",
                        input.display()
                    )));
                    *info
                }
                Applied::BeyondWindow(_) => {
                    return Err(Error::solver(
                        "a whole field reported samples outside its window",
                    ));
                }
            }
        }
    };
    set.commit()?;
    let mut info = info;
    info.deform.warnings.extend(crs_warning);
    Ok(info)
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
    output: (&Path, &ResultSet),
    params: &ApplyParams,
    chunk: usize,
    observer: &dyn Observer,
) -> Result<Applied> {
    let t = Instant::now();
    let origin = field.field.origin;
    if params.transfer == Some(Transfer::Rbf) && !field.has_rbf() {
        params.memory.check(
            format!("the RBF transfer of {} cells", field.field.centers.len()),
            crate::memory::rbf_bytes(field.field.centers.len(), 3),
            Said::from("apply the field with the transfer it was saved with (no ")
                .set(Opt::Transfer, "rbf")
                .text(")"),
        )?;
    }
    observer.stage("transfer", 0);
    let deformer = field.tile_deformer(params.transfer, params.rbf_tolerance, params.outside)?;
    observer.finish();
    let (mut notes, _) = transfer_pass(
        source,
        output,
        &deformer,
        &origin,
        None,
        &mut [],
        chunk,
        observer,
    )?;
    if deformer.beyond_window() > 0 {
        return Ok(Applied::BeyondWindow(deformer.beyond_window()));
    }
    if let Deformer::Pu(pu) = deformer.inner() {
        let (made, all, failed) = pu.fits();
        notes.push(Said::from(format!(
            "the PU transfer fitted {made} of its {all} patches (those the samples reached)"
        )));
        if failed > 0 {
            notes.push(Said::from(format!(
                "{failed} of the PU's patch fits failed; the samples there were blended from \
                 the patches around them"
            )));
        }
    }
    let outside = deformer.outside().count;
    let margin = crate::human::length(deformer.margin(), deformer.margin());
    match params.outside {
        Outside::Keep if outside > 0 => notes.push(Said::from(format!(
            "{outside} samples beyond the field's margin ({margin}) kept their coordinates"
        ))),
        Outside::Extend if outside > 0 => notes.push(Said::from(format!(
            "{outside} samples beyond the field's margin ({margin}) were moved by the \
             transfer extended there"
        ))),
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

/// The cell complex of the file `input` (pass 1 of [`deform_file`]) and, with a `spec`, its
/// solution: for inspecting the cells (`rigidcells cells`).
pub fn file_cells(
    input: &Path,
    spec: Option<&EditSpec<3>>,
    params: &DeformParams,
    chunk: usize,
    observer: &dyn Observer,
) -> Result<(CellComplex<3>, BuildInfo, Option<Solution<3>>, Vec<Said>)> {
    let mut source = io::open(input)?;
    let empty = EditSpec::default();
    let mut notes = Vec::new();
    let (complex, info, selections, _) = first_pass_cells(
        source.as_mut(),
        spec.unwrap_or(&empty),
        params,
        chunk,
        0,
        spec.is_some(),
        &mut notes,
        observer,
    )?;
    let mut warnings = stages::build_warnings(&info, &complex, params);
    warnings.extend(notes);
    let Some(spec) = spec else {
        return Ok((complex, info, None, warnings));
    };
    let selected = Selected::Gathered(&selections);
    let constraints = stages::constraints(&complex, spec, selected, params)?;
    warnings.extend(constraints.warnings.iter().cloned());
    let solution = solve::solve(
        complex.clone(),
        constraints,
        &params.solve,
        params.memory,
        observer,
    )?;
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
