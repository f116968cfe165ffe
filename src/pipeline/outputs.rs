//! `deform` of a file, and `solve` over tiles, with everything a user may ask to be written
//! beside its output — the solved field, the JSON report, the preview picture — as one result:
//! there all together or not at all. The CLI's `deform` and the Python package's `deform_file`
//! call [`deform_file_with`]; `solve` and `solve_files` call [`solve_files`]. Both check their
//! outputs, pick the proxy and write the report and the preview through the same functions
//! ([`prepare`], [`write_beside`]), so a solve over tiles reports and draws what a deformation
//! of the merged file does.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::report::Report;
use crate::error::{Error, Result};
use crate::io::ResultSet;
use crate::progress::Observer;
use crate::render::View;
use crate::said::{Opt, Said};
use crate::solve::Solution;
use crate::spec::EditSpec;

use super::files::{deform_in, refuse_clobbering, solve_in};
use super::{DeformParams, FOLDOVER_SAMPLES, FileInfo, PROXY_SAMPLES};

/// What is written beside a deformed file (for [`solve_files`], whose output is the field:
/// beside nothing).
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs<'a> {
    /// The solved field, for `rigidcells apply` (required by [`solve_files`]).
    pub save_field: Option<&'a Path>,
    /// The JSON report ([`Report`]).
    pub report: Option<&'a Path>,
    /// A PNG of the input and the output side by side, seen from the view, with the strained
    /// cells beside them when the flag is set ([`crate::pipeline::preview::preview`]).
    pub preview: Option<(&'a Path, View, bool)>,
    /// Replace no file that appears under the output's or another output's name while the run
    /// works (the editor's *Apply* to a name that was free when its user asked): the run then
    /// fails at its end, naming the file, and leaves it as it is.
    pub keep_existing: bool,
    /// Samples per chunk of the streamed passes (`None`: [`super::CHUNK`]; at most
    /// [`super::MAX_CHUNK`] are taken): memory, not results — every size writes the same
    /// bytes.
    pub chunk: Option<usize>,
}

impl Outputs<'_> {
    /// Samples per chunk: [`Outputs::chunk`]'s ([`super::check_chunk`]), or [`super::CHUNK`].
    fn chunk(&self) -> Result<usize> {
        self.chunk.map_or(Ok(super::CHUNK), super::check_chunk)
    }
}

/// [`super::deform_file`] of `input` into `output` with the `outputs` beside it: the proxy is the
/// preview's when a preview is asked (else the fold-over check's). The files are renamed into
/// place together at the end: an error or an interrupt on the way leaves none of them, and an
/// output that names the input, or two that name one file, are refused before any work.
/// Returns the solution, what the pass did and the report (whether or not it is written).
pub fn deform_file_with(
    input: &Path,
    output: &Path,
    spec: &EditSpec<3>,
    params: &DeformParams,
    outputs: &Outputs,
    observer: &dyn Observer,
) -> Result<(Solution<3>, FileInfo, Report)> {
    let start = Instant::now();
    let chunk = outputs.chunk()?;
    let mut named = vec![("the output", output)];
    named.extend(outputs.save_field.map(|p| ("the saved field", p)));
    let params = prepare(&[input], named, outputs, params)?;
    let set = result_set(outputs);
    let (solution, info) = deform_in(
        &set,
        input,
        (output, outputs.save_field),
        spec,
        &params,
        chunk,
        observer,
    )?;
    let report = finish(set, outputs, (&[input], output), &solution, &info, start)?;
    Ok((solution, info, report))
}

/// Solves `spec` over the files `inputs` taken as one (the tiles of a scan) and writes the
/// field to `outputs.save_field`, which must be given, with the report and the preview the
/// `outputs` ask for: what `deform` of the tiles merged in this order writes beside its output,
/// the preview drawn from a decimated proxy across all tiles (`apply` of the field to each
/// tile then writes what `deform` writes for the merged file). The files appear together at
/// the end or not at all; one that names an input, or two that name one file, are refused
/// before any work; so are tiles that declare different coordinate systems, unless `same_crs`
/// (the user's `--same-crs`). Returns the solution, what the pass did and the report (whether
/// or not it is written).
pub fn solve_files(
    inputs: &[PathBuf],
    spec: &EditSpec<3>,
    params: &DeformParams,
    (outputs, same_crs): (&Outputs, bool),
    observer: &dyn Observer,
) -> Result<(Solution<3>, FileInfo, Report)> {
    let start = Instant::now();
    let chunk = outputs.chunk()?;
    let Some(field) = outputs.save_field else {
        return Err(Error::param(
            Said::from("a solve writes a field: name its file (")
                .opt(Opt::SaveField)
                .text(")"),
        ));
    };
    let paths: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    let params = prepare(&paths, vec![("the saved field", field)], outputs, params)?;
    let set = result_set(outputs);
    set.last(field);
    let (solution, info) = solve_in(
        &set,
        inputs,
        spec,
        &params,
        chunk,
        (field, same_crs),
        observer,
    )?;
    let report = finish(set, outputs, (&paths, field), &solution, &info, start)?;
    Ok((solution, info, report))
}

/// Refuses, before any work, outputs (`named`, and the report and the preview of `outputs`)
/// that would replace one of `inputs` or each other, a preview that is not a PNG or whose view
/// is not one; returns `params` with the proxy the run gathers in its first pass: the
/// preview's when a preview is asked (else the fold-over check's). The proxy serves the
/// fold-over check, the report's residuals and the preview (which draws a mesh's triangles
/// when it holds every vertex).
fn prepare<'a>(
    inputs: &[&Path],
    mut named: Vec<(&'static str, &'a Path)>,
    outputs: &Outputs<'a>,
    params: &DeformParams,
) -> Result<DeformParams> {
    named.extend(outputs.report.map(|p| ("the report", p)));
    named.extend(outputs.preview.map(|(p, _, _)| ("the preview", p)));
    refuse_clobbering(inputs, &named)?;
    if let Some((path, view, _)) = &outputs.preview {
        crate::render::png_path(path)?;
        view.check()?;
    }
    Ok(DeformParams {
        // The caller's proxy ([`DeformParams::with_proxy_samples`]) where it chose one.
        proxy_samples: params.proxy_samples.or(Some(match outputs.preview {
            Some(_) => PROXY_SAMPLES,
            None => FOLDOVER_SAMPLES,
        })),
        ..*params
    })
}

/// The set a run's files are staged in: it replaces nothing that appears meanwhile under their
/// names when `outputs.keep_existing`.
fn result_set(outputs: &Outputs) -> ResultSet {
    let set = ResultSet::new();
    if outputs.keep_existing {
        set.keep_existing();
    }
    set
}

/// The end of a run that read `inputs` and made `output` (the deformed file, or the field) since
/// `start`: its report, handed to `set` with the preview when `outputs` ask for them, and every
/// file of the set renamed into place together.
fn finish(
    set: ResultSet,
    outputs: &Outputs,
    (inputs, output): (&[&Path], &Path),
    solution: &Solution<3>,
    info: &FileInfo,
    start: Instant,
) -> Result<Report> {
    let report = Report::new(
        inputs,
        output,
        solution,
        info,
        start.elapsed().as_secs_f64(),
    );
    write_beside(&set, outputs, &report, solution, info)?;
    set.commit()?;
    Ok(report)
}

/// Hands `set` the report and the preview that `outputs` ask for.
fn write_beside(
    set: &ResultSet,
    outputs: &Outputs,
    report: &Report,
    solution: &Solution<3>,
    info: &FileInfo,
) -> Result<()> {
    if let Some(path) = outputs.report {
        set.write(path, &report.json(path)?)?;
    }
    if let Some((path, view, strain)) = &outputs.preview {
        let picture = super::preview::preview(solution, &info.proxy, view, *strain);
        set.write(path, &picture.png(path)?)?;
    }
    Ok(())
}
