//! The live `Session` of the Python extension: a [`Live`] deformation behind a lock, so that
//! calls from several Python threads wait their turn (each with the GIL released) instead of
//! failing on a borrowed object. A call from within a call (a progress callback that touches
//! its session) would wait for itself: the lock knows the caller that holds it
//! ([`crate::observer::caller`]) and refuses it with a `RuntimeError`.

use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use numpy::{PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rigidcells::Vect;
use rigidcells::internal::spec::parse_poses;
use rigidcells::{Live, Step};

use crate::observer::caller;
use crate::{
    PyObserver, classes, moved_array, options, points, py_err, report_dict, said, spec, triangles,
};

/// A live deformation of samples in memory ([`Live`]): the cells built once, a spec solved
/// from rest, then poses dragged a short solver step at a time, previewed by the blend,
/// and released through the transfer. Every heavy call releases the GIL, so a face may run
/// it on a thread of its own; calls from several threads run one at a time.
#[pyclass(module = "rigidcells._rigidcells", frozen)]
pub(crate) struct Session {
    live: Mutex<Live>,
    /// The caller whose call holds `live` ([`caller`]; 0: none).
    holder: AtomicU64,
    /// The points' normals (one a point, or none), turned by the release.
    normals: Vec<Vect<3>>,
    /// The number of cells and the finest cells' edge (the cells never change).
    cells: usize,
    cell_size: f64,
}

/// Said when a call on a session comes from within a call on it.
const NESTED: &str = "this Session is busy with the call that runs this code (a progress \
    callback, or code it runs): use the session after that call returns";

/// Clears a session's holder when its call ends (also when it unwinds).
struct Held<'a>(&'a AtomicU64);

impl Drop for Held<'_> {
    fn drop(&mut self) {
        self.0.store(0, Ordering::SeqCst);
    }
}

impl Session {
    /// `f` on the live deformation, with the GIL released, once no other call holds it; a
    /// call from within the holding call is refused, as it would wait for itself. Only the
    /// holder stores its own token in `holder`, so a caller finds its token there exactly
    /// while its own call holds the lock.
    fn with<T: Send>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut Live, &[Vect<3>]) -> T + Send,
    ) -> PyResult<T> {
        let me = caller();
        if self.holder.load(Ordering::SeqCst) == me {
            return Err(PyRuntimeError::new_err(NESTED));
        }
        py.detach(|| {
            let mut live = self.live.lock().map_err(|_| {
                PyRuntimeError::new_err(
                    "this Session is unusable: a call on it panicked: start a new Session",
                )
            })?;
            self.holder.store(me, Ordering::SeqCst);
            let _held = Held(&self.holder);
            Ok(f(&mut live, &self.normals))
        })
    }
}

/// What a step of a [`Session`] did, as a dict.
fn step_dict<'py>(py: Python<'py>, step: Option<&Step>) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    // Nothing constrained: nothing to solve, and the samples rest.
    d.set_item("converged", step.is_none_or(|s| s.solver.converged))?;
    let step = step.cloned().unwrap_or_default();
    d.set_item("iterations", step.solver.iterations)?;
    d.set_item("from_rest", step.from_rest)?;
    d.set_item("seconds", step.seconds)?;
    d.set_item("warnings", said(py, &step.warnings)?)?;
    Ok(d)
}

#[pymethods]
impl Session {
    /// Builds the cells of `points` ((n, 3) float64, with `triangles`, their LAS `classes`
    /// (one a point) for the spec's classification regions, and `normals` to turn at the
    /// release) with the `options`.
    #[new]
    #[pyo3(signature = (points, triangles=None, normals=None, options=None, classes=None))]
    fn new(
        py: Python<'_>,
        points: PyReadonlyArray2<'_, f64>,
        triangles: Option<PyReadonlyArray2<'_, i64>>,
        normals: Option<PyReadonlyArray2<'_, f64>>,
        options: Option<Bound<'_, PyDict>>,
        classes: Option<PyReadonlyArray1<'_, u8>>,
    ) -> PyResult<Self> {
        let params = self::options(options.as_ref())?.params().map_err(py_err)?;
        let pts = self::points(&points)?;
        let tris = self::triangles(triangles.as_ref(), pts.len())?;
        let normals = match &normals {
            Some(n) => self::points(n)?,
            None => Vec::new(),
        };
        if !normals.is_empty() && normals.len() != pts.len() {
            return Err(PyValueError::new_err(format!(
                "normals: {} for {} points; give one per point, or none",
                normals.len(),
                pts.len()
            )));
        }
        let classes = self::classes(classes.as_ref());
        let live = py
            .detach(|| Live::new(pts, &tris, classes, params))
            .map_err(py_err)?;
        Ok(Self {
            cells: live.complex().len(),
            cell_size: live.complex().grid.finest_size(),
            live: Mutex::new(live),
            holder: AtomicU64::new(0),
            normals,
        })
    }

    /// Moves to the TOML `spec` with at most `iterations` solver steps (each one Gauss-Newton
    /// iteration or `DRAG_LOCAL_GLOBAL` local-global ones; all it takes when None): warm when
    /// only its handles' poses changed, else from rest.
    #[pyo3(signature = (spec_text, base, iterations=None, progress=None))]
    fn solve<'py>(
        &self,
        py: Python<'py>,
        spec_text: &str,
        base: &str,
        iterations: Option<usize>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let spec = self::spec(spec_text, base)?;
        let observer = PyObserver::new(progress);
        let solved = self.with(py, |live, _| {
            let most = iterations.unwrap_or(live.params().solve().max_iterations);
            live.solve(spec, most, &observer)
        })?;
        let step = observer.finished(solved)?;
        step_dict(py, step.as_ref())
    }

    /// The last spec with its handles posed as the TOML `poses` say (one `[[handle]]` table
    /// a handle, its motion alone), its pins going to `pins` ((k, 3), one a pin, or none) and
    /// its targets pulling towards `targets` ((t, 3), one a target, or none), with at most
    /// `iterations` solver steps.
    #[pyo3(signature = (poses_text, iterations, pins=None, targets=None))]
    fn pose<'py>(
        &self,
        py: Python<'py>,
        poses_text: &str,
        iterations: usize,
        pins: Option<PyReadonlyArray2<'py, f64>>,
        targets: Option<PyReadonlyArray2<'py, f64>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        // Named as a spec, so that the package says its errors by key path.
        let poses = parse_poses::<3>(poses_text, Path::new("spec")).map_err(py_err)?;
        let finite = |given: &Option<PyReadonlyArray2<'py, f64>>, what: &str| {
            let points = match given {
                Some(p) => self::points(p)?,
                None => Vec::new(),
            };
            if let Some(k) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
                return Err(PyValueError::new_err(format!(
                    "{what}[{k}]: {:?} is not 3 finite numbers",
                    points[k].as_slice()
                )));
            }
            Ok(points)
        };
        let (pins, targets) = (finite(&pins, "pins")?, finite(&targets, "targets")?);
        let step = self
            .with(py, |live, _| live.pose(&poses, &pins, &targets, iterations))?
            .map_err(py_err)?;
        step_dict(py, Some(&step))
    }

    /// One more iteration when the last step stopped short of converging; whether it ran.
    fn refine(&self, py: Python<'_>) -> PyResult<bool> {
        let refined = self.with(py, |live, _| live.refine())?;
        Ok(refined.map_err(py_err)?.is_some())
    }

    /// Whether the last step converged.
    #[getter]
    fn converged(&self, py: Python<'_>) -> PyResult<bool> {
        self.with(py, |live, _| live.converged())
    }

    /// The number of cells.
    #[getter]
    fn cells(&self) -> usize {
        self.cells
    }

    /// The finest cells' edge.
    #[getter]
    fn cell_size(&self) -> f64 {
        self.cell_size
    }

    /// The samples moved by the cells' current motions, blended: the preview of a pose.
    fn preview<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let moved = self.with(py, |live, _| live.preview())?.map_err(py_err)?;
        Ok(moved_array(py, &moved))
    }

    /// The last spec's deformation through the transfer, converged first; the moved samples
    /// and what was done (with the turned normals under `"normals"` when normals were given).
    #[pyo3(signature = (progress=None))]
    fn release<'py>(
        &self,
        py: Python<'py>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyDict>)> {
        let observer = PyObserver::new(progress);
        let start = Instant::now();
        let released = self.with(py, |live, normals| -> rigidcells::Result<_> {
            let (moved, turned, solution, info) = live.release(normals, &observer)?;
            let n = moved.len() as u64;
            let seconds = start.elapsed().as_secs_f64();
            let report = rigidcells::Report::of_samples(
                solution.as_ref(),
                &info,
                n,
                (live.points(), &moved),
                seconds,
            );
            Ok((moved, turned, report))
        })?;
        let (moved, turned, report) = observer.finished(released)?;
        let d = report_dict(py, &report)?;
        if !self.normals.is_empty() {
            d.set_item("normals", moved_array(py, &turned))?;
        }
        Ok((moved_array(py, &moved), d))
    }
}
