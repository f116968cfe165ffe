//! Block-sparse symmetric matrices of `dof × dof` blocks (one per cell with freedom and one
//! per pair of face neighbors), in `f64` or `f32`, and the small dense block arithmetic the
//! multilevel solve ([`super::multilevel`]) builds its levels with.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::{
    LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Mat, Side};
use rayon::prelude::*;

use crate::rigid::MAX_DOF;

/// The number type of a matrix's entries: `f64`, or `f32` for the copies the smoother reads
/// (half the memory traffic; products are summed in `f64`).
pub(crate) trait Entry: Copy + Send + Sync + Into<f64> {}
impl Entry for f32 {}
impl Entry for f64 {}

/// A symmetric matrix of `dof × dof` blocks: a block per node on the diagonal and a block per
/// edge `[a, b]` (rows of `a`, columns of `b`; its transpose is the `[b, a]` block).
pub(crate) struct BlockMatrix<S: Entry = f64> {
    pub(super) dof: usize,
    pub(super) n: usize,
    pub(super) diag: Vec<S>,
    pub(super) edges: Vec<[u32; 2]>,
    pub(super) blocks: Vec<S>,
    /// The edges of each node: `incident[start[a]..start[a + 1]]`, each `2 · edge + side`
    /// (side 1: the node is the edge's second).
    pub(super) start: Vec<u32>,
    pub(super) incident: Vec<u32>,
}

impl<S: Entry> BlockMatrix<S> {
    /// The matrix with `diag` (`n` full blocks, row-major) and `edges` with their `blocks`.
    pub fn new(dof: usize, n: usize, diag: Vec<S>, edges: Vec<[u32; 2]>, blocks: Vec<S>) -> Self {
        let mut start = vec![0u32; n + 1];
        for e in &edges {
            start[e[0] as usize + 1] += 1;
            start[e[1] as usize + 1] += 1;
        }
        for a in 0..n {
            start[a + 1] += start[a];
        }
        let mut fill = start.clone();
        let mut incident = vec![0u32; 2 * edges.len()];
        for (k, e) in edges.iter().enumerate() {
            for side in 0..2 {
                let a = e[side] as usize;
                incident[fill[a] as usize] = 2 * k as u32 + side as u32;
                fill[a] += 1;
            }
        }
        Self {
            dof,
            n,
            diag,
            edges,
            blocks,
            start,
            incident,
        }
    }

    /// The matrix without entries (a level waiting for [`Hierarchy::refresh`]).
    pub(super) fn empty(dof: usize) -> Self {
        Self::new(dof, 0, Vec::new(), Vec::new(), Vec::new())
    }

    /// Unknowns.
    pub fn len(&self) -> usize {
        self.n * self.dof
    }

    /// `y = H x`.
    pub fn mul(&self, x: &[f64], y: &mut [f64]) {
        match self.dof {
            6 => self.mul_blocks::<6>(x, y),
            3 => self.mul_blocks::<3>(x, y),
            d => unreachable!("blocks of {d} unknowns"),
        }
    }

    /// `y = H x` for blocks of `N` unknowns (a constant, so the block products unroll).
    pub(super) fn mul_blocks<const N: usize>(&self, x: &[f64], y: &mut [f64]) {
        let bb = N * N;
        let at = |v: &[f64], i: usize| -> [f64; N] { v[i * N..(i + 1) * N].try_into().unwrap() };
        y.par_chunks_mut(N).enumerate().for_each(|(a, ya)| {
            let xa = at(x, a);
            let da = &self.diag[a * bb..(a + 1) * bb];
            let mut acc = [0.0; N];
            for r in 0..N {
                for c in 0..N {
                    acc[r] += da[r * N + c].into() * xa[c];
                }
            }
            for &e in &self.incident[self.start[a] as usize..self.start[a + 1] as usize] {
                let (k, side) = ((e >> 1) as usize, (e & 1) as usize);
                let xo = at(x, self.edges[k][1 - side] as usize);
                let b = &self.blocks[k * bb..(k + 1) * bb];
                if side == 0 {
                    for r in 0..N {
                        for c in 0..N {
                            acc[r] += b[r * N + c].into() * xo[c];
                        }
                    }
                } else {
                    for c in 0..N {
                        for r in 0..N {
                            acc[r] += b[c * N + r].into() * xo[c];
                        }
                    }
                }
            }
            ya.copy_from_slice(&acc);
        });
    }
}

impl BlockMatrix {
    /// The same matrix in `f32`.
    pub(super) fn to_f32(&self) -> BlockMatrix<f32> {
        BlockMatrix {
            dof: self.dof,
            n: self.n,
            diag: self.diag.par_iter().map(|&v| v as f32).collect(),
            edges: self.edges.clone(),
            blocks: self.blocks.par_iter().map(|&v| v as f32).collect(),
            start: self.start.clone(),
            incident: self.incident.clone(),
        }
    }

    /// The off-diagonal blocks of row `i`: each neighbor `j` with `H_ij` (the stored block, or
    /// its transpose where `i` is the edge's second node).
    pub(super) fn row(&self, i: usize) -> impl Iterator<Item = (usize, Block)> + '_ {
        let bb = self.dof * self.dof;
        self.incident[self.start[i] as usize..self.start[i + 1] as usize]
            .iter()
            .map(move |&e| {
                let (k, side) = ((e >> 1) as usize, (e & 1) as usize);
                let b = &self.blocks[k * bb..(k + 1) * bb];
                let block = if side == 0 {
                    let mut out = [0.0; MAX_DOF * MAX_DOF];
                    out[..bb].copy_from_slice(b);
                    out
                } else {
                    transpose(b, self.dof)
                };
                (self.edges[k][1 - side] as usize, block)
            })
    }

    /// The inverses of the diagonal blocks (a tiny multiple of the largest diagonal entry added
    /// to a block that is not positive definite, growing a hundredfold up to eight times; a
    /// block still not invertible, such as one holding a NaN, smooths by `1/scale`, where a
    /// loop without a bound would hang).
    pub(super) fn block_inverses(&self) -> Vec<f64> {
        let d = self.dof;
        let bb = d * d;
        let scale = (0..self.len())
            .map(|i| self.diag[(i / d) * bb + (i % d) * (d + 1)])
            .fold(0.0f64, f64::max)
            .max(f64::MIN_POSITIVE);
        let mut inv = vec![0.0; self.n * bb];
        inv.par_chunks_mut(bb).enumerate().for_each(|(a, out)| {
            let block = &self.diag[a * bb..(a + 1) * bb];
            let inverted = std::iter::once(0.0)
                .chain((0..8).map(|k| 1e-12 * scale * 100f64.powi(k)))
                .any(|eps| invert_spd(block, d, eps, out));
            if !inverted {
                out.fill(0.0);
                let fallback = if scale.is_finite() { 1.0 / scale } else { 0.0 };
                for r in 0..d {
                    out[r * d + r] = fallback;
                }
            }
        });
        inv
    }
}

/// A `d × d` block, row-major, in the first `d²` entries (`d ≤ MAX_DOF`): products of blocks
/// live on the stack, not in an allocation each.
pub(super) type Block = [f64; MAX_DOF * MAX_DOF];

/// Adds `m` into the block of `g` in a short sparse row of blocks.
pub(super) fn accumulate(row: &mut Vec<(u32, Block)>, g: u32, m: &Block) {
    match row.iter_mut().find(|(h, _)| *h == g) {
        Some((_, b)) => add(b, m),
        None => row.push((g, *m)),
    }
}

pub(super) fn matmul(x: &[f64], y: &[f64], d: usize) -> Block {
    let mut out = [0.0; MAX_DOF * MAX_DOF];
    mul_add(&mut out, x, false, y, d);
    out
}

/// `out += x y` (`x` transposed with `transpose`) for `d × d` blocks stored row by row,
/// skipping the zero entries of `x` (a rigid prolongation block is mostly zeros).
pub(super) fn mul_add(out: &mut [f64], x: &[f64], transpose: bool, y: &[f64], d: usize) {
    match d {
        6 => mul_add_n::<6>(out, x, transpose, y),
        3 => mul_add_n::<3>(out, x, transpose, y),
        _ => mul_add_any(out, x, transpose, y, d),
    }
}

/// [`mul_add`] for blocks of a constant size (the loops unroll).
pub(super) fn mul_add_n<const N: usize>(out: &mut [f64], x: &[f64], transpose: bool, y: &[f64]) {
    mul_add_any(out, x, transpose, y, N)
}

#[inline(always)]
pub(super) fn mul_add_any(out: &mut [f64], x: &[f64], transpose: bool, y: &[f64], d: usize) {
    for r in 0..d {
        for k in 0..d {
            let v = if transpose {
                x[k * d + r]
            } else {
                x[r * d + k]
            };
            if v != 0.0 {
                for c in 0..d {
                    out[r * d + c] += v * y[k * d + c];
                }
            }
        }
    }
}

/// The sparse Cholesky factor of the coarsest level, with its pattern's analysis (the
/// pattern, where its entries come from, and the symbolic factorization), which a later
/// hierarchy of the same groups reuses: within a load step every rebuild groups the same
/// cells, and on the 2.5 m vegetation scene (10.8k coarse nodes, 96k edges) the pattern and
/// the analysis took 0.5 s of the factor's 1.5 s.
///
/// **Ordered by nodes.** The scalar pattern is laid out by columns from the edges (no sort of
/// its entries), and its fill-reducing order found on the graph of the nodes (AMD), each node's
/// `dof` unknowns kept together, rather than on the scalar pattern, `dof²` times as large:
/// every unknown of a node has the same neighbors, so the scalar order finds much the same
/// elimination at `dof²` times the work. On the 2.5 m hilly strip's coarsest level (13.9k
/// nodes, 114k edges) the analysis takes 0.47 s instead of 0.70 s, for a factor of the same
/// size (BENCHMARKS.md §3, "The coarsest level ordered by its nodes").
///
/// **In single precision.** The factor is a preconditioner's coarse correction, which
/// conjugate gradients need only to a few digits: its values are `f32` (faer's kernels take
/// twice the entries a vector instruction, and the factor is half the memory to make and to
/// read in each cycle's triangular solves). A matrix that is not positive definite to `f32`'s
/// rounding (the pivots of an ill-conditioned level) is factored again in `f64`. On the 2.5 m
/// hilly strip the numeric factor takes 0.35–0.44 s instead of 0.75–1.02 s, for the same
/// conjugate-gradient iterations and energy (BENCHMARKS.md §3, "The coarsest level in single
/// precision").
pub(crate) struct CoarseFactor {
    n: usize,
    dof: usize,
    pub(super) edges: Vec<[u32; 2]>,
    /// The lower triangle's scalar pattern, by columns.
    pattern: SymbolicSparseColMat<usize>,
    /// Where the blocks below the diagonal come from.
    below: Below,
    symbolic: SymbolicCholesky<usize>,
    /// The factor's values (`None`: the matrix was not positive definite).
    pub(super) values: Option<Values>,
}

/// A factor's values: in `f32` where the matrix factors in single precision, else `f64`.
pub(super) enum Values {
    Single(Vec<f32>),
    Double(Vec<f64>),
}

/// Below each node `j`, the blocks of its column, `below[start[j]..start[j + 1]]`: `(node
/// below, edge, whether the edge's first node is `j`)`, in the order of the nodes below.
struct Below {
    start: Vec<usize>,
    below: Vec<(u32, u32, bool)>,
}

impl CoarseFactor {
    /// `A⁻¹ b`, or `None` where the matrix was not positive definite.
    pub(super) fn solve(&self, b: &[f64]) -> Option<Vec<f64>> {
        Some(match self.values.as_ref()? {
            Values::Single(values) => {
                let x = solve_with(&self.symbolic, values, b.iter().map(|&v| v as f32));
                x.into_iter().map(f64::from).collect()
            }
            Values::Double(values) => solve_with(&self.symbolic, values, b.iter().copied()),
        })
    }
}

/// `L⁻ᵀ L⁻¹ b` for the factor `values` of `symbolic`.
fn solve_with<T: faer::traits::RealField + Copy>(
    symbolic: &SymbolicCholesky<usize>,
    values: &[T],
    b: impl ExactSizeIterator<Item = T>,
) -> Vec<T> {
    let par = faer::get_global_parallelism();
    let mut x = Mat::<T>::zeros(b.len(), 1);
    for (r, v) in b.enumerate() {
        x[(r, 0)] = v;
    }
    let mut scratch = MemBuffer::new(symbolic.solve_in_place_scratch::<T>(1, par));
    crate::with_faer(|| {
        LltRef::new(symbolic, values).solve_in_place_with_conj(
            faer::Conj::No,
            x.as_mut(),
            par,
            MemStack::new(&mut scratch),
        )
    });
    (0..x.nrows()).map(|r| x[(r, 0)]).collect()
}

/// The symbolic factorization of the scalar `pattern` of `n` nodes of `d` unknowns joined by
/// `edges`, in an order found on the nodes' graph ([`CoarseFactor`]).
fn analyse_by_nodes(
    pattern: &SymbolicSparseColMat<usize>,
    n: usize,
    d: usize,
    edges: &[[u32; 2]],
) -> Option<SymbolicCholesky<usize>> {
    let nodes = super::auto::analyse_graph::<usize>(n, edges)?;
    let perm = nodes.perm().map(|perm| perm.arrays().0);
    let node = |i: usize| perm.map_or(i, |perm| perm[i]);
    let forward: Vec<usize> = (0..n)
        .flat_map(|i| (0..d).map(move |r| node(i) * d + r))
        .collect();
    let mut inverse = vec![0usize; forward.len()];
    for (i, &f) in forward.iter().enumerate() {
        inverse[f] = i;
    }
    let perm = PermRef::new_checked(&forward, &inverse, n * d);
    crate::with_faer(|| {
        factorize_symbolic_cholesky(
            pattern.as_ref(),
            Side::Lower,
            SymmetricOrdering::Custom(perm),
            Default::default(),
        )
        .ok()
    })
}

/// The lower triangle's scalar pattern of `a` by columns, with where each column's blocks
/// below the diagonal come from ([`CoarseFactor::below`]): built from the edges directly
/// (each node's neighbors sorted in place), without sorting every scalar entry. `None` for an
/// edge given twice or from a node to itself.
fn lower_pattern(a: &BlockMatrix) -> Option<(SymbolicSparseColMat<usize>, Below)> {
    let (n, d) = (a.n, a.dof);
    let mut start = vec![0usize; n + 1];
    for e in &a.edges {
        if e[0] == e[1] {
            return None;
        }
        start[e[0].min(e[1]) as usize + 1] += 1;
    }
    for j in 0..n {
        start[j + 1] += start[j];
    }
    let mut next = start.clone();
    let mut below = vec![(0u32, 0u32, false); a.edges.len()];
    for (k, e) in a.edges.iter().enumerate() {
        let lo = e[0].min(e[1]) as usize;
        below[next[lo]] = (e[0].max(e[1]), k as u32, e[0] as usize == lo);
        next[lo] += 1;
    }
    for j in 0..n {
        let column = &mut below[start[j]..start[j + 1]];
        column.sort_unstable_by_key(|b| b.0);
        if column.windows(2).any(|w| w[0].0 == w[1].0) {
            return None;
        }
    }
    let mut col_ptr = Vec::with_capacity(n * d + 1);
    let mut row_idx = Vec::with_capacity(n * d * (d + 1) / 2 + a.edges.len() * d * d);
    col_ptr.push(0);
    for j in 0..n {
        for c in 0..d {
            row_idx.extend((c..d).map(|r| j * d + r));
            for &(k, _, _) in &below[start[j]..start[j + 1]] {
                row_idx.extend((0..d).map(|r| k as usize * d + r));
            }
            col_ptr.push(row_idx.len());
        }
    }
    let pattern = SymbolicSparseColMat::new_checked(n * d, n * d, col_ptr, None, row_idx);
    Some((pattern, Below { start, below }))
}

/// The factor of `a`, reusing the analysis of `reuse` when it was made for the same nodes and
/// edges (`None` when the pattern cannot be analysed).
pub(super) fn factor_coarsest(
    a: &BlockMatrix,
    reuse: Option<CoarseFactor>,
) -> Option<CoarseFactor> {
    let d = a.dof;
    let bb = d * d;
    let n = a.len();
    let reuse = reuse.filter(|f| f.n == n && f.dof == d && f.edges == a.edges);
    let (pattern, below, symbolic) = match reuse {
        Some(f) => (f.pattern, f.below, f.symbolic),
        None => {
            let (pattern, below) = lower_pattern(a)?;
            let symbolic = analyse_by_nodes(&pattern, a.n, d, &a.edges)?;
            (pattern, below, symbolic)
        }
    };
    // The entries in the pattern's order: each column's part of its diagonal block, then the
    // blocks below it (an edge's block holds the rows of its first node, so the column of its
    // first node reads it transposed).
    let mut values = Vec::with_capacity(pattern.row_idx().len());
    for j in 0..a.n {
        for c in 0..d {
            values.extend((c..d).map(|r| a.diag[j * bb + r * d + c]));
            for &(_, k, first) in &below.below[below.start[j]..below.start[j + 1]] {
                let block = &a.blocks[k as usize * bb..][..bb];
                if first {
                    values.extend((0..d).map(|r| block[c * d + r]));
                } else {
                    values.extend((0..d).map(|r| block[r * d + c]));
                }
            }
        }
    }
    // Single precision first; a matrix that is not positive definite in it (or a factor that
    // cannot be allocated) is factored again in double. None in double leaves the level
    // without a coarse correction.
    let single: Vec<f32> = values.iter().map(|&v| v as f32).collect();
    let factor = numeric(&symbolic, &pattern, &single)
        .map(Values::Single)
        .or_else(|| {
            drop(single);
            numeric(&symbolic, &pattern, &values).map(Values::Double)
        });
    Some(CoarseFactor {
        n,
        dof: d,
        edges: a.edges.clone(),
        pattern,
        below,
        symbolic,
        values: factor,
    })
}

/// The numeric Cholesky factor of `values` (in `pattern`'s order) by `symbolic`, or `None`
/// where it cannot be allocated or the matrix is not positive definite (in `T`'s precision).
fn numeric<T: faer::traits::RealField + Copy>(
    symbolic: &SymbolicCholesky<usize>,
    pattern: &SymbolicSparseColMat<usize>,
    values: &[T],
) -> Option<Vec<T>> {
    let par = faer::get_global_parallelism();
    let mut factor = Vec::new();
    factor.try_reserve_exact(symbolic.len_val()).ok()?;
    factor.resize(symbolic.len_val(), T::zero_impl());
    crate::with_faer(|| {
        let mut scratch = MemBuffer::try_new(
            symbolic.factorize_numeric_llt_scratch::<T>(par, Default::default()),
        )
        .ok()?;
        symbolic
            .factorize_numeric_llt(
                &mut factor,
                SparseColMatRef::new(pattern.as_ref(), values),
                Side::Lower,
                Default::default(),
                par,
                MemStack::new(&mut scratch),
                Default::default(),
            )
            .ok()
    })?;
    Some(factor)
}

pub(super) fn transpose(m: &[f64], d: usize) -> Block {
    let mut out = [0.0; MAX_DOF * MAX_DOF];
    for k in 0..d * d {
        out[k] = m[(k % d) * d + k / d];
    }
    out
}

pub(super) fn add(out: &mut [f64], m: &[f64]) {
    out.iter_mut().zip(m).for_each(|(o, m)| *o += m);
}

/// The inverse of the symmetric `d × d` block `m + eps I` by Cholesky, or `false` when it is not
/// positive definite.
pub(super) fn invert_spd(m: &[f64], d: usize, eps: f64, out: &mut [f64]) -> bool {
    let mut l = [0.0f64; 36];
    for r in 0..d {
        for c in 0..=r {
            let mut s = m[r * d + c] + if r == c { eps } else { 0.0 };
            for k in 0..c {
                s -= l[r * 6 + k] * l[c * 6 + k];
            }
            if r == c {
                if !(s > 0.0 && s.is_finite()) {
                    return false;
                }
                l[r * 6 + r] = s.sqrt();
            } else {
                l[r * 6 + c] = s / l[c * 6 + c];
            }
        }
    }
    for col in 0..d {
        // Solve L Lᵀ x = e_col.
        let mut y = [0.0f64; 6];
        for r in 0..d {
            let mut s = if r == col { 1.0 } else { 0.0 };
            for k in 0..r {
                s -= l[r * 6 + k] * y[k];
            }
            y[r] = s / l[r * 6 + r];
        }
        for r in (0..d).rev() {
            let mut s = y[r];
            for k in r + 1..d {
                s -= l[k * 6 + r] * y[k];
            }
            y[r] = s / l[r * 6 + r];
        }
        for r in 0..d {
            out[r * d + col] = y[r];
        }
    }
    true
}

#[inline]
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

/// `a · b`, summed in chunks of a fixed length and the chunks in order: the same bits whatever
/// the number of threads.
pub(super) fn par_dot(a: &[f64], b: &[f64]) -> f64 {
    const CHUNK: usize = 1 << 14;
    let parts: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(a, b)| dot(a, b))
        .collect();
    parts.iter().sum()
}

pub(super) fn norm(a: &[f64]) -> f64 {
    par_dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    /// A random symmetric positive definite matrix of `n` nodes of `d` unknowns on a ring with
    /// chords, its edges given in either order (an edge's block holds its first node's rows).
    fn random(n: usize, d: usize, seed: u64) -> BlockMatrix {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut edges = Vec::new();
        for a in 0..n {
            for b in [(a + 1) % n, (a + 7) % n] {
                let e = if rng.random_bool(0.5) { [a, b] } else { [b, a] };
                if a != b && !edges.contains(&[e[0] as u32, e[1] as u32]) {
                    edges.push([e[0] as u32, e[1] as u32]);
                }
            }
        }
        let bb = d * d;
        let blocks: Vec<f64> = (0..edges.len() * bb)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        // Diagonally dominant: each diagonal block symmetric, its diagonal beyond every row's
        // off-diagonal sum.
        let mut diag = vec![0.0; n * bb];
        for a in 0..n {
            for r in 0..d {
                for c in 0..r {
                    let v = rng.random_range(-0.5..0.5);
                    diag[a * bb + r * d + c] = v;
                    diag[a * bb + c * d + r] = v;
                }
                diag[a * bb + r * d + r] = 4.0 * d as f64 + 4.0;
            }
        }
        BlockMatrix::new(d, n, diag, edges, blocks)
    }

    #[test]
    fn the_coarse_factor_ordered_by_nodes_solves_the_matrix() {
        for (n, d, seed) in [(40, 6, 1), (25, 3, 2), (1, 6, 3)] {
            let a = random(n, d, seed);
            let b: Vec<f64> = (0..a.len()).map(|i| (i % 7) as f64 - 3.0).collect();
            let f = factor_coarsest(&a, None).expect("analysed");
            let x = f.solve(&b).expect("positive definite");
            let err = largest_residual(&a, &x, &b);
            // Factored in single precision: a residual of single precision's rounding.
            assert!(matches!(f.values, Some(Values::Single(_))));
            assert!(err < 1e-5, "n {n} d {d}: residual {err:e}");
            // The nodes' order fills in about as little as AMD on the scalars (a permutation
            // taken the wrong way round would still solve, with more fill).
            let (pattern, _) = lower_pattern(&a).unwrap();
            let scalar = factorize_symbolic_cholesky(
                pattern.as_ref(),
                Side::Lower,
                SymmetricOrdering::Amd,
                Default::default(),
            )
            .unwrap();
            let (ours, theirs) = (f.symbolic.len_val(), scalar.len_val());
            assert!(
                ours * 10 <= theirs * 11,
                "n {n}: fill {ours} against {theirs}"
            );
            // A second factor of the same pattern reuses the analysis and solves as well.
            let again = factor_coarsest(&a, Some(f)).expect("analysed");
            assert_eq!(again.solve(&b), Some(x));
        }
    }

    /// The largest entry of `a x − b`.
    fn largest_residual(a: &BlockMatrix, x: &[f64], b: &[f64]) -> f64 {
        let mut ax = vec![0.0; a.len()];
        a.mul(x, &mut ax);
        ax.iter()
            .zip(b)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_matrix_singular_in_single_precision_is_factored_in_double() {
        // Two nodes tied by `c` = 1 − 1e-9: the eigenvalues 1 ± c, singular once `c` rounds to
        // 1 in `f32`.
        let d = 3;
        let c = 1.0 - 1e-9;
        let identity: Vec<f64> = (0..d * d)
            .map(|k| if k % (d + 1) == 0 { 1.0 } else { 0.0 })
            .collect();
        let diag = [identity.clone(), identity.clone()].concat();
        let tie = identity.iter().map(|v| -c * v).collect();
        let a = BlockMatrix::new(d, 2, diag, vec![[0, 1]], tie);
        let f = factor_coarsest(&a, None).expect("analysed");
        assert!(matches!(f.values, Some(Values::Double(_))));
        let b = [1.0, 0.0, -1.0, 0.5, 0.0, 2.0];
        let x = f.solve(&b).expect("positive definite");
        let err = largest_residual(&a, &x, &b);
        assert!(err < 1e-6, "residual {err:e} of a solution as large as 1e9");
    }

    #[test]
    fn an_edge_given_twice_or_to_its_own_node_is_not_analysed() {
        let a = random(10, 3, 4);
        let twice = BlockMatrix::new(
            3,
            10,
            a.diag.clone(),
            vec![[0, 1], [1, 0]],
            [&a.blocks[..9], &a.blocks[..9]].concat(),
        );
        assert!(factor_coarsest(&twice, None).is_none());
        let own = BlockMatrix::new(3, 10, a.diag.clone(), vec![[2, 2]], a.blocks[..9].to_vec());
        assert!(factor_coarsest(&own, None).is_none());
    }
}
