//! Which linear solver [`Method::Auto`](super::Method::Auto) takes for a system: the count of
//! free cells, their sizes, and the fill of their Cholesky factor, estimated before the
//! system's own symbolic analysis.

use faer::Side;
use faer::sparse::linalg::cholesky::{SymmetricOrdering, factorize_symbolic_cholesky};
use faer::sparse::{Pair, SymbolicSparseColMat};

use crate::cells::CellComplex;

/// Free cells past which `auto` solves a complex of one-size cells by the multilevel path: on
/// the 10M-point terrain the factorization is the faster up to 80k free cells (12.3 s against
/// 15.1 s), the multilevel path from 229k (27 s against 42 s; at 742k in half the memory).
pub(super) const MULTILEVEL_FROM: usize = 100_000;

/// Entries of the Cholesky factor per unknown past which `auto` takes the multilevel path for
/// cells of one size (where the hierarchy has a level to build, past `multilevel::COARSEST` free cells;
/// the grid groups merge a solid's large interior cells poorly, and the bunny at 20k cells of
/// four sizes factors in 15 s against 38 s multilevel): the factor's work grows as their
/// square. The entries are estimated before the system's own analysis (`cell_fill`: within
/// 15 % of the true count on these scenes, 300 against 268 on the tube at 5.5k cells, 121
/// against 140 on the vegetation at 5 m). Measured one `deform` process each (BENCHMARKS.md,
/// "Which solver `auto` takes"): the one-cell-thick terrain at 82k cells has 150 and factors
/// faster (9.1 s against 13.1 s); the vegetation scan at 5 m, 140, takes the same either way;
/// the tube at 5.5k, 10k and 20k cells (269, 316, 413) and the vegetation scan at 2.5 m (290)
/// solve 1.1–1.6 times faster by the multilevel path.
pub(super) const MULTILEVEL_FILL: usize = 200;

/// The entries per unknown of the Cholesky factor of the system on `free_cells` (`dof`
/// unknowns each) coupled by the face pairs `pairs` (indices into `complex.pairs`),
/// estimated from the symbolic analysis of the free cells' adjacency (a node per cell: a
/// thirty-sixth of the entries, and so of the analysis' cost): each node's column of the
/// factor stands for `dof` columns of `dof` times its entries.
pub(super) fn cell_fill<const D: usize>(
    complex: &CellComplex<D>,
    free_cells: &[u32],
    pairs: &[u32],
    dof: usize,
) -> usize {
    let mut node = vec![u32::MAX; complex.len()];
    for (k, &c) in free_cells.iter().enumerate() {
        node[c as usize] = k as u32;
    }
    let nodes = free_cells.len();
    let mut indices: Vec<Pair<u32, u32>> =
        (0..nodes as u32).map(|k| Pair { row: k, col: k }).collect();
    for &p in pairs {
        let pr = &complex.pairs[p as usize];
        let (a, b) = (node[pr.i as usize], node[pr.j as usize]);
        if a != u32::MAX && b != u32::MAX {
            indices.push(Pair {
                row: a.max(b),
                col: a.min(b),
            });
        }
    }
    let analysed = SymbolicSparseColMat::try_new_from_indices(nodes, nodes, &indices)
        .ok()
        .and_then(|(sym, _)| {
            crate::with_faer(|| {
                factorize_symbolic_cholesky(
                    sym.as_ref(),
                    Side::Lower,
                    SymmetricOrdering::Amd,
                    Default::default(),
                )
            })
            .ok()
        });
    analysed.map_or(0, |llt| dof * llt.len_val() / nodes.max(1))
}
