//! Block-sparse symmetric matrices of `dof × dof` blocks (one per cell with freedom and one
//! per pair of face neighbors), in `f64` or `f32`, and the small dense block arithmetic the
//! multilevel solve ([`super::multilevel`]) builds its levels with.

use faer::Side;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{Argsort, Pair, SparseColMat, SymbolicSparseColMat};
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
/// entries' order and the symbolic factorization), which a later hierarchy of the same groups
/// reuses: within a load step every rebuild groups the same cells, and on the 2.5 m vegetation
/// scene (10.8k coarse nodes, 96k edges) the entries' order and the analysis took 0.5 s of the
/// factor's 1.5 s.
pub(crate) struct CoarseFactor {
    n: usize,
    dof: usize,
    pub(super) edges: Vec<[u32; 2]>,
    pattern: SymbolicSparseColMat<usize>,
    argsort: Argsort<usize>,
    symbolic: SymbolicLlt<usize>,
    /// The factor (`None`: the matrix was not positive definite).
    pub(super) llt: Option<Llt<usize, f64>>,
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
    let entries = a.n * d * (d + 1) / 2 + a.edges.len() * bb;
    let mut values = Vec::with_capacity(entries);
    // The entries' positions, only where the pattern is analysed anew.
    let mut indices = Vec::with_capacity(if reuse.is_some() { 0 } else { entries });
    let fresh = reuse.is_none();
    for g in 0..a.n {
        for r in 0..d {
            for c in 0..=r {
                if fresh {
                    indices.push(Pair::new(g * d + r, g * d + c));
                }
                values.push(a.diag[g * bb + r * d + c]);
            }
        }
    }
    for (k, e) in a.edges.iter().enumerate() {
        // Rows of the higher node: the transpose of the block when the first is lower.
        let (i, j) = (e[0] as usize, e[1] as usize);
        for r in 0..d {
            for c in 0..d {
                let (row, col) = (i * d + r, j * d + c);
                if fresh {
                    indices.push(Pair::new(row.max(col), row.min(col)));
                }
                values.push(a.blocks[k * bb + r * d + c]);
            }
        }
    }
    let (pattern, argsort, symbolic) = match reuse {
        Some(f) => (f.pattern, f.argsort, f.symbolic),
        None => {
            let (pattern, argsort) =
                SymbolicSparseColMat::try_new_from_indices(n, n, &indices).ok()?;
            let symbolic =
                crate::with_faer(|| SymbolicLlt::try_new(pattern.as_ref(), Side::Lower)).ok()?;
            (pattern, argsort, symbolic)
        }
    };
    let matrix = SparseColMat::new_from_argsort(pattern.clone(), &argsort, &values).ok()?;
    let llt = crate::with_faer(|| {
        Llt::try_new_with_symbolic(symbolic.clone(), matrix.as_ref(), Side::Lower).ok()
    });
    Some(CoarseFactor {
        n,
        dof: d,
        edges: a.edges.clone(),
        pattern,
        argsort,
        symbolic,
        llt,
    })
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
