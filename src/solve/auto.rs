//! Which linear solver [`Method::Auto`](super::Method::Auto) takes for a system: the count of
//! free cells, their sizes, and the fill of their Cholesky factor, estimated before the
//! system's own symbolic analysis.

use faer::Side;
use faer::sparse::linalg::cholesky::{
    SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering, factorize_symbolic_cholesky,
};
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
    let nodes = free_cells.len();
    let fill = graph_fill(nodes, &free_edges(complex, free_cells, pairs), dof);
    fill.map_or(0, |f| (f.nodes_len as usize) * dof / nodes.max(1))
}

/// The pairs of `pairs` (indices into `complex.pairs`) whose two cells are both among
/// `free_cells`, as pairs of positions in `free_cells`.
pub(super) fn free_edges<const D: usize>(
    complex: &CellComplex<D>,
    free_cells: &[u32],
    pairs: &[u32],
) -> Vec<[u32; 2]> {
    let mut node = vec![u32::MAX; complex.len()];
    for (k, &c) in free_cells.iter().enumerate() {
        node[c as usize] = k as u32;
    }
    pairs
        .iter()
        .filter_map(|&p| {
            let pr = &complex.pairs[p as usize];
            let (a, b) = (node[pr.i as usize], node[pr.j as usize]);
            (a != u32::MAX && b != u32::MAX).then_some([a, b])
        })
        .collect()
}

/// The Cholesky factor of a graph's matrix with a `dof × dof` block per node and per edge,
/// from the symbolic analysis of the graph itself (AMD, as the system's own): what its
/// numeric factorization stores and costs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Fill {
    /// Entries of the graph's own factor (a node each): its scalar Laplacian's, as the position
    /// system factors it.
    pub nodes_len: f64,
    /// Entries of the factor of the `dof`-unknown system.
    pub len: f64,
    /// Multiply-adds of the system's numeric factorization.
    pub flops: f64,
    /// The largest dense update of the system's factorization (entries): faer's scratch.
    pub largest_update: f64,
}

/// The [`Fill`] of the graph of `nodes` nodes and `edges` (either order, no self-edge), or
/// `None` where faer cannot analyse it.
pub(crate) fn graph_fill(nodes: usize, edges: &[[u32; 2]], dof: usize) -> Option<Fill> {
    if nodes == 0 {
        return Some(Fill::default());
    }
    let llt = analyse_graph::<u32>(nodes, edges)?;
    let d = dof as f64;
    let mut fill = Fill {
        nodes_len: llt.len_val() as f64,
        ..Default::default()
    };
    match llt.raw() {
        SymbolicCholeskyRaw::Supernodal(s) => {
            let rows = s.col_ptr_for_row_idx();
            for (k, (&begin, &end)) in s
                .supernode_begin()
                .iter()
                .zip(s.supernode_end())
                .enumerate()
            {
                let w = d * (end - begin) as f64;
                let r = d * (rows[k + 1] - rows[k]) as f64;
                fill.len += w * (w + r);
                fill.flops += w * w * w / 3.0 + w * w * r + w * r * r;
                fill.largest_update = fill.largest_update.max(r * r);
            }
        }
        SymbolicCholeskyRaw::Simplicial(s) => {
            // Each node's column stands for `dof` columns of `dof` times its entries.
            let ptr = s.col_ptr();
            for j in 0..nodes {
                let c = d * (ptr[j + 1] - ptr[j]) as f64;
                fill.len += d * c;
                fill.flops += d * c * c;
            }
        }
    }
    Some(fill)
}

/// The symbolic Cholesky factorization of the graph of `nodes` nodes and `edges` (either
/// order, no self-edge) in AMD's order, or `None` where faer cannot analyse it: the fill of a
/// block matrix of that graph ([`graph_fill`]) and the order of its nodes
/// (`blocks::CoarseFactor`) are read from it, at a `dof²`-th of the scalar pattern's work.
pub(crate) fn analyse_graph<I: faer::Index>(
    nodes: usize,
    edges: &[[u32; 2]],
) -> Option<SymbolicCholesky<I>> {
    let at = |k: u32| I::truncate(k as usize);
    let mut indices: Vec<Pair<I, I>> = (0..nodes as u32).map(|k| Pair::new(at(k), at(k))).collect();
    indices.extend(
        edges
            .iter()
            .map(|&[a, b]| Pair::new(at(a.max(b)), at(a.min(b)))),
    );
    let (sym, _) = SymbolicSparseColMat::try_new_from_indices(nodes, nodes, &indices).ok()?;
    drop(indices);
    crate::with_faer(|| {
        factorize_symbolic_cholesky(
            sym.as_ref(),
            Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
    })
    .ok()
}
