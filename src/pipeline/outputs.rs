//! `deform` of a file with everything a user may ask to be written beside its output — the
//! solved field, the JSON report, the preview picture — as one result: there all together or
//! not at all. The CLI's `deform` and the Python package's `deform_file` both call
//! [`deform_file_with`].

use std::path::Path;
use std::time::Instant;

use crate::error::Result;
use crate::io::ResultSet;
use crate::progress::Observer;
use crate::render::View;
use crate::report::Report;
use crate::solve::Solution;
use crate::spec::EditSpec;

use super::files::{deform_in, refuse_clobbering};
use super::{DeformParams, FOLDOVER_SAMPLES, FileInfo, PROXY_SAMPLES};

/// What is written beside a deformed file.
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs<'a> {
    /// The solved field, for `rigidcells apply`.
    pub save_field: Option<&'a Path>,
    /// The JSON report ([`Report`]).
    pub report: Option<&'a Path>,
    /// A PNG of the input and the output side by side, seen from the view, with the strained
    /// cells beside them when the flag is set ([`crate::preview::preview`]).
    pub preview: Option<(&'a Path, View, bool)>,
    /// Replace no file that appears under the output's or another output's name while the run
    /// works (the editor's *Apply* to a name that was free when its user asked): the run then
    /// fails at its end, naming the file, and leaves it as it is.
    pub keep_existing: bool,
}

/// [`deform_file`] of `input` into `output` with the `outputs` beside it: the proxy is the
/// preview's when a preview is asked (else the fold-over check's). The files are renamed into
/// place together at the end: an error or an interrupt on the way leaves none of them, and an
/// output that names the input, or two that name one file, are refused before any work.
/// Returns the solution, what the pass did and
/// the report (whether or not it is written).
pub fn deform_file_with(
    input: &Path,
    output: &Path,
    spec: &EditSpec<3>,
    params: &DeformParams,
    chunk: usize,
    outputs: &Outputs,
    observer: &dyn Observer,
) -> Result<(Solution<3>, FileInfo, Report)> {
    let start = Instant::now();
    let mut named = vec![("the output", output)];
    named.extend(outputs.save_field.map(|p| ("the saved field", p)));
    named.extend(outputs.report.map(|p| ("the report", p)));
    named.extend(outputs.preview.map(|(p, _, _)| ("the preview", p)));
    refuse_clobbering(&[input], &named)?;
    if let Some((path, view, _)) = &outputs.preview {
        crate::render::png_path(path)?;
        view.check()?;
    }
    // The proxy serves the fold-over check, the report's residual and the preview (which
    // draws a mesh's triangles when it holds every vertex).
    let params = DeformParams {
        proxy_samples: Some(match outputs.preview {
            Some(_) => PROXY_SAMPLES,
            None => FOLDOVER_SAMPLES,
        }),
        ..*params
    };
    let set = ResultSet::new();
    if outputs.keep_existing {
        set.keep_existing();
    }
    let (solution, info) = deform_in(
        &set,
        input,
        (output, outputs.save_field),
        spec,
        &params,
        chunk,
        observer,
    )?;
    let report = Report::new(
        input,
        output,
        &solution,
        &info,
        start.elapsed().as_secs_f64(),
    );
    if let Some(path) = outputs.report {
        set.write(path, &report.json(path)?)?;
    }
    if let Some((path, view, strain)) = &outputs.preview {
        let picture = crate::preview::preview(&solution, &info.proxy, view, *strain);
        set.write(path, &picture.png(path)?)?;
    }
    set.commit()?;
    Ok((solution, info, report))
}
