//! The subdomains' blocks given to Python workers ([`PyWorkers`]): the library's
//! `schwarz::Workers` over a Python object, which `rigidcells.dask.solve_tiles` makes from
//! Dask actors.
//!
//! The object's `factor(blocks)` takes one `(size, rows, cols, values)` tuple a block (the
//! lower triangle of the block in its own numbering: `uint32`, `uint32` and `float64` arrays)
//! and returns an object whose `solve(rhs)` takes one `float64` array a block (its columns one
//! after the other) and returns the solutions in the same shapes. An exception either raises
//! ends the solve; it is kept and raised in place of the library's error, as it was raised.

use std::sync::{Arc, Mutex};

use numpy::{IntoPyArray, PyReadonlyArray1};
use pyo3::prelude::*;
use rigidcells::Error;
use rigidcells::internal::solve::schwarz::{Block, BlockSolves, Workers};

/// The exception a worker raised, kept for the call to raise.
type Kept = Arc<Mutex<Option<PyErr>>>;

/// A Python object as the subdomains' workers.
pub(crate) struct PyWorkers {
    workers: Py<PyAny>,
    raised: Kept,
}

impl PyWorkers {
    pub(crate) fn new(workers: Py<PyAny>) -> Self {
        Self {
            workers,
            raised: Arc::default(),
        }
    }

    /// The exception a worker raised, if one ended the solve.
    pub(crate) fn raised(&self) -> Option<PyErr> {
        self.raised.lock().unwrap_or_else(|e| e.into_inner()).take()
    }
}

/// Keeps `e` (the first one) for the call to raise, and says it as the library's error.
fn keep(raised: &Kept, e: PyErr) -> Error {
    let said = Error::solver(format!("a subdomains' worker failed: {e}"));
    let mut slot = raised.lock().unwrap_or_else(|e| e.into_inner());
    if slot.is_none() {
        *slot = Some(e);
    }
    said
}

impl Workers for PyWorkers {
    fn factor(&self, blocks: Vec<Block>) -> rigidcells::Result<Box<dyn BlockSolves>> {
        Python::attach(|py| -> PyResult<Box<dyn BlockSolves>> {
            let blocks: Vec<_> = blocks
                .into_iter()
                .map(|b| {
                    (
                        b.size,
                        b.rows.into_pyarray(py),
                        b.cols.into_pyarray(py),
                        b.values.into_pyarray(py),
                    )
                })
                .collect();
            let solves = self.workers.call_method1(py, "factor", (blocks,))?;
            Ok(Box::new(PySolves {
                solves,
                raised: Arc::clone(&self.raised),
            }))
        })
        .map_err(|e| keep(&self.raised, e))
    }
}

/// The blocks factored by Python workers.
struct PySolves {
    solves: Py<PyAny>,
    raised: Kept,
}

impl BlockSolves for PySolves {
    fn solve(&self, rhs: Vec<Vec<f64>>) -> rigidcells::Result<Vec<Vec<f64>>> {
        Python::attach(|py| -> PyResult<Vec<Vec<f64>>> {
            let rhs: Vec<_> = rhs.into_iter().map(|r| r.into_pyarray(py)).collect();
            let answers = self.solves.call_method1(py, "solve", (rhs,))?;
            answers
                .bind(py)
                .try_iter()?
                .map(|a| {
                    let a: PyReadonlyArray1<f64> = a?.extract()?;
                    Ok(a.as_array().to_vec())
                })
                .collect()
        })
        .map_err(|e| keep(&self.raised, e))
    }
}

/// Solves a block sent by the library: `factor(size, rows, cols, values)` once on the worker
/// that holds it, then `solve(rhs)` for every right-hand side (its columns one after the other).
#[pyclass(module = "rigidcells._rigidcells", frozen)]
pub(crate) struct BlockFactor {
    factor: rigidcells::internal::solve::schwarz::BlockFactor,
}

#[pymethods]
impl BlockFactor {
    /// Factors the block of `size` rows whose lower triangle has the entries
    /// `values[t]` at `(rows[t], cols[t])`; a `ValueError` where it is not positive definite.
    #[new]
    fn new(
        py: Python<'_>,
        size: usize,
        rows: PyReadonlyArray1<u32>,
        cols: PyReadonlyArray1<u32>,
        values: PyReadonlyArray1<f64>,
    ) -> PyResult<Self> {
        let block = Block {
            size,
            rows: rows.as_array().to_vec(),
            cols: cols.as_array().to_vec(),
            values: values.as_array().to_vec(),
        };
        let lengths =
            block.rows.len() == block.cols.len() && block.cols.len() == block.values.len();
        let factor = lengths
            .then(|| py.detach(|| block.factor()))
            .flatten()
            .ok_or_else(|| {
                pyo3::exceptions::PyValueError::new_err(format!(
                    "the block of {size} rows is not positive definite, or its entries lie \
                     outside its lower triangle"
                ))
            })?;
        Ok(Self { factor })
    }

    /// Rows of the block.
    fn __len__(&self) -> usize {
        self.factor.len()
    }

    /// The block's inverse applied to `rhs` (whole columns of `len(self)` each).
    fn solve<'py>(
        &self,
        py: Python<'py>,
        rhs: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
        let b = rhs.as_array().to_vec();
        let x = py.detach(|| self.factor.solve(&b)).ok_or_else(|| {
            pyo3::exceptions::PyValueError::new_err(format!(
                "a right-hand side of {} values is not whole columns of {}",
                b.len(),
                self.factor.len()
            ))
        })?;
        Ok(x.into_pyarray(py))
    }
}
