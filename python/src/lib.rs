//! The Python extension of rigidcells (`rigidcells._rigidcells`): thin wrappers over the
//! library's `pipeline` functions, numpy arrays in and out, the GIL released around every
//! heavy call, and the library's errors as Python exceptions (`ValueError` for a bad spec or
//! parameter, `OSError` for I/O, `rigidcells.FormatError` for malformed files). The Python
//! package (`python/python/rigidcells/__init__.py`) adds specs as dicts or paths and numpy
//! structured arrays.

use std::path::{Path, PathBuf};

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray2};
use pyo3::create_exception;
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rigidcells::Error;
use rigidcells::cells::BuildParams;
use rigidcells::field::{Outside, SavedField, Transfer};
use rigidcells::io;
use rigidcells::names::{Named, UnknownName};
use rigidcells::pipeline::{self, DeformInfo, DeformParams};
use rigidcells::progress::Silent;
use rigidcells::rigid::Vect;
use rigidcells::spec::{EditSpec, parse_spec};

create_exception!(
    _rigidcells,
    FormatError,
    PyValueError,
    "A malformed or unreadable input file."
);

/// The library's error as a Python exception, by its exit code's class.
fn py_err(e: Error) -> PyErr {
    let text = e.to_string();
    match (&e, e.exit_code()) {
        (Error::Io { .. } | Error::Write { .. }, _) => PyOSError::new_err(text),
        (_, 3) => FormatError::new_err(text),
        (_, 4) => PyValueError::new_err(text),
        _ => PyRuntimeError::new_err(text),
    }
}

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

fn moved_array<'py>(py: Python<'py>, moved: &[Vect<3>]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = moved.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    Array2::from_shape_vec((moved.len(), 3), flat)
        .expect("n × 3")
        .into_pyarray(py)
}

fn spec(text: &str, base: &str) -> PyResult<EditSpec<3>> {
    parse_spec(text, Path::new(base), Path::new("spec")).map_err(py_err)
}

/// The transfer named `name` (default: the command line's, `pu`).
fn transfer(name: Option<&str>) -> PyResult<Transfer> {
    let Some(name) = name else {
        return Ok(Transfer::Pu);
    };
    name.parse().map_err(|e: UnknownName| {
        // The default first, as the package's documentation lists them.
        let order = [
            Transfer::Pu,
            Transfer::Rbf,
            Transfer::Blend,
            Transfer::BlendIdw,
        ];
        let expected = order.map(Named::name).to_vec();
        PyValueError::new_err(UnknownName { expected, ..e }.to_string())
    })
}

fn params(
    cell_size: Option<f64>,
    cells: Option<usize>,
    name: Option<&str>,
) -> PyResult<DeformParams> {
    Ok(DeformParams {
        build: BuildParams {
            cell_size,
            target_cells: cells,
            ..Default::default()
        },
        transfer: transfer(name)?,
        ..Default::default()
    })
}

/// The arguments `deform` and `solve` share, checked and converted.
#[allow(clippy::type_complexity)]
fn inputs(
    points: &PyReadonlyArray2<f64>,
    triangles: Option<&PyReadonlyArray2<i64>>,
    spec_text: &str,
    base: &str,
    cell_size: Option<f64>,
    cells: Option<usize>,
    transfer: Option<&str>,
) -> PyResult<(Vec<Vect<3>>, Vec<[u32; 3]>, EditSpec<3>, DeformParams)> {
    let pts = self::points(points)?;
    let tris = self::triangles(triangles, pts.len())?;
    Ok((
        pts,
        tris,
        self::spec(spec_text, base)?,
        params(cell_size, cells, transfer)?,
    ))
}

/// What a deformation did, as a dict.
fn info_dict<'py>(
    py: Python<'py>,
    info: &DeformInfo,
    samples: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("samples", samples)?;
    d.set_item("cells", info.solver.cells_final)?;
    d.set_item("iterations", info.solver.iterations)?;
    d.set_item(
        "energy",
        info.solver.energies.last().copied().unwrap_or(0.0),
    )?;
    d.set_item("converged", info.solver.converged)?;
    d.set_item("foldovers", (info.foldovers.1, info.foldovers.0))?;
    d.set_item("warnings", PyList::new(py, &info.warnings)?)?;
    let turns = PyList::empty(py);
    for t in &info.solver.turns {
        let c = PyDict::new(py);
        c.set_item("line", t.line)?;
        c.set_item("turn_asked_degrees", t.asked_degrees)?;
        c.set_item("turn_taken_degrees", t.taken_degrees)?;
        turns.append(c)?;
    }
    d.set_item("handle_turns", turns)?;
    let points = PyList::empty(py);
    for p in &info.control_points {
        let c = PyDict::new(py);
        c.set_item("id", &p.id)?;
        c.set_item("from", p.from.clone())?;
        c.set_item("wanted", p.wanted.clone())?;
        c.set_item("got", p.got.clone())?;
        c.set_item("residual", p.residual)?;
        points.append(c)?;
    }
    d.set_item("control_points", points)?;
    d.set_item(
        "control_rmse",
        rigidcells::control::rmse(&info.control_points),
    )?;
    Ok(d)
}

/// Deforms `points` ((n, 3) float64), with their `normals` when given, under the TOML `spec`
/// (relative file names against `base`); returns the moved points and what was done (with the
/// turned normals under `"normals"` when normals were given).
#[pyfunction]
#[pyo3(signature = (points, spec_text, base, triangles=None, normals=None, cell_size=None, cells=None, transfer=None))]
#[allow(clippy::too_many_arguments)]
fn deform<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    spec_text: &str,
    base: &str,
    triangles: Option<PyReadonlyArray2<'py, i64>>,
    normals: Option<PyReadonlyArray2<'py, f64>>,
    cell_size: Option<f64>,
    cells: Option<usize>,
    transfer: Option<&str>,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyDict>)> {
    let (pts, tris, spec, params) = inputs(
        &points,
        triangles.as_ref(),
        spec_text,
        base,
        cell_size,
        cells,
        transfer,
    )?;
    let nrm = match &normals {
        Some(n) => self::points(n)?,
        None => Vec::new(),
    };
    let (moved, moved_normals, _, info) = py
        .detach(|| pipeline::deform_oriented(&pts, &nrm, &tris, &spec, &params, &Silent))
        .map_err(py_err)?;
    let d = info_dict(py, &info, pts.len() as u64)?;
    if normals.is_some() {
        d.set_item("normals", moved_array(py, &moved_normals))?;
    }
    Ok((moved_array(py, &moved), d))
}

/// A solved field: apply it to samples, save it for `rigidcells apply`, load one.
#[pyclass(module = "rigidcells")]
struct Field {
    saved: SavedField<3>,
}

#[pymethods]
impl Field {
    /// Moves `points` ((n, 3) float64) through the field; samples beyond its margin are an
    /// error (as `rigidcells apply` refuses them).
    fn apply<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let mut pts = self::points(&points)?;
        let saved = &self.saved;
        py.detach(|| -> rigidcells::Result<()> {
            let deformer = saved.deformer_of(None, None, Outside::Refuse)?;
            rigidcells::field::apply(&deformer, &saved.field.origin, &mut pts);
            let outside = deformer.outside();
            if outside.count > 0 {
                return Err(Error::Param(format!(
                    "{} samples lie beyond the field's margin (the farthest {} from it)",
                    outside.count, outside.farthest
                )));
            }
            Ok(())
        })
        .map_err(py_err)?;
        Ok(moved_array(py, &pts))
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

    /// The number of cells.
    #[getter]
    fn cells(&self) -> usize {
        self.saved.field.centers.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "rigidcells.Field({} cells, transfer {})",
            self.cells(),
            self.saved.transfer
        )
    }
}

/// Solves the TOML `spec` over `points`; returns the field and what was done.
#[pyfunction]
#[pyo3(signature = (points, spec_text, base, triangles=None, cell_size=None, cells=None, transfer=None))]
#[allow(clippy::too_many_arguments)]
fn solve<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    spec_text: &str,
    base: &str,
    triangles: Option<PyReadonlyArray2<'py, i64>>,
    cell_size: Option<f64>,
    cells: Option<usize>,
    transfer: Option<&str>,
) -> PyResult<(Field, Bound<'py, PyDict>)> {
    let (pts, tris, spec, params) = inputs(
        &points,
        triangles.as_ref(),
        spec_text,
        base,
        cell_size,
        cells,
        transfer,
    )?;
    let (saved, _, info) = py
        .detach(|| pipeline::solve_points(&pts, &tris, &spec, &params, &Silent))
        .map_err(py_err)?;
    Ok((Field { saved }, info_dict(py, &info, pts.len() as u64)?))
}

/// `rigidcells deform` on a file: streams `input` into `output` (atomically), with the field
/// saved to `save_field` when given.
#[pyfunction]
#[pyo3(signature = (input, output, spec_text, base, save_field=None, cell_size=None, cells=None, transfer=None))]
#[allow(clippy::too_many_arguments)]
fn deform_file<'py>(
    py: Python<'py>,
    input: PathBuf,
    output: PathBuf,
    spec_text: &str,
    base: &str,
    save_field: Option<PathBuf>,
    cell_size: Option<f64>,
    cells: Option<usize>,
    transfer: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = self::spec(spec_text, base)?;
    let params = DeformParams {
        proxy_samples: Some(pipeline::FOLDOVER_SAMPLES),
        ..params(cell_size, cells, transfer)?
    };
    let (_, info) = py
        .detach(|| -> rigidcells::Result<_> {
            rigidcells::io::refuse_overwrite(&input, &output)?;
            pipeline::deform_file(
                &input,
                &output,
                &spec,
                &params,
                pipeline::CHUNK,
                save_field.as_deref(),
                &Silent,
            )
        })
        .map_err(py_err)?;
    let d = info_dict(py, &info.deform, info.samples)?;
    d.set_item("notes", PyList::new(py, &info.notes)?)?;
    Ok(d)
}

/// `rigidcells apply` on a file: the field saved in `field` applied to `input`, written to
/// `output` (atomically). `outside`: `refuse` (default), `keep` or `extend`.
#[pyfunction]
#[pyo3(signature = (field, input, output, outside=None))]
fn apply_file<'py>(
    py: Python<'py>,
    field: PathBuf,
    input: PathBuf,
    output: PathBuf,
    outside: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let outside = match outside {
        Some(name) => name
            .parse::<Outside>()
            .map_err(|e| PyValueError::new_err(e.to_string()))?,
        None => Outside::Refuse,
    };
    let params = pipeline::ApplyParams {
        outside,
        ..Default::default()
    };
    let info = py
        .detach(|| -> rigidcells::Result<_> {
            rigidcells::io::refuse_overwrite(&input, &output)?;
            pipeline::apply_file(&field, &input, &output, &params, pipeline::CHUNK, &Silent)
        })
        .map_err(py_err)?;
    let d = PyDict::new(py);
    d.set_item("samples", info.samples)?;
    d.set_item("notes", PyList::new(py, &info.notes)?)?;
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

#[pymodule]
fn _rigidcells(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FormatError", m.py().get_type::<FormatError>())?;
    m.add_class::<Field>()?;
    m.add_function(wrap_pyfunction!(deform, m)?)?;
    m.add_function(wrap_pyfunction!(solve, m)?)?;
    m.add_function(wrap_pyfunction!(deform_file, m)?)?;
    m.add_function(wrap_pyfunction!(apply_file, m)?)?;
    m.add_function(wrap_pyfunction!(toml_from_json, m)?)?;
    m.add_function(wrap_pyfunction!(decode_las, m)?)?;
    m.add_function(wrap_pyfunction!(encode_las, m)?)?;
    Ok(())
}
