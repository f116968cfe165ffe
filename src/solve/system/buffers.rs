//! The storage a Gauss-Newton iteration keeps from one iteration to the next.

use faer::dyn_stack::MemBuffer;
use faer::sparse::SymbolicSparseColMat;

/// The storage of an iteration: the assembled values (one slot per block entry), the numeric
/// factor and faer's scratch. Kept with the system: allocating the factor (45 MB at 29k
/// unknowns) and its scratch anew each iteration faulted its pages in every time, and the step
/// took 119 ms instead of 87–94.
pub(super) struct Buffers {
    pub(super) values: Vec<f64>,
    pub(super) factor: Vec<f64>,
    pub(super) scratch: MemBuffer,
    /// The matrix's sparsity, moved into each iteration's matrix and taken back from it (a
    /// clone per iteration held 0.3 GiB more at the peak at 1.14M cells).
    pub(super) pattern: Option<SymbolicSparseColMat<u32>>,
    /// Each pair's gradient and curvature terms for its two cells, summed into the cells'
    /// after the pairs' parallel pass (192 bytes a pair: kept from one iteration of a
    /// minimization to the next, so that their pages are not mapped and zeroed anew every
    /// iteration).
    pub(super) pair_grad: Vec<f64>,
    pub(super) pair_curv: Vec<[f64; 6]>,
}

impl Default for Buffers {
    fn default() -> Self {
        Self {
            values: Vec::new(),
            factor: Vec::new(),
            scratch: MemBuffer::new(faer::dyn_stack::StackReq::EMPTY),
            pattern: None,
            pair_grad: Vec::new(),
            pair_curv: Vec::new(),
        }
    }
}
