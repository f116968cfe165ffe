//! Subdomains' blocks factored and solved by workers: the seam a solve spread over processes
//! plugs into ([`super::schwarz`] sends the blocks, `SolveParams::workers` names the workers).
//!
//! Each subdomain's block of the global step's Laplacian travels as a [`Block`] (its lower
//! triangle in its own numbering) to [`Workers::factor`], once per system; the answer
//! ([`BlockSolves`]) solves every block for the right-hand sides of each conjugate-gradient
//! iteration. A worker holds its blocks' [`BlockFactor`]s, what a process that solves blocks
//! (the Python package's Dask actors) builds from a `Block`. Workers are registered for the
//! length of a call ([`register`]) and named in the solve's parameters by a [`WorkersId`], so
//! that the parameters stay plain values.

use std::sync::{Arc, Mutex};

use faer::prelude::*;
use faer::sparse::Triplet;
use faer::sparse::linalg::solvers::Llt;

use super::laplacian::factor;
use crate::error::{Error, Result};

/// One subdomain's block as the process that holds it receives it: the lower triangle of
/// `A_k = R_k L R_kᵀ` in the block's own numbering (`rows[t] ≥ cols[t]`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Block {
    /// Rows (and columns) of the block.
    pub size: usize,
    /// Each entry's row.
    pub rows: Vec<u32>,
    /// Each entry's column.
    pub cols: Vec<u32>,
    /// Each entry's value.
    pub values: Vec<f64>,
}

impl Block {
    /// Its Cholesky factor; `None` where the block is not positive definite, or an entry
    /// lies outside it or above its diagonal.
    pub fn factor(&self) -> Option<BlockFactor> {
        let n = self.size;
        let mut lower = Vec::with_capacity(self.values.len());
        for ((&i, &j), &v) in self.rows.iter().zip(&self.cols).zip(&self.values) {
            let (i, j) = (i as usize, j as usize);
            if i >= n || j > i || !v.is_finite() {
                return None;
            }
            lower.push(Triplet::new(i, j, v));
        }
        let factor = factor(n, &lower)?;
        Some(BlockFactor { factor, n })
    }
}

/// A block's Cholesky factor, held by the process that solves it.
pub struct BlockFactor {
    factor: Llt<usize, f64>,
    n: usize,
}

impl BlockFactor {
    /// Rows of the block.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether the block has no rows.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// `A⁻¹ b` for `b` of columns of `len()` each, column after column; `None` where `b` is
    /// not whole columns.
    pub fn solve(&self, b: &[f64]) -> Option<Vec<f64>> {
        let n = self.n;
        if b.is_empty() {
            return Some(Vec::new());
        }
        if n == 0 || !b.len().is_multiple_of(n) {
            return None;
        }
        let d = b.len() / n;
        let mut x = Mat::<f64>::from_fn(n, d, |i, a| b[a * n + i]);
        crate::with_faer(|| self.factor.solve_in_place(x.as_mut()));
        Some((0..n * d).map(|k| x[(k % n, k / n)]).collect())
    }
}

/// Processes that hold the subdomains' blocks, one block each or several: each factors its
/// blocks once per system and solves them for the right-hand sides sent to it, so that no
/// process but its own holds a block's factor. Without workers this process factors and
/// solves every block itself. The Python package's Dask layer is one.
pub trait Workers: Send + Sync {
    /// Sends every block to the worker that will hold it, to factor; the answer solves them.
    /// An error (a block not positive definite, a worker lost) ends the solve.
    fn factor(&self, blocks: Vec<Block>) -> Result<Box<dyn BlockSolves>>;
}

/// The blocks factored by [`Workers`].
pub trait BlockSolves: Send + Sync {
    /// `A_k⁻¹ r_k` for every block `k`, in the blocks' order, each right-hand side of whole
    /// columns (column after column) and each answer the same shape. An error ends the solve.
    fn solve(&self, rhs: Vec<Vec<f64>>) -> Result<Vec<Vec<f64>>>;
}

/// Workers registered for the length of a call ([`register`]): what a solve's parameters
/// name them by, so that the parameters stay plain values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct WorkersId(u64);

/// The last id given, and the workers registered now by id.
struct Registry {
    last: u64,
    workers: Vec<(u64, Arc<dyn Workers>)>,
}

static REGISTERED: Mutex<Registry> = Mutex::new(Registry {
    last: 0,
    workers: Vec::new(),
});

/// Registers `workers` until the answer is dropped; its [`Registration::id`] goes in the solve's
/// parameters.
pub fn register(workers: Arc<dyn Workers>) -> Registration {
    let mut r = REGISTERED.lock().unwrap_or_else(|e| e.into_inner());
    r.last += 1;
    let id = r.last;
    r.workers.push((id, workers));
    Registration(WorkersId(id))
}

/// Keeps workers registered ([`register`]) while it lives.
pub struct Registration(WorkersId);

impl Registration {
    /// The id the solve's parameters name the workers by.
    pub fn id(&self) -> WorkersId {
        self.0
    }
}

impl Drop for Registration {
    fn drop(&mut self) {
        let mut r = REGISTERED.lock().unwrap_or_else(|e| e.into_inner());
        r.workers.retain(|(id, _)| *id != (self.0).0);
    }
}

/// The workers registered as `id`; an error once they are no longer registered.
pub fn registered(id: WorkersId) -> Result<Arc<dyn Workers>> {
    let r = REGISTERED.lock().unwrap_or_else(|e| e.into_inner());
    r.workers
        .iter()
        .find(|(k, _)| *k == id.0)
        .map(|(_, w)| Arc::clone(w))
        .ok_or_else(|| Error::solver("the workers given for the subdomains are gone"))
}
