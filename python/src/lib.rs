//! The Python extension of rigidcells (`rigidcells._rigidcells`): thin wrappers over the
//! library's `pipeline` functions, numpy arrays in and out, the GIL released around every
//! heavy call, and the library's errors as Python exceptions (`ValueError` for a bad spec or
//! parameter, `OSError` for I/O, `rigidcells.FormatError` for malformed files,
//! `rigidcells.TurnNotHeldError` for a turn the shape gives way under). The Python
//! package (`python/python/rigidcells/__init__.py`) adds specs as dicts or paths and numpy
//! structured arrays. The live `Session` is in `session.rs`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use rigidcells::Inside;
use rigidcells::Options;
use rigidcells::Vect;
use rigidcells::View;
use rigidcells::internal::io;
use rigidcells::internal::names::{Named, UnknownName};
use rigidcells::internal::pipeline::{self, DeformParams};
use rigidcells::{EditSpec, parse_spec};
use rigidcells::{LooseParts, Method};
use rigidcells::{Outside, SavedField, Transfer};

mod errors;
mod observer;
mod session;
mod workers;
use errors::{FormatError, TurnNotHeldError, py_err, said, said_text};
use observer::PyObserver;
use session::Session;

/// An `(n, 3)` array of coordinates as points.
fn points(a: &PyReadonlyArray2<f64>) -> PyResult<Vec<Vect<3>>> {
    let v = a.as_array();
    if v.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "points must be an (n, 3) array, got {:?}",
            v.shape()
        )));
    }
    Ok(v.rows()
        .into_iter()
        .map(|r| Vect::<3>::new(r[0], r[1], r[2]))
        .collect())
}

/// An `(m, 3)` array of vertex indices as triangles, each checked against `n` points.
fn triangles(a: Option<&PyReadonlyArray2<i64>>, n: usize) -> PyResult<Vec<[u32; 3]>> {
    let Some(a) = a else { return Ok(Vec::new()) };
    let v = a.as_array();
    if v.ncols() != 3 {
        return Err(PyValueError::new_err("triangles must be an (m, 3) array"));
    }
    v.rows()
        .into_iter()
        .map(|r| {
            let t = [r[0], r[1], r[2]];
            let index = |i: i64| u32::try_from(i).ok().filter(|&i| (i as usize) < n);
            match (index(t[0]), index(t[1]), index(t[2])) {
                (Some(a), Some(b), Some(c)) => Ok([a, b, c]),
                _ => Err(PyValueError::new_err(format!(
                    "triangle {t:?} names a vertex outside 0..{n}"
                ))),
            }
        })
        .collect()
}

/// LAS classes ((n,), uint8), one a point, or none.
fn classes(a: Option<&PyReadonlyArray1<u8>>) -> Vec<u8> {
    a.map_or_else(Vec::new, |a| a.as_array().to_vec())
}

fn moved_array<'py>(py: Python<'py>, moved: &[Vect<3>]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = moved.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    Array2::from_shape_vec((moved.len(), 3), flat)
        .expect("n × 3")
        .into_pyarray(py)
}

fn spec(text: &str, base: &str) -> PyResult<EditSpec<3>> {
    parse_spec(text, Path::new(base), Path::new("spec")).map_err(py_err)
}

/// A choice named by the user for the argument `arg` (`transfer="rbf"`), or its default.
fn named<T: std::str::FromStr<Err = UnknownName> + Named>(
    arg: &'static str,
    name: Option<String>,
    default: T,
) -> PyResult<T> {
    match name {
        None => Ok(default),
        Some(name) => name.parse().map_err(|e: UnknownName| {
            let expected = T::ALL.iter().map(|v| v.name()).collect();
            PyValueError::new_err(
                UnknownName {
                    what: arg,
                    expected,
                    ..e
                }
                .to_string(),
            )
        }),
    }
}

/// The keyword arguments the package takes for a deformation (every option of the command
/// line's `deform`), as the library's options; a wrong type or value names the argument.
fn options(d: Option<&Bound<'_, PyDict>>) -> PyResult<Options> {
    let mut o = Options::default();
    let Some(d) = d else { return Ok(o) };
    for (key, value) in d.iter() {
        let key: String = key.extract()?;
        if value.is_none() {
            continue;
        }
        let whole = |what: &str| whole(&value, &key, what);
        let number = || -> PyResult<f64> {
            if value.is_instance_of::<pyo3::types::PyBool>() {
                return Err(PyTypeError::new_err(format!(
                    "{key} must be a number, got a bool"
                )));
            }
            value.extract::<f64>().map_err(|_| {
                PyTypeError::new_err(format!("{key} must be a number, got {}", type_name(&value)))
            })
        };
        let level = |n: u64, most: u64| {
            u8::try_from(n)
                .ok()
                .filter(|&n| u64::from(n) <= most)
                .ok_or_else(|| PyValueError::new_err(format!("{key} must be 0 to {most}, got {n}")))
        };
        let flag = || -> PyResult<bool> {
            value
                .extract::<bool>()
                .map_err(|_| PyTypeError::new_err(format!("{key} must be True or False")))
        };
        let name = || -> PyResult<Option<String>> {
            value
                .extract::<String>()
                .map(Some)
                .map_err(|_| PyTypeError::new_err(format!("{key} must be a name (a str)")))
        };
        match key.as_str() {
            "cell_size" => o.cell_size = Some(number()?),
            "cells" => match whole("a whole number of cells, 1 or more")? {
                0 => return Err(PyValueError::new_err("cells must be 1 or more, got 0")),
                n => o.cells = Some(usize::try_from(n).unwrap_or(usize::MAX)),
            },
            "min_cell_size" => o.min_cell_size = Some(number()?),
            "max_level" => {
                let most = u64::from(rigidcells::internal::cells::MAX_LEVEL);
                o.max_level = Some(level(whole("a whole number of levels")?, most)?)
            }
            "shell" => o.shell = flag()?,
            "inside" => o.inside = named("inside", name()?, Inside::Auto)?,
            "interior_stiffness" => o.interior_stiffness = number()?,
            "solver" => o.solver = named("solver", name()?, Method::Auto)?,
            "subdomains" => {
                o.subdomains =
                    usize::try_from(whole("a whole number of subdomains")?).unwrap_or(usize::MAX)
            }
            "tolerance" => o.tolerance = number()?,
            "coarse_levels" => {
                o.coarse_levels = Some(level(whole("a whole number of levels")?, 8)?)
            }
            "loose_parts" => o.loose_parts = named("loose_parts", name()?, LooseParts::Carry)?,
            "refine_strain" => o.refine_strain = Some(number()?),
            "transfer" => o.transfer = named("transfer", name()?, Transfer::Pu)?,
            "rbf_tolerance" => o.rbf_tolerance = Some(number()?),
            "check_gcp" => o.check_control_points = flag()?,
            "memory_limit" => o.memory_limit = Some(memory_limit(&value)?),
            _ => return Err(PyTypeError::new_err(format!("unexpected argument {key}"))),
        }
    }
    Ok(o)
}

/// A memory budget in bytes, given as a number or as a size such as "8G".
fn memory_limit(value: &Bound<'_, PyAny>) -> PyResult<u64> {
    if value.is_instance_of::<pyo3::types::PyString>() {
        let text: String = value.extract()?;
        return rigidcells::internal::memory::parse_size(&text)
            .map_err(|e| PyValueError::new_err(format!("memory_limit: {e}")));
    }
    whole(
        value,
        "memory_limit",
        "a number of bytes or a size such as \"8G\"",
    )
}

/// `value` as a whole number 0 or more; a wrong type or value names the argument `key` and
/// says `what` it must be.
fn whole(value: &Bound<'_, PyAny>, key: &str, what: &str) -> PyResult<u64> {
    if value.is_instance_of::<pyo3::types::PyBool>() {
        return Err(PyTypeError::new_err(format!(
            "{key} must be {what}, got a bool"
        )));
    }
    let n: i128 = value.extract().map_err(|_| {
        PyTypeError::new_err(format!("{key} must be {what}, got {}", type_name(value)))
    })?;
    u64::try_from(n).map_err(|_| PyValueError::new_err(format!("{key} must be {what}, got {n}")))
}

/// The Python type's name of `value`, for messages.
fn type_name(value: &Bound<'_, PyAny>) -> String {
    value
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "another type".into())
}

/// The library's report ([`rigidcells::Report`], serialized as the command line's `--report`
/// writes it) as a dict, its messages as [`said`]'s parts for the package to say.
fn report_dict<'py>(py: Python<'py>, report: &rigidcells::Report) -> PyResult<Bound<'py, PyDict>> {
    let text = serde_json::to_string(report)
        .map_err(|e| PyRuntimeError::new_err(format!("the report: {e}")))?;
    let d = py
        .import("json")?
        .call_method1("loads", (text,))?
        .cast_into::<PyDict>()?;
    d.set_item("warnings", said(py, &report.warnings)?)?;
    d.set_item("notes", said(py, &report.notes)?)?;
    Ok(d)
}

/// The samples `deform` and `solve` take: points, triangles over them and their LAS classes
/// (empty when none are given).
struct Samples {
    points: Vec<Vect<3>>,
    triangles: Vec<[u32; 3]>,
    classes: Vec<u8>,
}

/// The arguments `deform` and `solve` share, checked and converted.
fn inputs(
    points: &PyReadonlyArray2<f64>,
    triangles: Option<&PyReadonlyArray2<i64>>,
    classes: Option<&PyReadonlyArray1<u8>>,
    spec_text: &str,
    base: &str,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<(Samples, EditSpec<3>, DeformParams)> {
    let params = self::options(options)?.params().map_err(py_err)?;
    let pts = self::points(points)?;
    let samples = Samples {
        triangles: self::triangles(triangles, pts.len())?,
        classes: self::classes(classes),
        points: pts,
    };
    Ok((samples, self::spec(spec_text, base)?, params))
}

/// Deforms `points` ((n, 3) float64), with their `normals` when given, under the TOML `spec`
/// (relative file names against `base`) with the `options` (keyword arguments as the command
/// line's options); `classes` ((n,) uint8) are the points' LAS classes, for the spec's
/// classification regions. Returns the moved points and what was done (with the turned normals
/// under `"normals"` when normals were given).
#[pyfunction]
#[pyo3(signature = (points, spec_text, base, triangles=None, normals=None, options=None, progress=None, classes=None))]
#[allow(clippy::too_many_arguments)]
fn deform<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    spec_text: &str,
    base: &str,
    triangles: Option<PyReadonlyArray2<'py, i64>>,
    normals: Option<PyReadonlyArray2<'py, f64>>,
    options: Option<Bound<'py, PyDict>>,
    progress: Option<Py<PyAny>>,
    classes: Option<PyReadonlyArray1<'py, u8>>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyDict>)> {
    let (s, spec, params) = inputs(
        &points,
        triangles.as_ref(),
        classes.as_ref(),
        spec_text,
        base,
        options.as_ref(),
    )?;
    let nrm = match &normals {
        Some(n) => self::points(n)?,
        None => Vec::new(),
    };
    let observer = PyObserver::new(progress);
    let start = Instant::now();
    let result = py.detach(|| -> rigidcells::Result<_> {
        let (moved, turned, solution, info) = pipeline::deform_oriented(
            &s.points,
            &nrm,
            &s.triangles,
            &s.classes,
            &spec,
            &params,
            &observer,
        )?;
        let n = s.points.len() as u64;
        let seconds = start.elapsed().as_secs_f64();
        let report =
            rigidcells::Report::of_samples(Some(&solution), &info, n, (&s.points, &moved), seconds);
        Ok((moved, turned, report))
    });
    let (moved, moved_normals, report) = observer.finished(result)?;
    let d = report_dict(py, &report)?;
    if normals.is_some() {
        d.set_item("normals", moved_array(py, &moved_normals))?;
    }
    Ok((moved_array(py, &moved), d))
}

/// A solved field: apply it to samples, save it for `rigidcells apply`, load one; pickled as
/// its saved bytes.
#[pyclass(module = "rigidcells._rigidcells")]
struct Field {
    saved: SavedField<3>,
}

#[pymethods]
impl Field {
    /// Moves `points` ((n, 3) float64), with their `normals` ((n, 3)) when given, through the
    /// field. `outside`: `refuse` (samples beyond the field's margin are an error, as
    /// `rigidcells apply` refuses them), `keep` or `extend`. Returns the moved points and the
    /// turned normals (or None).
    #[pyo3(signature = (points, normals=None, outside=None))]
    #[allow(clippy::type_complexity)]
    fn apply<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
        normals: Option<PyReadonlyArray2<'py, f64>>,
        outside: Option<String>,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Option<Bound<'py, PyArray2<f64>>>)> {
        let outside = named("outside", outside, Outside::Refuse)?;
        let pts = self::points(&points)?;
        let nrm = match &normals {
            Some(n) => self::points(n)?,
            None => Vec::new(),
        };
        let saved = &self.saved;
        let (moved, moved_normals) = py
            .detach(|| pipeline::apply_points(saved, &pts, &nrm, outside, Path::new("points")))
            .map_err(py_err)?;
        let turned = normals.is_some().then(|| moved_array(py, &moved_normals));
        Ok((moved_array(py, &moved), turned))
    }

    /// Writes the field to `path` (the format `rigidcells apply` reads).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let saved = &self.saved;
        py.detach(|| saved.save(&path)).map_err(py_err)
    }

    /// Reads a field saved by `save` or `rigidcells deform --save-field`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let saved = py.detach(|| SavedField::<3>::load(&path)).map_err(py_err)?;
        Ok(Self { saved })
    }

    /// The field's saved bytes (what `save` writes).
    fn to_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let bytes = self.saved.to_bytes().map_err(py_err)?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// The field of bytes `to_bytes` gave.
    #[staticmethod]
    fn from_bytes(bytes: &[u8]) -> PyResult<Self> {
        let saved =
            SavedField::<3>::from_bytes(bytes, Path::new("<field bytes>")).map_err(py_err)?;
        Ok(Self { saved })
    }

    /// The number of cells.
    #[getter]
    fn cells(&self) -> usize {
        self.saved.field.centers.len()
    }

    /// The transfer the field was made for.
    #[getter]
    fn transfer(&self) -> String {
        self.saved.transfer.to_string()
    }

    /// The finest cells' edge length.
    #[getter]
    fn cell_size(&self) -> f64 {
        self.levels().first().map_or(0.0, |&(size, _)| size)
    }

    /// The cells' edge lengths, one per octree level they occupy, smallest first, each with
    /// its count of cells.
    #[getter]
    fn levels(&self) -> Vec<(f64, usize)> {
        self.saved.field.cell_sizes()
    }

    /// The cells' bounding box, `((xmin, ymin, zmin), (xmax, ymax, zmax))` in the points'
    /// coordinates.
    #[getter]
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        match self.saved.field.domain() {
            Some((lo, hi)) => (lo.into(), hi.into()),
            None => ([f64::NAN; 3], [f64::NAN; 3]),
        }
    }
}

/// Solves the TOML `spec` over `points` (with their LAS `classes` when given) with the
/// `options`; returns the field and what was done.
#[pyfunction]
#[pyo3(signature = (points, spec_text, base, triangles=None, options=None, progress=None, classes=None))]
#[allow(clippy::too_many_arguments)]
fn solve<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    spec_text: &str,
    base: &str,
    triangles: Option<PyReadonlyArray2<'py, i64>>,
    options: Option<Bound<'py, PyDict>>,
    progress: Option<Py<PyAny>>,
    classes: Option<PyReadonlyArray1<'py, u8>>,
) -> PyResult<(Field, Bound<'py, PyDict>)> {
    let (s, spec, params) = inputs(
        &points,
        triangles.as_ref(),
        classes.as_ref(),
        spec_text,
        base,
        options.as_ref(),
    )?;
    let observer = PyObserver::new(progress);
    let start = Instant::now();
    let result = py.detach(|| {
        pipeline::solve_points(
            &s.points,
            &s.triangles,
            &s.classes,
            &spec,
            &params,
            &observer,
        )
    });
    let (saved, solution, info) = observer.finished(result)?;
    let seconds = start.elapsed().as_secs_f64();
    let n = s.points.len() as u64;
    let report = rigidcells::Report::of_samples(Some(&solution), &info, n, (&[], &[]), seconds);
    Ok((Field { saved }, report_dict(py, &report)?))
}

/// What `deform` or `solve` of `points` under the TOML `spec` with the `options` will take,
/// without solving (`rigidcells::internal::pipeline::estimate`): a dict of its `cells`, peak memory in
/// `bytes`, `seconds` (the whole run: the cells as built, the solve and the transfer as
/// estimated), `solve_seconds`, `solver` (`direct`, `multilevel` or `local-global`), `limit` (the memory
/// budget), `fits` and `complete` (false where the cells were only forecast, because they
/// cannot fit the budget: the least the run takes).
#[pyfunction]
#[pyo3(signature = (points, spec_text, base, triangles=None, options=None, classes=None))]
fn estimate<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    spec_text: &str,
    base: &str,
    triangles: Option<PyReadonlyArray2<'py, i64>>,
    options: Option<Bound<'py, PyDict>>,
    classes: Option<PyReadonlyArray1<'py, u8>>,
) -> PyResult<Bound<'py, PyDict>> {
    let (s, spec, params) = inputs(
        &points,
        triangles.as_ref(),
        classes.as_ref(),
        spec_text,
        base,
        options.as_ref(),
    )?;
    let e = py
        .detach(|| pipeline::estimate(&s.points, &s.triangles, &s.classes, &spec, &params))
        .map_err(py_err)?;
    let d = PyDict::new(py);
    d.set_item("cells", e.cells)?;
    d.set_item("bytes", e.bytes)?;
    d.set_item("seconds", e.seconds)?;
    d.set_item("solve_seconds", e.solve_seconds)?;
    d.set_item("solver", e.solver.name())?;
    d.set_item("limit", e.limit)?;
    d.set_item("fits", e.fits())?;
    d.set_item("complete", e.complete)?;
    Ok(d)
}

/// `rigidcells deform` on a file: streams `input` into `output` (atomically), with the field
/// saved to `save_field`, the JSON report written to `report` and the preview picture to
/// `preview` (seen as the `view` dict says: `azimuth`, `elevation`, `size`, `up`, `zoom`,
/// `strain`) when given, all together or none. Stopped (Ctrl-C, or `progress` raising), it
/// leaves no output behind.
#[pyfunction]
#[pyo3(signature = (input, output, spec_text, base, save_field=None, report=None, preview=None, view=None, chunk=None, options=None, progress=None))]
#[allow(clippy::too_many_arguments)]
fn deform_file<'py>(
    py: Python<'py>,
    input: PathBuf,
    output: PathBuf,
    spec_text: &str,
    base: &str,
    save_field: Option<PathBuf>,
    report: Option<PathBuf>,
    preview: Option<PathBuf>,
    view: Option<Bound<'py, PyDict>>,
    chunk: Option<Bound<'py, PyAny>>,
    options: Option<Bound<'py, PyDict>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let params = self::options(options.as_ref())?.params().map_err(py_err)?;
    let spec = self::spec(spec_text, base)?;
    let (view, strain) = self::view(view.as_ref(), &input)?;
    let chunk = self::chunk(chunk)?;
    let outputs = pipeline::Outputs {
        save_field: save_field.as_deref(),
        report: report.as_deref(),
        preview: preview.as_deref().map(|p| (p, view, strain)),
        keep_existing: false,
        chunk: Some(chunk),
    };
    let observer = PyObserver::new(progress);
    let result = py.detach(|| -> rigidcells::Result<_> {
        rigidcells::internal::io::refuse_overwrite(&input, &output)?;
        pipeline::deform_file_with(&input, &output, &spec, &params, &outputs, &observer)
    });
    let (_, _, report) = observer.result(result)?;
    report_dict(py, &report)
}

/// Samples per streamed chunk (default: the command line's): 1 to [`pipeline::MAX_CHUNK`].
fn chunk(chunk: Option<Bound<'_, PyAny>>) -> PyResult<usize> {
    const WHAT: &str =
        "a number of samples, 1 or more (more than 16,777,216 is taken as 16,777,216)";
    let Some(c) = chunk else {
        return Ok(pipeline::CHUNK);
    };
    // As the command line takes `--chunk`: the library's bound on larger values.
    match whole(&c, "chunk", WHAT)? {
        n @ 1.. => Ok(n.min(pipeline::MAX_CHUNK as u64) as usize),
        n => Err(PyValueError::new_err(format!(
            "chunk must be {WHAT}, got {n}"
        ))),
    }
}

/// `rigidcells solve`: the field of the edit over several files taken as one (the tiles of a
/// scan), written to `save_field` for `apply_file` on each tile; together they give what
/// `deform_file` gives on the merged file. The JSON report and the preview (seen as the `view`
/// dict says, as for `deform_file`) are written beside the field when given, all together or
/// none; what they and the returned dict hold is what `deform_file` gives for the merged file.
/// Tiles in different coordinate systems are refused unless `same_crs`. With `workers` (and
/// the option `subdomains`), the subdomains' blocks are factored and solved by that object
/// (`workers.rs`); an exception it raises ends the call and is raised as it was.
#[pyfunction]
#[pyo3(signature = (inputs, save_field, spec_text, base, report=None, preview=None, view=None, chunk=None, options=None, progress=None, same_crs=false, workers=None))]
#[allow(clippy::too_many_arguments)]
fn solve_files<'py>(
    py: Python<'py>,
    inputs: Vec<PathBuf>,
    save_field: PathBuf,
    spec_text: &str,
    base: &str,
    report: Option<PathBuf>,
    preview: Option<PathBuf>,
    view: Option<Bound<'py, PyDict>>,
    chunk: Option<Bound<'py, PyAny>>,
    options: Option<Bound<'py, PyDict>>,
    progress: Option<Py<PyAny>>,
    same_crs: bool,
    workers: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let params = self::options(options.as_ref())?.params().map_err(py_err)?;
    let workers = workers.map(|w| std::sync::Arc::new(workers::PyWorkers::new(w)));
    let registration = workers
        .as_ref()
        .map(|w| rigidcells::internal::solve::schwarz::register(std::sync::Arc::clone(w) as _));
    let params = params.with_workers(registration.as_ref().map(|r| r.id()));
    let spec = self::spec(spec_text, base)?;
    let first = inputs.first().map_or(Path::new(""), PathBuf::as_path);
    let (view, strain) = self::view(view.as_ref(), first)?;
    let chunk = self::chunk(chunk)?;
    let outputs = pipeline::Outputs {
        save_field: Some(&save_field),
        report: report.as_deref(),
        preview: preview.as_deref().map(|p| (p, view, strain)),
        keep_existing: false,
        chunk: Some(chunk),
    };
    let observer = PyObserver::new(progress);
    let result = py
        .detach(|| pipeline::solve_files(&inputs, &spec, &params, (&outputs, same_crs), &observer));
    drop(registration);
    if let (Err(_), Some(raised)) = (&result, workers.and_then(|w| w.raised())) {
        return Err(raised);
    }
    let (_, _, report) = observer.result(result)?;
    report_dict(py, &report)
}

/// The preview's view of a `view` dict (`azimuth`, `elevation`, `size` as (width, height),
/// `up` as "x", "y" or "z", `zoom`, `strain`), the command line's defaults for the rest.
fn view(d: Option<&Bound<'_, PyDict>>, input: &Path) -> PyResult<(View, bool)> {
    let mut view = View {
        up: rigidcells::internal::render::up_of(input),
        ..Default::default()
    };
    let mut strain = false;
    if let Some(d) = d {
        for (key, value) in d.iter() {
            let key: String = key.extract()?;
            if value.is_none() {
                continue;
            }
            let number = || {
                value.extract::<f64>().map_err(|_| {
                    PyTypeError::new_err(format!(
                        "{key} must be a number, got {}",
                        type_name(&value)
                    ))
                })
            };
            match key.as_str() {
                "azimuth" => view.azimuth = number()?,
                "elevation" => view.elevation = number()?,
                "zoom" => view.zoom = number()?,
                "strain" => {
                    strain = value
                        .extract::<bool>()
                        .map_err(|_| PyTypeError::new_err("strain must be True or False"))?
                }
                "size" => {
                    let (w, h): (i64, i64) = value.extract().map_err(|_| {
                        PyTypeError::new_err("size must be (width, height) in pixels")
                    })?;
                    let side =
                        |v: i64| u32::try_from(v).unwrap_or(if v < 0 { 0 } else { u32::MAX });
                    (view.width, view.height) = (side(w), side(h));
                }
                "up" => {
                    view.up = match value.extract::<String>().as_deref() {
                        Ok("x") => 0,
                        Ok("y") => 1,
                        Ok("z") => 2,
                        _ => return Err(PyValueError::new_err("up must be \"x\", \"y\" or \"z\"")),
                    }
                }
                _ => return Err(PyTypeError::new_err(format!("unexpected argument {key}"))),
            }
        }
    }
    view.check().map_err(py_err)?;
    Ok((view, strain))
}

/// `rigidcells apply` on a file: the field saved in `field` applied to `input`, written to
/// `output` (atomically). `outside`: `refuse` (default), `keep` or `extend`; `transfer`
/// (default: the field's own), `rbf_tolerance` and `memory_limit` as for `deform_file`. A field
/// solved in another coordinate system than the input's is refused unless `same_crs`.
#[pyfunction]
#[pyo3(signature = (field, input, output, outside=None, transfer=None, rbf_tolerance=None, memory_limit=None, chunk=None, progress=None, same_crs=false))]
#[allow(clippy::too_many_arguments)]
fn apply_file<'py>(
    py: Python<'py>,
    field: PathBuf,
    input: PathBuf,
    output: PathBuf,
    outside: Option<String>,
    transfer: Option<String>,
    rbf_tolerance: Option<f64>,
    memory_limit: Option<Bound<'py, PyAny>>,
    chunk: Option<Bound<'py, PyAny>>,
    progress: Option<Py<PyAny>>,
    same_crs: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let params = pipeline::ApplyParams {
        transfer: transfer
            .map(|t| named("transfer", Some(t), Transfer::Pu))
            .transpose()?,
        rbf_tolerance,
        outside: named("outside", outside, Outside::Refuse)?,
        memory: rigidcells::internal::memory::Budget::checked(
            memory_limit.map(|m| self::memory_limit(&m)).transpose()?,
        )
        .map_err(errors::py_err)?,
        same_crs,
    };
    let chunk = self::chunk(chunk)?;
    let observer = PyObserver::new(progress);
    let result = py.detach(|| -> rigidcells::Result<_> {
        rigidcells::internal::io::refuse_overwrite(&input, &output)?;
        pipeline::apply_file(&field, &input, &output, &params, chunk, &observer)
    });
    let info = observer.result(result)?;
    let d = PyDict::new(py);
    d.set_item("samples", info.samples)?;
    d.set_item("notes", said_text(&info.notes))?;
    d.set_item("warnings", said_text(&info.deform.warnings))?;
    d.set_item("seconds", info.seconds_write)?;
    Ok(d)
}

/// LAS record integers ((n, 3), of any integer type, as int64) as coordinates in the frame
/// `scale`, `offset`: what the command line reads from a LAS file with that header.
#[pyfunction]
fn decode_las<'py>(
    py: Python<'py>,
    records: PyReadonlyArray2<'py, i64>,
    scale: [f64; 3],
    offset: [f64; 3],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let v = records.as_array();
    if v.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "records must be an (n, 3) array, got {:?}",
            v.shape()
        )));
    }
    let rows: Vec<[i64; 3]> = v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect();
    let xyz = io::decode_coordinates(&rows, scale, offset).map_err(py_err)?;
    Ok(moved_array(py, &xyz))
}

/// `moved` ((n, 3) float64) as LAS record integers (int32, each rounded to the nearest step as
/// the command line's LAS writer rounds it) in the frame `scale`, `offset`. With `reframe`, an
/// axis whose coordinates do not fit gets the offset (and scale) the command line would give
/// its output; without, that is a `ValueError`. Returns the records, the frame's scale and
/// offset, and a note per re-framed axis.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn encode_las<'py>(
    py: Python<'py>,
    moved: PyReadonlyArray2<'py, f64>,
    scale: [f64; 3],
    offset: [f64; 3],
    reframe: bool,
) -> PyResult<(Bound<'py, PyArray2<i32>>, [f64; 3], [f64; 3], Vec<String>)> {
    let pts = self::points(&moved)?;
    let encoded = py
        .detach(|| io::encode_coordinates(&pts, scale, offset, reframe))
        .map_err(py_err)?;
    let flat: Vec<i32> = encoded.records.iter().flatten().copied().collect();
    let records = Array2::from_shape_vec((encoded.records.len(), 3), flat)
        .expect("n × 3")
        .into_pyarray(py);
    Ok((records, encoded.scale, encoded.offset, encoded.notes))
}

/// A spec given as JSON (from a Python dict) as TOML text.
#[pyfunction]
fn toml_from_json(json: &str) -> PyResult<String> {
    let value: toml::Value =
        serde_json::from_str(json).map_err(|e| PyValueError::new_err(format!("spec: {e}")))?;
    toml::to_string(&value).map_err(|e| PyValueError::new_err(format!("spec: {e}")))
}

/// The library's tables the package's faces are checked against: the keyword arguments of a
/// deformation (the options, in order) and the names each choice takes, keyed by its keyword.
#[pyfunction]
fn names(py: Python<'_>) -> PyResult<(Vec<String>, Bound<'_, PyDict>)> {
    fn all<T: Named>() -> Vec<&'static str> {
        T::ALL.iter().map(|v| v.name()).collect()
    }
    let keywords = pipeline::OPTION_NAMES
        .iter()
        .map(|n| n.replace('-', "_"))
        .collect();
    let choices = PyDict::new(py);
    choices.set_item("transfer", all::<Transfer>())?;
    choices.set_item("inside", all::<Inside>())?;
    choices.set_item("solver", all::<Method>())?;
    choices.set_item("loose_parts", all::<LooseParts>())?;
    choices.set_item("outside", all::<Outside>())?;
    Ok((keywords, choices))
}

#[pymodule]
fn _rigidcells(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FormatError", m.py().get_type::<FormatError>())?;
    m.add("TurnNotHeldError", m.py().get_type::<TurnNotHeldError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<Field>()?;
    m.add_class::<Session>()?;
    m.add_class::<workers::BlockFactor>()?;
    m.add_function(wrap_pyfunction!(deform, m)?)?;
    m.add_function(wrap_pyfunction!(solve, m)?)?;
    m.add_function(wrap_pyfunction!(estimate, m)?)?;
    m.add_function(wrap_pyfunction!(deform_file, m)?)?;
    m.add_function(wrap_pyfunction!(apply_file, m)?)?;
    m.add_function(wrap_pyfunction!(solve_files, m)?)?;
    m.add_function(wrap_pyfunction!(toml_from_json, m)?)?;
    m.add_function(wrap_pyfunction!(observer::py_caller, m)?)?;
    m.add_function(wrap_pyfunction!(decode_las, m)?)?;
    m.add_function(wrap_pyfunction!(encode_las, m)?)?;
    m.add_function(wrap_pyfunction!(names, m)?)?;
    Ok(())
}
