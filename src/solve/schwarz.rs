//! The global step's system solved by subdomains: conjugate gradients preconditioned by a
//! two-level additive Schwarz method. This is the global half of a local-global solve spread
//! over processes or machines: `SolveParams::subdomains` (`--subdomains`) solves by it, each
//! subdomain's block factored and solved by [`Workers`] registered for the call ([`register`];
//! the Python package's Dask actors) or else in this process. The process that runs the
//! iterations keeps the matrix's products and the coarse problem.
//!
//! The local-global solver's global step solves `L p = b` with `L` the weighted graph Laplacian
//! of the free cells ([`Laplacian`]): one scalar matrix for the `D` coordinates, constant
//! over an edit. One process factors it whole. Split over subdomains, each needs only its own
//! rows, and the system is solved iteratively with a preconditioner that each subdomain applies
//! alone, plus one small problem they share (here one process builds them all: the setup and
//! the vector products read the whole matrix):
//!
//! ```text
//! M⁻¹ r = Σ_k R_kᵀ A_k⁻¹ R_k r  +  P A_0⁻¹ Pᵀ r,      A_0 = Pᵀ L P
//! ```
//!
//! - **Subdomains** ([`Subdomains::split`]): the free cells in Morton order of their lower
//!   corners on the finest grid, cut into `k` runs of equal length — compact pieces of space,
//!   each a run of the space-filling curve.
//! - **Local solves**: `R_k` takes the rows of subdomain `k` grown by [`OVERLAP`] layer of
//!   neighbors; `A_k = R_k L R_kᵀ`, a principal block of `L`, is factored once, by whoever holds
//!   the subdomain.
//! - **Coarse space**: with local solves alone, the iterations grow with the number of
//!   subdomains (a correction crosses one subdomain per iteration). The coarse space carries
//!   the Laplacian's near-null vectors, the constants, across all of them: aggregates of
//!   [`aggregate_size`] consecutive cells of each subdomain's Morton run, their indicators
//!   smoothed by one damped Jacobi step (`P = (I − ⅔ D⁻¹ L) P₀`, smoothed aggregation), and
//!   `A_0` factored once by one process.
//!
//! `M⁻¹` is symmetric positive definite wherever `L` is (each term is semidefinite, and the
//! subdomains cover every row), so conjugate gradients apply. Measured by
//! `tools/src/bin/schwarz.rs` on the hilly 1 km × 200 m strip (its west end fixed and its east
//! end lifted, a random right-hand side solved to 1e-8; BENCHMARKS.md §7), the iterations from 4 to 16
//! subdomains: 50 → 63 at 2.5 m (74,717 free cells) and 52 → 64 at 1.25 m (388,638); with the
//! aggregates' plain indicators 66 → 90, and with the coarse correction applied before and
//! after the local solves (the balanced form) 56 → 81, at two more products by `L` and coarse
//! solves an iteration. A second
//! layer of overlap changes them by −8 to +3 %. One process factoring the whole matrix is
//! far faster (3.1 s to factor and 0.4 s to solve at 1.25 m, against 13 s of iterations): the
//! split is for a solve whose matrix one process cannot hold.

use faer::prelude::*;
use faer::sparse::Triplet;
use faer::sparse::linalg::solvers::Llt;
use rayon::prelude::*;

use super::laplacian::{Laplacian, factor};
pub use super::workers::{
    Block, BlockFactor, BlockSolves, Registration, Workers, WorkersId, register, registered,
};
use crate::cells::CellComplex;
use crate::error::{Error, Result};

/// Layers of neighbors each subdomain's block grows by.
pub const OVERLAP: usize = 1;

/// Cells per coarse aggregate for `n` free cells: 16, or more where the coarse problem would
/// pass [`COARSE_MAX`] unknowns.
pub fn aggregate_size(n: usize) -> usize {
    16.max(n.div_ceil(COARSE_MAX))
}

/// Coarse unknowns at most, but for each subdomain's last aggregate (the one problem every
/// subdomain shares, factored by one process).
pub const COARSE_MAX: usize = 50_000;

/// The free cells split into subdomains.
pub struct Subdomains {
    /// Each subdomain's rows, ascending.
    parts: Vec<Vec<u32>>,
    /// Rows in Morton order: each subdomain is a run of it, and so is each coarse aggregate.
    order: Vec<u32>,
    /// Where each subdomain's run starts in `order` (and the end).
    runs: Vec<usize>,
}

impl Subdomains {
    /// `k` subdomains of the free cells (`row` as [`Laplacian::of`] gives it): runs of equal
    /// length of the cells' Morton order (their lower corners on the finest grid).
    pub fn split<const D: usize>(complex: &CellComplex<D>, row: &[Option<u32>], k: usize) -> Self {
        let max = complex.grid.max_level as u32;
        let mut keyed: Vec<(u64, u32)> = complex
            .cells
            .iter()
            .zip(row)
            .filter_map(|(cell, r)| {
                let shift = max - cell.key.level as u32;
                let corner = cell.key.coord.map(|c| c << shift);
                r.map(|r| (crate::cells::morton_code(&corner), r))
            })
            .collect();
        keyed.par_sort_unstable();
        let order: Vec<u32> = keyed.into_iter().map(|(_, r)| r).collect();
        let n = order.len();
        let k = k.clamp(1, n.max(1));
        let runs: Vec<usize> = (0..=k).map(|p| p * n / k).collect();
        let parts = runs
            .windows(2)
            .map(|w| {
                let mut rows = order[w[0]..w[1]].to_vec();
                rows.sort_unstable();
                rows
            })
            .collect();
        Self { parts, order, runs }
    }
}

impl Subdomains {
    /// Each subdomain's rows, ascending.
    pub fn parts(&self) -> &[Vec<u32>] {
        &self.parts
    }
}

/// `l`'s principal block on `rows` (ascending), as a worker receives it.
fn block_of(l: &Laplacian, rows: &[u32]) -> Block {
    let mut block = Block {
        size: rows.len(),
        ..Block::default()
    };
    for (i, &r) in rows.iter().enumerate() {
        for (c, v) in l.row(r as usize) {
            if let Ok(j) = rows.binary_search(&(c as u32))
                && j <= i
            {
                block.rows.push(i as u32);
                block.cols.push(j as u32);
                block.values.push(v);
            }
        }
    }
    block
}

/// Where the subdomains' blocks are factored and solved.
enum Local {
    /// In this process.
    Here(Vec<BlockFactor>),
    /// By workers.
    Workers(Box<dyn BlockSolves>),
}

/// The two-level additive Schwarz preconditioner of a [`Laplacian`] (see the module docs).
pub struct Schwarz {
    /// Each subdomain's grown rows, ascending.
    rows: Vec<Vec<u32>>,
    local: Local,
    /// Rows.
    n: usize,
    prolongation: Prolongation,
    coarse: Llt<usize, f64>,
    coarse_n: usize,
}

impl Schwarz {
    /// Factors each subdomain's block, grown by `overlap` layers of neighbors, and the coarse
    /// problem on aggregates of `aggregate` consecutive cells of each subdomain's run. `None`
    /// if a block or the coarse problem is not positive definite (`L` is singular: a free part
    /// with nothing holding its translation; such a part may also go unnoticed here when its
    /// blocks and aggregates each reach a held row, which `resolve` rules out by giving such
    /// parts no free cells).
    pub fn new(
        l: &Laplacian,
        subdomains: &Subdomains,
        overlap: usize,
        aggregate: usize,
        workers: Option<&dyn Workers>,
    ) -> Result<Option<Self>> {
        let rows: Vec<Vec<u32>> = subdomains
            .parts
            .par_iter()
            .map(|part| grown(l, part, overlap))
            .collect();
        let blocks = rows.par_iter().map(|r| block_of(l, r));
        let local = match workers {
            // On faer's pool, where each block's factor runs inline: from the global pool each
            // would wait for faer's, taking other blocks' factors onto its stack meanwhile, and
            // thousands of small blocks overflowed it.
            None => {
                match crate::with_faer(|| blocks.map(|b| b.factor()).collect::<Option<Vec<_>>>()) {
                    Some(factors) => Local::Here(factors),
                    None => return Ok(None),
                }
            }
            Some(workers) => Local::Workers(workers.factor(blocks.collect())?),
        };
        let size = aggregate.max(1);
        let mut of = vec![0u32; l.n];
        let mut coarse_n = 0usize;
        for w in subdomains.runs.windows(2) {
            for (k, &r) in subdomains.order[w[0]..w[1]].iter().enumerate() {
                of[r as usize] = (coarse_n + k / size) as u32;
            }
            coarse_n += (w[1] - w[0]).div_ceil(size);
        }
        let prolongation = smoothed(l, &of);
        let lower = prolongation.galerkin(l);
        let Some(coarse) = factor(coarse_n, &lower) else {
            return Ok(None);
        };
        Ok(Some(Self {
            rows,
            local,
            n: l.n,
            prolongation,
            coarse,
            coarse_n,
        }))
    }

    /// Subdomains.
    pub fn subdomains(&self) -> usize {
        self.rows.len()
    }

    /// Coarse unknowns.
    pub fn coarse_len(&self) -> usize {
        self.coarse_n
    }

    /// Rows of the largest grown subdomain block (what one process factors).
    pub fn largest_block(&self) -> usize {
        self.rows.iter().map(Vec::len).max().unwrap_or(0)
    }

    /// `z = M⁻¹ r` for `D` columns of `n` each. Fails only where workers do.
    pub fn apply(&self, r: &[f64], z: &mut [f64], d: usize) -> Result<()> {
        let (q, y) = rayon::join(|| self.coarse(r, d), || self.local(r, d));
        let y = y?;
        for k in 0..r.len() {
            z[k] = q[k] + y[k];
        }
        Ok(())
    }

    /// `Σ_k R_kᵀ A_k⁻¹ R_k r`: every subdomain's solve.
    fn local(&self, r: &[f64], d: usize) -> Result<Vec<f64>> {
        let n = self.n;
        let restricted = |rows: &Vec<u32>| -> Vec<f64> {
            (0..rows.len() * d)
                .map(|k| r[(k / rows.len()) * n + rows[k % rows.len()] as usize])
                .collect()
        };
        let solved: Vec<Vec<f64>> = match &self.local {
            // On faer's pool, as the factors were made.
            Local::Here(factors) => crate::with_faer(|| {
                self.rows
                    .par_iter()
                    .zip(factors)
                    .map(|(rows, f)| f.solve(&restricted(rows)).unwrap_or_default())
                    .collect()
            }),
            Local::Workers(solves) => solves.solve(self.rows.iter().map(restricted).collect())?,
        };
        let whole = solved.len() == self.rows.len()
            && solved
                .iter()
                .zip(&self.rows)
                .all(|(x, rows)| x.len() == rows.len() * d);
        if !whole {
            return Err(Error::solver(
                "a subdomain's solve gave the wrong number of values",
            ));
        }
        let mut z = vec![0.0; n * d];
        for (rows, x) in self.rows.iter().zip(&solved) {
            for (k, v) in x.iter().enumerate() {
                z[(k / rows.len()) * n + rows[k % rows.len()] as usize] += v;
            }
        }
        Ok(z)
    }

    /// `R_0ᵀ A_0⁻¹ R_0 r`: the coarse problem's solve.
    fn coarse(&self, r: &[f64], d: usize) -> Vec<f64> {
        let n = self.n;
        let p = &self.prolongation;
        let mut x0 = Mat::<f64>::zeros(self.coarse_n, d);
        for a in 0..d {
            for i in 0..n {
                for (g, w) in p.row(i) {
                    x0[(g, a)] += w * r[a * n + i];
                }
            }
        }
        crate::with_faer(|| self.coarse.solve_in_place(x0.as_mut()));
        (0..n * d)
            .map(|k| p.row(k % n).map(|(g, w)| w * x0[(g, k / n)]).sum())
            .collect()
    }
}

/// The coarse space's basis, row by row: `P = R_0ᵀ`.
struct Prolongation {
    start: Vec<usize>,
    to: Vec<u32>,
    weight: Vec<f64>,
}

impl Prolongation {
    fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.start[i]..self.start[i + 1];
        self.to[range.clone()]
            .iter()
            .zip(&self.weight[range])
            .map(|(&g, &w)| (g as usize, w))
    }

    /// The lower triangle of `Pᵀ L P`.
    fn galerkin(&self, l: &Laplacian) -> Vec<Triplet<usize, usize, f64>> {
        use rustc_hash::FxHashMap;
        // L P, row by row, then Pᵀ (L P) gathered by coarse row.
        let mut sums: FxHashMap<(u32, u32), f64> = FxHashMap::default();
        let mut lp: FxHashMap<u32, f64> = FxHashMap::default();
        for i in 0..l.n {
            lp.clear();
            for (j, v) in l.row(i) {
                for (g, w) in self.row(j) {
                    *lp.entry(g as u32).or_default() += v * w;
                }
            }
            for (a, wa) in self.row(i) {
                for (&b, &x) in &lp {
                    if a as u32 >= b {
                        *sums.entry((a as u32, b)).or_default() += wa * x;
                    }
                }
            }
        }
        sums.into_iter()
            .map(|((a, b), v)| Triplet::new(a as usize, b as usize, v))
            .collect()
    }
}

/// The aggregates' indicators smoothed by one damped Jacobi step, `P = (I − ω D⁻¹ L) P₀` with
/// `ω = 2/3`.
fn smoothed(l: &Laplacian, of: &[u32]) -> Prolongation {
    use rustc_hash::FxHashMap;
    let mut start = vec![0usize];
    let (mut to, mut weight) = (Vec::new(), Vec::new());
    let mut row: FxHashMap<u32, f64> = FxHashMap::default();
    for i in 0..l.n {
        row.clear();
        let diag = l.row(i).find(|&(j, _)| j == i).map_or(1.0, |(_, v)| v);
        let omega = 2.0 / 3.0 / diag;
        *row.entry(of[i]).or_default() += 1.0;
        for (j, v) in l.row(i) {
            *row.entry(of[j]).or_default() -= omega * v;
        }
        let mut entries: Vec<(u32, f64)> = row
            .iter()
            .map(|(&g, &w)| (g, w))
            .filter(|e| e.1 != 0.0)
            .collect();
        entries.sort_unstable_by_key(|e| e.0);
        for (g, w) in entries {
            to.push(g);
            weight.push(w);
        }
        start.push(to.len());
    }
    Prolongation { start, to, weight }
}

/// `part` grown by `layers` layers of its rows' neighbors in `l`, ascending.
fn grown(l: &Laplacian, part: &[u32], layers: usize) -> Vec<u32> {
    let mut rows = part.to_vec();
    let mut front = part.to_vec();
    for _ in 0..layers {
        let mut next: Vec<u32> = front
            .iter()
            .flat_map(|&r| l.row(r as usize).map(|(c, _)| c as u32))
            .filter(|c| rows.binary_search(c).is_err())
            .collect();
        next.sort_unstable();
        next.dedup();
        rows.extend_from_slice(&next);
        rows.sort_unstable();
        front = next;
    }
    rows
}

/// `L` factored whole, as one process solves the global step: the reference the subdomains'
/// solve is measured against.
pub struct Factored(BlockFactor);

impl Factored {
    /// The factor of `l`; `None` where `l` is singular.
    pub fn new(l: &Laplacian) -> Option<Self> {
        let all: Vec<u32> = (0..l.n as u32).collect();
        block_of(l, &all).factor().map(Self)
    }

    /// `L⁻¹ b` for `b` of `D` columns of `n` each (column after column); `None` where `b` is
    /// not whole columns.
    pub fn solve(&self, b: &[f64]) -> Option<Vec<f64>> {
        self.0.solve(b)
    }
}

/// What [`solve`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solved {
    /// Conjugate-gradient iterations (the most any column took).
    pub iterations: usize,
    /// The largest relative residual over the columns at the end: the iteration's residual
    /// (updated step by step, `b − L x` but for rounding) over the larger of `|b|` and the
    /// first residual's norm.
    pub residual: f64,
}

/// Solves `L x = b` (`D` columns of `n` each, column after column) by conjugate gradients
/// preconditioned by `m`, from `x` as given, until every column's residual is at most
/// `tolerance` of its right-hand side or of its first residual, whichever is larger (or
/// `max_iterations`).
pub fn solve(
    l: &Laplacian,
    m: &Schwarz,
    b: &[f64],
    x: &mut [f64],
    tolerance: f64,
    max_iterations: usize,
) -> Result<Solved> {
    let n = l.n;
    let d = b.len() / n.max(1);
    let dot = |u: &[f64], v: &[f64], a: usize| -> f64 {
        u[a * n..(a + 1) * n]
            .iter()
            .zip(&v[a * n..(a + 1) * n])
            .map(|(p, q)| p * q)
            .sum()
    };
    let mut r = vec![0.0; n * d];
    l.mul(x, &mut r);
    r.iter_mut().zip(b).for_each(|(r, b)| *r = b - *r);
    let norm_b: Vec<f64> = (0..d)
        .map(|a| {
            let start = dot(&r, &r, a).sqrt().max(dot(b, b, a).sqrt());
            start.max(f64::MIN_POSITIVE)
        })
        .collect();
    let relative = |r: &[f64]| -> f64 {
        (0..d)
            .map(|a| dot(r, r, a).sqrt() / norm_b[a])
            .fold(0.0, f64::max)
    };
    let mut z = vec![0.0; n * d];
    m.apply(&r, &mut z, d)?;
    let mut p = z.clone();
    let mut rz: Vec<f64> = (0..d).map(|a| dot(&r, &z, a)).collect();
    let mut q = vec![0.0; n * d];
    let mut iterations = 0;
    while iterations < max_iterations && relative(&r) > tolerance {
        l.mul(&p, &mut q);
        for a in 0..d {
            let pq = dot(&p, &q, a);
            let alpha = if pq > 0.0 { rz[a] / pq } else { 0.0 };
            let s = a * n..(a + 1) * n;
            x[s.clone()]
                .iter_mut()
                .zip(&p[s.clone()])
                .for_each(|(x, p)| *x += alpha * p);
            r[s.clone()]
                .iter_mut()
                .zip(&q[s])
                .for_each(|(r, q)| *r -= alpha * q);
        }
        m.apply(&r, &mut z, d)?;
        for a in 0..d {
            let next = dot(&r, &z, a);
            let beta = if rz[a] > 0.0 { next / rz[a] } else { 0.0 };
            rz[a] = next;
            let s = a * n..(a + 1) * n;
            p[s.clone()]
                .iter_mut()
                .zip(&z[s])
                .for_each(|(p, z)| *p = z + beta * *p);
        }
        iterations += 1;
    }
    Ok(Solved {
        iterations,
        residual: relative(&r),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::{BuildParams, build};
    use crate::memory::Budget;
    use crate::rigid::Vect;
    use crate::solve::constraints::{Constraints, Role};
    use rand::{Rng, SeedableRng, rngs::StdRng};
    use std::sync::{Arc, Mutex};

    /// A plate of cells over a wavy ground, its west end fixed: the global step's matrix.
    fn plate() -> (Laplacian, CellComplex<3>, Vec<Option<u32>>) {
        let mut rng = StdRng::seed_from_u64(11);
        let pts: Vec<Vect<3>> = (0..60_000)
            .map(|_| {
                let (x, y) = (rng.random_range(0.0..40.0), rng.random_range(0.0..10.0));
                Vect::<3>::new(x, y, (0.3 * x).sin() + 0.2 * rng.random_range(0.0..1.0))
            })
            .collect();
        let params = BuildParams {
            cell_size: Some(0.5),
            ..Default::default()
        };
        let complex = build(&pts, &[], &params, Budget::default()).unwrap().0;
        let roles = complex
            .cells
            .iter()
            .map(|c| {
                if c.center.x + complex.grid.origin.x < 2.0 {
                    Role::Fixed
                } else {
                    Role::Free
                }
            })
            .collect();
        let (l, row) = Laplacian::of(&complex, &Constraints::held(&complex, roles));
        (l, complex, row)
    }

    /// The preconditioned solve equals the factored one, and its iterations barely grow from 4
    /// subdomains to 16 (the coarse space's work); without the coarse space they would grow.
    #[test]
    fn schwarz_solves_as_the_factor_does_with_iterations_flat_in_the_subdomains() {
        let (l, complex, row) = plate();
        let n = l.n;
        assert!(n > 2000, "{n} free cells");
        let mut rng = StdRng::seed_from_u64(3);
        let b: Vec<f64> = (0..3 * n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let exact = Factored::new(&l).unwrap().solve(&b).unwrap();
        let scale = exact.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        let mut iterations = Vec::new();
        for k in [4, 16] {
            let sub = Subdomains::split(&complex, &row, k);
            assert_eq!(sub.parts().iter().map(Vec::len).sum::<usize>(), n);
            let m = Schwarz::new(&l, &sub, OVERLAP, aggregate_size(n), None)
                .unwrap()
                .unwrap();
            let mut x = vec![0.0; 3 * n];
            let solved = solve(&l, &m, &b, &mut x, 1e-10, 500).unwrap();
            assert!(solved.residual <= 1e-10, "{solved:?}");
            let error = x
                .iter()
                .zip(&exact)
                .map(|(x, e)| (x - e).abs())
                .fold(0.0, f64::max);
            assert!(
                error <= 1e-7 * scale,
                "{k} subdomains: error {error} of {scale}"
            );
            iterations.push(solved.iterations);
        }
        // 36 and 49 measured; the aggregates' plain indicators need about a third more.
        assert!(
            iterations[0] <= 42 && iterations[1] <= 55,
            "iterations at 4 and 16 subdomains: {iterations:?}"
        );
        assert!(
            iterations[1] as f64 <= 1.5 * iterations[0] as f64,
            "iterations at 4 and 16 subdomains: {iterations:?}"
        );
    }

    /// Entries given twice are summed, a row with no entry stays empty, and every row is whole.
    #[test]
    fn rows_are_built_whole_from_a_lower_triangle() {
        let t = |r, c, v| Triplet::new(r, c, v);
        let l = Laplacian::from_lower(
            4,
            &[t(0, 0, 2.0), t(2, 0, -1.0), t(2, 0, -0.5), t(2, 2, 3.0)],
        );
        let rows: Vec<Vec<(usize, f64)>> = (0..4).map(|r| l.row(r).collect()).collect();
        assert_eq!(rows[0], vec![(0, 2.0), (2, -1.5)]);
        assert!(rows[1].is_empty() && rows[3].is_empty());
        assert_eq!(rows[2], vec![(0, -1.5), (2, 3.0)]);
    }

    /// The coarse matrix is `Pᵀ L P` of the smoothed aggregates, entry for entry.
    #[test]
    fn the_coarse_matrix_is_the_galerkin_product() {
        let (l, _, _) = plate();
        let n = 300.min(l.n);
        // The leading block of the plate's matrix, a Laplacian of its own.
        let lower: Vec<_> = (0..n)
            .flat_map(|r| {
                l.row(r)
                    .filter(move |&(c, _)| c <= r)
                    .map(move |(c, v)| Triplet::new(r, c, v))
            })
            .collect();
        let l = Laplacian::from_lower(n, &lower);
        let of: Vec<u32> = (0..n as u32).map(|i| i / 7).collect();
        let m = of[n - 1] as usize + 1;
        let p = smoothed(&l, &of);
        let dense =
            |f: &dyn Fn(usize, usize) -> f64, rows, cols| Mat::<f64>::from_fn(rows, cols, f);
        let lm = dense(
            &|i, j| l.row(i).filter(|&(c, _)| c == j).map(|(_, v)| v).sum(),
            n,
            n,
        );
        let pm = dense(
            &|i, g| p.row(i).filter(|&(h, _)| h == g).map(|(_, w)| w).sum(),
            n,
            m,
        );
        let want = pm.transpose() * &lm * &pm;
        let mut got = Mat::<f64>::zeros(m, m);
        for e in p.galerkin(&l) {
            assert!(e.row >= e.col);
            got[(e.row, e.col)] += e.val;
        }
        for a in 0..m {
            for b in 0..=a {
                assert!((got[(a, b)] - want[(a, b)]).abs() <= 1e-12 * want[(a, a)].abs().max(1.0));
            }
        }
    }

    /// With every cell held there is nothing to solve, by subdomains as by the factor.
    #[test]
    fn no_free_cell_leaves_nothing_to_solve() {
        let (_, complex, _) = plate();
        let n = complex.len();
        let constraints = Constraints::held(&complex, vec![Role::Fixed; n]);
        let (l, row) = Laplacian::of(&complex, &constraints);
        assert_eq!(l.n, 0);
        assert!(
            Subdomains::split(&complex, &row, 4)
                .parts()
                .iter()
                .all(Vec::is_empty)
        );
        let positions =
            super::super::positions::Positions::by_subdomains(&complex, &constraints, 4, None)
                .unwrap();
        assert!(!positions.is_factored());
    }

    /// Workers that factor and solve the blocks they are sent in this process, counting the
    /// blocks and the solves, or failing the solves from the `fail_at`-th on: what a process
    /// pool does, without the processes.
    struct Pool {
        blocks: Mutex<usize>,
        solves: Arc<Mutex<usize>>,
        fail_at: usize,
    }

    struct PoolSolves {
        factors: Vec<BlockFactor>,
        solves: Arc<Mutex<usize>>,
        fail_at: usize,
    }

    impl Workers for Pool {
        fn factor(&self, blocks: Vec<Block>) -> Result<Box<dyn BlockSolves>> {
            *self.blocks.lock().unwrap() += blocks.len();
            let factors = blocks
                .iter()
                .map(|b| b.factor().ok_or_else(|| Error::solver("not definite")))
                .collect::<Result<Vec<_>>>()?;
            Ok(Box::new(PoolSolves {
                factors,
                solves: Arc::clone(&self.solves),
                fail_at: self.fail_at,
            }))
        }
    }

    impl BlockSolves for PoolSolves {
        fn solve(&self, rhs: Vec<Vec<f64>>) -> Result<Vec<Vec<f64>>> {
            let mut solves = self.solves.lock().unwrap();
            *solves += 1;
            if *solves >= self.fail_at {
                return Err(Error::solver("worker lost"));
            }
            Ok(self
                .factors
                .iter()
                .zip(&rhs)
                .map(|(f, r)| f.solve(r).unwrap())
                .collect())
        }
    }

    /// Blocks solved by workers give the bits of blocks solved here, each block sent once;
    /// a worker's failure ends the solve with its error, and workers no longer registered are
    /// named as gone.
    #[test]
    fn workers_solve_the_blocks_as_this_process_does_and_their_failure_ends_the_solve() {
        let (l, complex, row) = plate();
        let n = l.n;
        let mut rng = StdRng::seed_from_u64(5);
        let b: Vec<f64> = (0..3 * n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let sub = Subdomains::split(&complex, &row, 6);
        let here = Schwarz::new(&l, &sub, OVERLAP, aggregate_size(n), None)
            .unwrap()
            .unwrap();
        let mut x_here = vec![0.0; 3 * n];
        let solved_here = solve(&l, &here, &b, &mut x_here, 1e-10, 500).unwrap();

        let pool = Arc::new(Pool {
            blocks: Mutex::new(0),
            solves: Arc::new(Mutex::new(0)),
            fail_at: usize::MAX,
        });
        let registration = register(Arc::clone(&pool) as Arc<dyn Workers>);
        let workers = registered(registration.id()).unwrap();
        let there = Schwarz::new(&l, &sub, OVERLAP, aggregate_size(n), Some(&*workers))
            .unwrap()
            .unwrap();
        let mut x_there = vec![0.0; 3 * n];
        let solved_there = solve(&l, &there, &b, &mut x_there, 1e-10, 500).unwrap();
        assert_eq!(x_there, x_here);
        assert_eq!(solved_there, solved_here);
        assert_eq!(*pool.blocks.lock().unwrap(), 6);
        // One solve of the blocks per iteration, and one before the first.
        assert_eq!(*pool.solves.lock().unwrap(), solved_here.iterations + 1);
        let id = registration.id();
        drop(registration);
        assert!(registered(id).is_err());

        let failing = Pool {
            blocks: Mutex::new(0),
            solves: Arc::new(Mutex::new(0)),
            fail_at: 5,
        };
        let m = Schwarz::new(&l, &sub, OVERLAP, aggregate_size(n), Some(&failing))
            .unwrap()
            .unwrap();
        let mut x = vec![0.0; 3 * n];
        let e = solve(&l, &m, &b, &mut x, 1e-10, 500).unwrap_err();
        assert!(e.to_string().contains("worker lost"), "{e}");

        // Answers of the wrong length are an error, not a preconditioner that adds nothing.
        struct Short;
        impl Workers for Short {
            fn factor(&self, _: Vec<Block>) -> Result<Box<dyn BlockSolves>> {
                Ok(Box::new(Short))
            }
        }
        impl BlockSolves for Short {
            fn solve(&self, rhs: Vec<Vec<f64>>) -> Result<Vec<Vec<f64>>> {
                Ok(rhs.iter().map(|r| r[1..].to_vec()).collect())
            }
        }
        let m = Schwarz::new(&l, &sub, OVERLAP, aggregate_size(n), Some(&Short))
            .unwrap()
            .unwrap();
        let e = solve(&l, &m, &b, &mut x, 1e-10, 500).unwrap_err();
        assert!(e.to_string().contains("wrong number of values"), "{e}");
    }
}
