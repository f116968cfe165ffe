//! The global step's matrix: the weighted graph Laplacian of the free cells, `L` in `L p = b`
//! (see `positions.rs` for where it comes from), the same for the `D` coordinates and constant
//! over an edit; built as a lower triangle for a factor, or whole in compressed rows for
//! multiplying and for the subdomains of [`super::schwarz`].

use faer::Side;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMat, Triplet};
use rayon::prelude::*;

use super::constraints::{Constraints, Role};
use crate::cells::CellComplex;

/// A matrix's lower triangle, entry by entry.
pub type Lower = Vec<Triplet<usize, usize, f64>>;

/// The global step's matrix: the weighted graph Laplacian of the free cells plus the targets'
/// weights on the diagonal, as the lower triangle's entries (the diagonal's last), with the row
/// of every cell whose position is free and the number of rows.
pub fn laplacian<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
) -> (Vec<Option<u32>>, usize, Lower) {
    let mut n = 0usize;
    let row: Vec<Option<u32>> = constraints
        .roles
        .iter()
        .map(|r| {
            (*r == Role::Free).then(|| {
                n += 1;
                n as u32 - 1
            })
        })
        .collect();
    let mut triplets = Vec::new();
    let mut diag = vec![0.0f64; n];
    for pr in &complex.pairs {
        let (i, j) = (pr.i as usize, pr.j as usize);
        let k = pair_weight(constraints, pr.weight, i, j);
        for r in [row[i], row[j]].into_iter().flatten() {
            diag[r as usize] += k;
        }
        if let (Some(ri), Some(rj)) = (row[i], row[j]) {
            triplets.push(Triplet::new(ri.max(rj) as usize, ri.min(rj) as usize, -k));
        }
    }
    for t in &constraints.targets {
        if let Some(r) = row[t.cell as usize] {
            diag[r as usize] += t.weight;
        }
    }
    triplets.extend(diag.iter().enumerate().map(|(r, &d)| Triplet::new(r, r, d)));
    (row, n, triplets)
}

/// A symmetric sparse matrix, every row whole (both triangles), in compressed rows.
pub struct Laplacian {
    /// Rows (and columns).
    pub n: usize,
    start: Vec<usize>,
    column: Vec<u32>,
    value: Vec<f64>,
}

impl Laplacian {
    /// The global step's matrix for `constraints` on `complex` (the free cells' weighted graph
    /// Laplacian plus the targets' weights) and the row of every cell whose position is free.
    pub fn of<const D: usize>(
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
    ) -> (Self, Vec<Option<u32>>) {
        let (row, n, lower) = laplacian(complex, constraints);
        (Self::from_lower(n, &lower), row)
    }

    /// The matrix whose lower triangle `lower` gives (entries at one place are summed).
    pub fn from_lower(n: usize, lower: &[Triplet<usize, usize, f64>]) -> Self {
        let mut entries: Vec<(u32, u32, f64)> = Vec::with_capacity(2 * lower.len());
        for t in lower {
            entries.push((t.row as u32, t.col as u32, t.val));
            if t.row != t.col {
                entries.push((t.col as u32, t.row as u32, t.val));
            }
        }
        entries.par_sort_unstable_by_key(|e| (e.0, e.1));
        let mut start = vec![0usize; n + 1];
        let (mut column, mut value) = (Vec::new(), Vec::new());
        let mut last = None;
        for (r, c, v) in entries {
            if last == Some((r, c)) {
                *value.last_mut().expect("an entry was pushed") += v;
                continue;
            }
            last = Some((r, c));
            column.push(c);
            value.push(v);
            start[r as usize + 1] = column.len();
        }
        for r in 0..n {
            start[r + 1] = start[r + 1].max(start[r]);
        }
        Self {
            n,
            start,
            column,
            value,
        }
    }

    /// The row `r`'s columns and values.
    pub(super) fn row(&self, r: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.start[r]..self.start[r + 1];
        self.column[range.clone()]
            .iter()
            .zip(&self.value[range])
            .map(|(&c, &v)| (c as usize, v))
    }

    /// `y = L x`, for `x` and `y` of `D` columns of `n` each (column after column).
    pub fn mul(&self, x: &[f64], y: &mut [f64]) {
        let n = self.n;
        if n == 0 {
            return;
        }
        y.par_chunks_mut(n).enumerate().for_each(|(a, col)| {
            let x = &x[a * n..(a + 1) * n];
            for (r, out) in col.iter_mut().enumerate() {
                *out = self.row(r).map(|(c, v)| v * x[c]).sum();
            }
        });
    }
}

pub(super) fn pair_weight<const D: usize>(
    constraints: &Constraints<D>,
    weight: f64,
    i: usize,
    j: usize,
) -> f64 {
    (constraints.stiffness[i] * constraints.stiffness[j]).sqrt() * weight
}

/// The sparse Cholesky factor of the `n × n` matrix given by lower-triangle `triplets`.
pub(super) fn factor(n: usize, triplets: &[Triplet<usize, usize, f64>]) -> Option<Llt<usize, f64>> {
    let m = SparseColMat::try_new_from_triplets(n, n, triplets).ok()?;
    crate::with_faer(|| {
        let symbolic = SymbolicLlt::try_new(m.symbolic(), Side::Lower).ok()?;
        Llt::try_new_with_symbolic(symbolic, m.as_ref(), Side::Lower).ok()
    })
}
