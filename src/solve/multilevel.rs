//! The multilevel solve of the Gauss-Newton normal equations (`--solver multilevel`).
//!
//! The normal equations `H δ = −g` of [`super::system`] are block-sparse: one `DOF × DOF` block
//! per cell with freedom and one per pair of such face neighbors. This module solves them by
//! conjugate gradients preconditioned with a smoothed-aggregation multigrid whose coarse space
//! is the rigid motions themselves:
//!
//! - **Groups.** Cells are grouped by the blocks of a regular grid (rest centers), from twice
//!   the finest cell size grown by a quarter a try until the groups hold [`MEMBERS`] cells on
//!   average, and on (to at most [`MAX_MEMBERS`]) until their level is small enough to factor
//!   ([`FACTORED`]). Each further level groups the last one's groups by a grid twice as coarse
//!   again (doubled where that merges too little). Groups of twice the cell size (four cells on
//!   a terrain one cell thick) made a coarse level that cost more to build and factor than the
//!   iterations it saved: on the 2.5 m hilly strip 13.9k groups against 5.6k, 1.3–1.4 s of a
//!   hierarchy against 0.55. The bent plate is the exception: groups of four take half the
//!   conjugate-gradient iterations of eight there, and it is 7–15 % slower with eight
//!   (BENCHMARKS.md §3, "Groups of eight").
//! - **Coarse space.** A group moves rigidly: a velocity `(V, Ω)` about its deformed centroid `Z`
//!   gives each member `ω_i = Ω`, `v_i = V + Ω × (y_i − Z)` (`y_i` the member's deformed center;
//!   a pinned cell takes only `Ω`). On the first level this tentative prolongation `P₀` is
//!   smoothed once, `P = (I − 4/(3λ) D⁻¹H) P₀`; further levels use `P₀` itself. Each coarse
//!   matrix is the Galerkin product `Pᵀ H P`; levels are added until one has at most
//!   [`FACTORED`] nodes, or at most four times as many and a factor of at most
//!   [`FACTOR_WORK`] multiply-adds, which faer's sparse Cholesky factors in AMD's order of
//!   the nodes' graph, each node's unknowns together, in `f32` (in `f64` where `f32` breaks
//!   down; `blocks::CoarseFactor`).
//! - **Smoothing.** A Chebyshev polynomial of degree [`SMOOTH_DEGREE`] in the block-Jacobi
//!   preconditioned matrix over `[λ/RATIO, λ]`, `λ` its largest eigenvalue by power iteration,
//!   the same before and after the coarse correction (a symmetric positive preconditioner).
//!   It multiplies by `f32` copies of the level matrices (half the memory traffic of the
//!   smoothing, which is most of an iteration); conjugate gradients multiply by the `f64` one.
//! - **Kept between steps.** Once a Gauss-Newton step has lowered the energy by less than
//!   half, the next step keeps the coarse levels and renews only the finest level's matrix and
//!   smoother ([`Hierarchy::refresh`]): the preconditioner stays symmetric positive definite,
//!   only less exact; it is rebuilt when it takes more than three times the iterations it
//!   first took (plus two) to reduce the residual to [`LOOSEST`], which every solve reaches (a
//!   refreshed hierarchy loses most in the first iterations: on the bent plate of BENCHMARKS.md
//!   §3, 3 of a fresh one's to [`LOOSEST`] became 7 and 9 with 11 and 10 in all, where a
//!   rebuild cost as much as the solves it shortened).
//!
//! Conjugate gradients stop at a relative residual between [`LOOSEST`] and [`TOLERANCE`] of the
//! right-hand side, as the system's forcing term says (inexact Newton: the first system of a
//! solve to [`LOOSEST`], each later one as far as the gradient's fall says its step is worth;
//! [`forcing`]). Gauss-Newton needs a descent direction, and its line search and energy
//! test are unchanged, so it reaches the direct solve's minimum (tested in `tests/solver.rs`;
//! the levels and the refresh on a lattice plate in this module's tests).
//!
//! **Why these levels** (BENCHMARKS.md, the 1 km corridor at 1.25 m, 432k free cells): with
//! two levels the coarse level (74k groups, the smoothed prolongation's wide stencil) took
//! 45–54 s to factor per step, 341 s in all; smoothing every level widens each stencil again
//! (a third level of 13.7k groups with 71 neighbors each took 13 s to factor, 239 s in all);
//! unsmoothed levels below the first keep the stencil and the iteration count (12–16 per step
//! against 10–13): 115 s and 4.4 GB instead of 10.5. A fourth unsmoothed level (2.8k groups)
//! doubled the iterations; so the coarsening stops at [`FACTORED`] nodes, as few unsmoothed
//! levels as the factor's cost allows — and sooner where the factor's work, counted on the
//! level's graph, is small (a terrain one cell thick, whose levels are nearly planar: there
//! one unsmoothed level can take the iterations from 7 to 100). Geometric nested dissection
//! of the coarse level, tried instead of faer's AMD, gave a factor half as large again (77M
//! entries against 49M at 13.7k groups).
//! Other coarse spaces and cycles measured slower (BENCHMARKS.md §13).

mod smoothing;

use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::blocks::*;
use crate::rigid::{Dim, Rigid, Vect};
use smoothing::{Work, chebyshev, largest_eigenvalue};

/// A system of at most this many nodes is factored directly, without a hierarchy.
pub(crate) const COARSEST: usize = 2000;
/// Levels past the first are coarsened until they have at most this many nodes; the last is
/// factored directly (0.35–0.45 s in `f32` at the hilly strip's 13.9k nodes with the first
/// level's wide stencil, 33M entries). Each unsmoothed level costs iterations: on the
/// 10M-point terrain at 123k cells, a third level below a first coarse level of 20k groups
/// took 224 CG iterations where two levels took 26.
pub(crate) const FACTORED: usize = 30_000;
/// A coarse level of up to four times [`FACTORED`] nodes is factored all the same where its
/// factor takes at most this many multiply-adds (counted on its graph, `auto::graph_fill`):
/// one more unsmoothed level can cost far more than a larger factor. The 10M-point terrain at
/// 3.9 m cells (206k free cells, a plate about one cell thick) groups into 52,968 nodes; a
/// third level below them took 96–105 conjugate-gradient iterations a step, the factor of those
/// nodes (1.5e8 entries, 4–5 s in `f32`) 6–7 (BENCHMARKS.md §3, "A larger coarsest level
/// where its factor is cheap").
pub(crate) const FACTOR_WORK: f64 = 2.5e11;

/// Where a hierarchy stops coarsening: [`LIMITS`] but in tests.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Limits {
    /// A finest level of at most this many nodes is factored as it is.
    pub coarsest: usize,
    /// A coarse level of at most this many nodes is factored.
    pub factored: usize,
    /// A coarse level of at most four times `factored` nodes is factored where its factor
    /// takes at most this many multiply-adds.
    pub work: f64,
}

/// The limits every solve takes.
pub(crate) const LIMITS: Limits = Limits {
    coarsest: COARSEST,
    factored: FACTORED,
    work: FACTOR_WORK,
};
/// The first level's groups hold this many nodes on average.
const MEMBERS: f64 = 8.0;
/// The first level's groups hold at most this many nodes on average where more would be
/// needed to make their level small enough to factor.
const MAX_MEMBERS: f64 = 24.0;
/// The first level's grid grows by this factor a try.
const GROW: f64 = 1.25;
/// The Chebyshev smoother's degree.
const SMOOTH_DEGREE: usize = 2;
/// The smoother targets the upper `1/RATIO` of the spectrum of `D⁻¹H`.
const RATIO: f64 = 12.0;
/// The tightest relative residual conjugate gradients solve to (the forcing term's floor).
pub(crate) const TOLERANCE: f64 = 1e-4;
/// The loosest relative residual a Gauss-Newton system is solved to: the first of a solve, and
/// the forcing term's ceiling after it ([`forcing`]).
pub(crate) const LOOSEST: f64 = 1e-2;
/// Conjugate-gradient iterations at most.
const MAX_ITERATIONS: usize = 300;

/// One level of the hierarchy and the way to the next coarser one.
struct Level {
    /// The level's matrix (the finest level's only: conjugate gradients multiply by it).
    matrix: BlockMatrix,
    /// The matrix in `f32`, which the smoother and the cycle's residual multiply by.
    smoother: BlockMatrix<f32>,
    inverse: Vec<f64>,
    /// Largest eigenvalue of `D⁻¹H` (estimated, with a margin).
    lambda: f64,
    /// The prolongation to this level from the next coarser one.
    prolongation: Prolongation,
}

/// The relative residual to which conjugate gradients solve a Newton system whose gradient has
/// the norm `gradient`, after one whose gradient had the norm `previous` (inexact Newton with
/// Eisenstat and Walker's second forcing term, γ = 0.9 and α = 2): a system is solved only as
/// far as its step is worth, `0.9 (‖g‖ / ‖g_previous‖)²`, between [`TOLERANCE`] and
/// [`LOOSEST`], and the first of a solve to [`LOOSEST`]. Far from the minimum the quadratic
/// model a step solves is itself rough, so a tighter solve there buys nothing; where Newton
/// converges fast the gradient falls fast, and the solves tighten to [`TOLERANCE`] by the last
/// steps (BENCHMARKS.md §3, "Inexact Newton steps").
///
/// Those last steps are expected to move the cells by little, and a relative residual only has
/// to place a step within a fraction of the move tolerance: `enough` (the caller's estimate of
/// the loosest residual that does, [`super::iteration::enough_residual`]; 0 where it has none)
/// loosens the forcing term up to [`LOOSEST`]. On the bent plate the step that confirms the
/// solve has stopped moved 0.001 cells and took 47 iterations at [`TOLERANCE`].
pub(crate) fn forcing(gradient: f64, previous: Option<f64>, enough: f64) -> f64 {
    let forcing = match previous {
        Some(last) if last > 0.0 => (0.9 * (gradient / last).powi(2)).clamp(TOLERANCE, LOOSEST),
        _ => LOOSEST,
    };
    forcing.max(enough.min(LOOSEST))
}

/// What [`Hierarchy::solve_to`] found: the solution, its conjugate-gradient iterations, and
/// how many of them took the residual to [`LOOSEST`] of the right-hand side.
pub(crate) struct Solved {
    pub x: Vec<f64>,
    pub iterations: usize,
    pub to_loosest: usize,
}

/// A block-sparse prolongation: the coarse nodes `to[start[i]..start[i + 1]]` of fine node `i`
/// and their blocks; and by coarse node, its entries with their fine nodes
/// `entries[from[g]..from[g + 1]]` (in fine node order), so that the restriction sums each coarse row in one fixed order, whatever the
/// number of threads (the same bits on every machine).
struct Prolongation {
    start: Vec<u32>,
    to: Vec<u32>,
    blocks: Vec<f64>,
    coarse: usize,
    from: Vec<u32>,
    entries: Vec<[u32; 2]>,
}

/// The multigrid hierarchy of one Gauss-Newton system.
pub(crate) struct Hierarchy {
    levels: Vec<Level>,
    coarsest: Option<CoarseFactor>,
}

/// What a node of a level is, for grouping and the rigid prolongation.
pub(crate) struct Nodes<const D: usize> {
    /// Rest position (grouping).
    pub rest: Vec<Vect<D>>,
    /// Deformed position (the lever arm of the coarse rotation).
    pub deformed: Vec<Vect<D>>,
    /// Whether the node has only rotational unknowns (a pinned cell, its unknowns first).
    pub pinned: Vec<bool>,
}

impl Hierarchy {
    /// The hierarchy of `matrix`, whose nodes are `nodes`; `size` is the finest cell size. A
    /// matrix of at most `limits.coarsest` nodes is factored as it is; otherwise levels are
    /// added until one is factored by `limits` ([`LIMITS`] but in tests). `reuse`:
    /// an earlier hierarchy's coarsest factor ([`Hierarchy::into_coarsest`]), whose analysis
    /// serves again where the coarsest level has the same nodes and edges.
    pub fn new<const D: usize>(
        matrix: BlockMatrix,
        nodes: Nodes<D>,
        size: f64,
        limits: Limits,
        reuse: Option<CoarseFactor>,
    ) -> Self
    where
        Dim<D>: Rigid<D>,
    {
        let mut levels: Vec<Level> = Vec::new();
        let (mut matrix, mut nodes, mut step) = (matrix, nodes, 2.0 * size);
        while !factors(matrix.n, &matrix.edges, matrix.dof, levels.len(), limits) {
            let (group, count) = groups(
                &nodes.rest,
                &mut step,
                levels.is_empty().then_some(limits.factored),
            );
            let coarse = coarse_nodes(&nodes, &group, count);
            let tentative = prolongation::<D>(&nodes, &coarse.deformed, &group);
            let inverse = matrix.block_inverses();
            let lambda = largest_eigenvalue(&matrix, &inverse);
            let prolongation = if levels.is_empty() {
                smoothed(&matrix, &inverse, lambda, &group, &tentative, count)
            } else {
                Prolongation::new((0..=matrix.n as u32).collect(), group, tentative, count)
            };
            let next = galerkin(&matrix, &prolongation);
            let smoother = matrix.to_f32();
            let kept = if levels.is_empty() {
                std::mem::replace(&mut matrix, BlockMatrix::empty(0))
            } else {
                BlockMatrix::empty(matrix.dof)
            };
            levels.push(Level {
                matrix: kept,
                smoother,
                inverse,
                lambda,
                prolongation,
            });
            (matrix, nodes) = (next, coarse);
        }
        Self {
            coarsest: factor_coarsest(&matrix, reuse),
            levels,
        }
    }

    /// The hierarchy for `matrix`, a new matrix of the finest level's pattern: its smoother is
    /// renewed, the coarse levels kept (a preconditioner that stays symmetric and positive
    /// definite, only less exact).
    pub fn refresh(&mut self, matrix: BlockMatrix) {
        match self.levels.first_mut() {
            Some(fine) => {
                fine.inverse = matrix.block_inverses();
                fine.lambda = largest_eigenvalue(&matrix, &fine.inverse);
                fine.smoother = matrix.to_f32();
                fine.matrix = matrix;
            }
            None => self.coarsest = factor_coarsest(&matrix, self.coarsest.take()),
        }
    }

    /// Frees the finest level's smoother and block inverses while the hierarchy waits for
    /// [`Hierarchy::refresh`] and hands back its matrix, whose storage the next Gauss-Newton
    /// step assembles its own into (`None` for a hierarchy that is only its coarsest factor).
    pub fn shed_finest(&mut self) -> Option<BlockMatrix> {
        let fine = self.levels.first_mut()?;
        let dof = fine.matrix.dof;
        fine.smoother = BlockMatrix::empty(dof);
        fine.inverse = Vec::new();
        Some(std::mem::replace(&mut fine.matrix, BlockMatrix::empty(dof)))
    }

    /// The coarsest level's analysis, for the next hierarchy of the same cells (its numeric
    /// factor freed first: the next one is made before this one would be dropped).
    pub fn into_coarsest(self) -> Option<CoarseFactor> {
        self.coarsest.map(|mut f| {
            f.values = None;
            f
        })
    }

    /// Levels including the coarsest.
    pub fn depth(&self) -> usize {
        self.levels.len() + 1
    }

    /// Solves `H x = b` by preconditioned conjugate gradients on the finest level; returns the
    /// solution and the iterations, or `None` when the iteration broke down (a matrix that is not
    /// positive definite).
    #[cfg(test)]
    pub fn solve(&self, b: &[f64]) -> Option<(Vec<f64>, usize)> {
        self.solve_to(b, TOLERANCE).map(|s| (s.x, s.iterations))
    }

    /// [`Hierarchy::solve`] to a relative residual of `tolerance` (at most [`LOOSEST`]).
    pub fn solve_to(&self, b: &[f64], tolerance: f64) -> Option<Solved> {
        let solved = |x: Vec<f64>, iterations, to_loosest| {
            x.iter().all(|v| v.is_finite()).then_some(Solved {
                x,
                iterations,
                to_loosest,
            })
        };
        let Some(fine) = self.levels.first() else {
            return solved(self.coarse_solve(b), 0, 0);
        };
        let n = b.len();
        let norm_b = norm(b);
        let mut x = vec![0.0; n];
        if norm_b == 0.0 {
            return solved(x, 0, 0);
        }
        let mut to_loosest = None;
        let mut work = self.work();
        let mut r = b.to_vec();
        let mut z = vec![0.0; n];
        self.cycle(0, &r, &mut z, &mut work);
        let mut p = z.clone();
        let mut rz = par_dot(&r, &z);
        let mut q = vec![0.0; n];
        for it in 1..=MAX_ITERATIONS {
            fine.matrix.mul(&p, &mut q);
            let pq = par_dot(&p, &q);
            if !(pq > 0.0 && rz.is_finite()) {
                return None;
            }
            let alpha = rz / pq;
            x.par_iter_mut().zip(&p).for_each(|(x, p)| *x += alpha * p);
            r.par_iter_mut().zip(&q).for_each(|(r, q)| *r -= alpha * q);
            let residual = norm(&r);
            if residual <= LOOSEST * norm_b {
                to_loosest.get_or_insert(it);
            }
            if residual <= tolerance * norm_b || it == MAX_ITERATIONS {
                return solved(x, it, to_loosest.unwrap_or(it));
            }
            self.cycle(0, &r, &mut z, &mut work);
            let rz_new = par_dot(&r, &z);
            let beta = rz_new / rz;
            rz = rz_new;
            p.par_iter_mut()
                .zip(&z)
                .for_each(|(p, z)| *p = z + beta * *p);
        }
        None
    }

    /// The buffers of a V-cycle, one set a level, allocated once a solve: each is 55 MB on the
    /// finest level at the 1.14M cells of BENCHMARKS.md §4, which the kernel would map and zero
    /// anew if every conjugate-gradient iteration allocated it.
    fn work(&self) -> Vec<Work> {
        self.levels
            .iter()
            .map(|level| {
                let n = level.smoother.len();
                let coarse = level.prolongation.coarse * level.smoother.dof;
                Work {
                    residual: vec![0.0; n],
                    smoothing: vec![0.0; n],
                    direction: vec![0.0; n],
                    product: vec![0.0; n],
                    preconditioned: vec![0.0; n],
                    coarse_b: vec![0.0; coarse],
                    coarse_x: vec![0.0; coarse],
                }
            })
            .collect()
    }

    /// One V-cycle from level `l` for the right-hand side `b`, from a zero guess, into `x`:
    /// smoothing, the coarse correction, smoothing. `work`: the buffers of level `l` and on.
    fn cycle(&self, l: usize, b: &[f64], x: &mut [f64], work: &mut [Work]) {
        let (Some(level), Some((w, coarser))) = (self.levels.get(l), work.split_first_mut()) else {
            x.copy_from_slice(&self.coarse_solve(b));
            return;
        };
        let a = &level.smoother;
        let d = a.dof;
        x.fill(0.0);
        chebyshev(level, b, x, true, w);
        a.mul(x, &mut w.residual);
        w.residual
            .par_iter_mut()
            .zip(b)
            .for_each(|(r, b)| *r = b - *r);
        level.prolongation.restrict(&w.residual, d, &mut w.coarse_b);
        self.cycle(l + 1, &w.coarse_b, &mut w.coarse_x, coarser);
        level.prolongation.prolong(&w.coarse_x, x, d);
        chebyshev(level, b, x, false, w);
    }

    fn coarse_solve(&self, b: &[f64]) -> Vec<f64> {
        self.coarsest
            .as_ref()
            .and_then(|f| f.solve(b))
            .unwrap_or_else(|| vec![0.0; b.len()])
    }
}

/// The hierarchy [`Hierarchy::new`] builds for nodes at `rest` coupled by `edges`, counted on
/// the graph alone, before any matrix is assembled: what the multilevel solve's memory and
/// work go with.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Shape {
    /// Nodes and edges of every level, the finest first; the last is factored.
    pub levels: Vec<(usize, usize)>,
    /// Blocks of the first level's smoothed prolongation.
    pub prolongation: usize,
    /// The edges of the last level, which is factored.
    pub coarsest_edges: Vec<[u32; 2]>,
}

/// The [`Shape`] of the hierarchy of nodes at `rest` (the free cells' rest centers) coupled by
/// `edges`, for finest cells of `size`, under the `limits` [`Hierarchy::new`] takes: the same
/// groups, and each coarse level's edges as its Galerkin product makes them (the first through
/// the smoothed prolongation, whose coarse node reaches the members of its group and their
/// neighbors; the others through the groups alone).
pub(crate) fn shape<const D: usize>(
    rest: Vec<Vect<D>>,
    edges: &[[u32; 2]],
    size: f64,
    limits: Limits,
) -> Shape
where
    Dim<D>: Rigid<D>,
{
    let mut shape = Shape {
        levels: vec![(rest.len(), edges.len())],
        ..Default::default()
    };
    let (mut rest, mut edges, mut step) = (rest, edges.to_vec(), 2.0 * size);
    while !factors(
        rest.len(),
        &edges,
        <Dim<D> as Rigid<D>>::DOF,
        shape.levels.len() - 1,
        limits,
    ) {
        let n = rest.len();
        let (group, count) = groups(
            &rest,
            &mut step,
            (shape.levels.len() == 1).then_some(limits.factored),
        );
        let mut sum = vec![(Vect::<D>::zeros(), 0u32); count];
        for (p, &g) in rest.iter().zip(&group) {
            sum[g as usize].0 += p;
            sum[g as usize].1 += 1;
        }
        rest = sum.into_iter().map(|(p, m)| p / m.max(1) as f64).collect();
        let coarse = if shape.levels.len() == 1 {
            let (coarse, blocks) = smoothed_pattern(n, &edges, &group);
            shape.prolongation = blocks;
            coarse
        } else {
            let mut coarse: Vec<u64> = edges
                .iter()
                .filter_map(|&[a, b]| {
                    let (g, h) = (group[a as usize], group[b as usize]);
                    (g != h).then(|| ((g.min(h) as u64) << 32) | g.max(h) as u64)
                })
                .collect();
            coarse.par_sort_unstable();
            coarse.dedup();
            coarse
        };
        edges = coarse
            .into_iter()
            .map(|k| [(k >> 32) as u32, k as u32])
            .collect();
        shape.levels.push((count, edges.len()));
    }
    shape.coarsest_edges = edges;
    shape
}

/// Whether level `depth` (0 the finest) of `n` nodes of `dof` unknowns joined by `edges` is
/// factored rather than coarsened again ([`Limits`]).
fn factors(n: usize, edges: &[[u32; 2]], dof: usize, depth: usize, limits: Limits) -> bool {
    match depth {
        0 => n <= limits.coarsest,
        _ => {
            n <= limits.factored
                || n <= 4 * limits.factored
                    && super::auto::graph_fill(n, edges, dof)
                        .is_some_and(|fill| fill.flops <= limits.work)
        }
    }
}

/// The coarse edges of the Galerkin product through the smoothed prolongation of `group`, as
/// sorted keys `g << 32 | h` (`g < h`), and the prolongation's blocks: fine node `i` reaches
/// the groups `S(i)` of itself and its neighbors, and the coarse matrix couples each group of
/// `S(i)` with each group of `S(k)` for `k` = `i` and its neighbors. Counted a bounded chunk of
/// fine nodes at a time.
fn smoothed_pattern(n: usize, edges: &[[u32; 2]], group: &[u32]) -> (Vec<u64>, usize) {
    let mut start = vec![0u32; n + 1];
    for &[a, b] in edges {
        start[a as usize + 1] += 1;
        start[b as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut adjacent = vec![0u32; start[n] as usize];
    for &[a, b] in edges {
        adjacent[fill[a as usize] as usize] = b;
        fill[a as usize] += 1;
        adjacent[fill[b as usize] as usize] = a;
        fill[b as usize] += 1;
    }
    drop(fill);
    let neighbors = |i: usize| &adjacent[start[i] as usize..start[i + 1] as usize];
    let reach = |i: usize| -> Vec<u32> {
        let mut s: Vec<u32> = std::iter::once(group[i])
            .chain(neighbors(i).iter().map(|&j| group[j as usize]))
            .collect();
        s.sort_unstable();
        s.dedup();
        s
    };
    let blocks: usize = (0..n).into_par_iter().map(|i| reach(i).len()).sum();
    let (mut coarse, mut sorted): (Vec<u64>, usize) = (Vec::new(), 0);
    const CHUNK: usize = 1 << 14;
    for from in (0..n).step_by(CHUNK) {
        let mut keys: Vec<u64> = (from..(from + CHUNK).min(n))
            .into_par_iter()
            .flat_map_iter(|i| {
                let own = reach(i);
                let mut far: Vec<u32> = std::iter::once(i as u32)
                    .chain(neighbors(i).iter().copied())
                    .flat_map(|k| reach(k as usize))
                    .collect();
                far.sort_unstable();
                far.dedup();
                own.into_iter().flat_map(move |g| {
                    far.iter()
                        .filter(move |&&h| h > g)
                        .map(move |&h| ((g as u64) << 32) | h as u64)
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        keys.par_sort_unstable();
        keys.dedup();
        coarse.extend(keys);
        if coarse.len() > 2 * sorted + (1 << 20) {
            coarse.par_sort_unstable();
            coarse.dedup();
            sorted = coarse.len();
        }
    }
    coarse.par_sort_unstable();
    coarse.dedup();
    (coarse, blocks)
}

/// The groups of a level's nodes at `rest`, and the step of the grid the next level starts
/// from. The first level's grid (`factored`: [`Limits::factored`]) grows from `step` until its
/// groups hold [`MEMBERS`] nodes on average, and on until they are few enough to be factored
/// or hold [`MAX_MEMBERS`]; each further level's doubles until it merges the nodes to at most
/// 0.7 of them.
fn groups<const D: usize>(
    rest: &[Vect<D>],
    step: &mut f64,
    first: Option<usize>,
) -> (Vec<u32>, usize) {
    let n = rest.len() as f64;
    loop {
        let (group, count) = group_by_grid(rest, *step);
        let enough = match first {
            Some(factored) => {
                count as f64 * MEMBERS <= n
                    && (count <= factored || count as f64 * MAX_MEMBERS <= n)
            }
            None => (count as f64) < 0.7 * n,
        };
        if enough || *step > 1e300 {
            *step *= 2.0;
            return (group, count);
        }
        *step *= if first.is_some() { GROW } else { 2.0 };
    }
}

/// Groups the points by the cells of a grid of step `step`: the group of every point and the
/// number of groups, numbered in the order they are first met.
fn group_by_grid<const D: usize>(points: &[Vect<D>], step: f64) -> (Vec<u32>, usize) {
    let mut ids: FxHashMap<[i64; D], u32> = FxHashMap::default();
    let group = points
        .iter()
        .map(|p| {
            let key = std::array::from_fn(|a| (p[a] / step).floor() as i64);
            let next = ids.len() as u32;
            *ids.entry(key).or_insert(next)
        })
        .collect();
    (group, ids.len())
}

/// The groups as nodes: mean rest and deformed positions, never pinned.
fn coarse_nodes<const D: usize>(nodes: &Nodes<D>, group: &[u32], count: usize) -> Nodes<D> {
    let mut rest = vec![Vect::<D>::zeros(); count];
    let mut deformed = vec![Vect::<D>::zeros(); count];
    let mut members = vec![0u32; count];
    for (i, &g) in group.iter().enumerate() {
        rest[g as usize] += nodes.rest[i];
        deformed[g as usize] += nodes.deformed[i];
        members[g as usize] += 1;
    }
    for g in 0..count {
        let m = members[g].max(1) as f64;
        rest[g] /= m;
        deformed[g] /= m;
    }
    Nodes {
        rest,
        deformed,
        pinned: vec![false; count],
    }
}

/// The prolongation block of every node: its velocity when its group moves rigidly about the
/// group's deformed centroid.
fn prolongation<const D: usize>(nodes: &Nodes<D>, centers: &[Vect<D>], group: &[u32]) -> Vec<f64>
where
    Dim<D>: Rigid<D>,
{
    let d = <Dim<D> as Rigid<D>>::DOF;
    let rot = <Dim<D> as Rigid<D>>::ROT;
    let mut p = vec![0.0; group.len() * d * d];
    p.par_chunks_mut(d * d).enumerate().for_each(|(i, block)| {
        if nodes.pinned[i] {
            for r in 0..rot {
                block[r * d + D + r] = 1.0;
            }
            return;
        }
        let lever = nodes.deformed[i] - centers[group[i] as usize];
        let cols = <Dim<D> as Rigid<D>>::cross_jacobian(&lever);
        for a in 0..D {
            block[a * d + a] = 1.0;
            for r in 0..rot {
                block[a * d + D + r] = cols[r][a];
            }
        }
        for r in 0..rot {
            block[(D + r) * d + D + r] = 1.0;
        }
    });
    p
}

impl Prolongation {
    fn new(start: Vec<u32>, to: Vec<u32>, blocks: Vec<f64>, coarse: usize) -> Self {
        let mut from = vec![0u32; coarse + 1];
        for &g in &to {
            from[g as usize + 1] += 1;
        }
        for g in 0..coarse {
            from[g + 1] += from[g];
        }
        let mut fill = from.clone();
        let mut entries = vec![[0u32; 2]; to.len()];
        for i in 0..start.len() - 1 {
            for e in start[i]..start[i + 1] {
                let g = to[e as usize] as usize;
                entries[fill[g] as usize] = [e, i as u32];
                fill[g] += 1;
            }
        }
        Self {
            start,
            to,
            blocks,
            coarse,
            from,
            entries,
        }
    }

    /// `rc = Pᵀ r`, each coarse row summed over its entries in fine node order.
    fn restrict(&self, r: &[f64], d: usize, rc: &mut [f64]) {
        let bb = d * d;
        rc.fill(0.0);
        rc.par_chunks_mut(d).enumerate().for_each(|(g, out)| {
            for &[e, i] in &self.entries[self.from[g] as usize..self.from[g + 1] as usize] {
                let (e, i) = (e as usize, i as usize);
                let ri = &r[i * d..(i + 1) * d];
                let p = &self.blocks[e * bb..(e + 1) * bb];
                for row in 0..d {
                    let v = ri[row];
                    if v != 0.0 {
                        for c in 0..d {
                            out[c] += p[row * d + c] * v;
                        }
                    }
                }
            }
        });
    }

    /// `x += P xc`.
    fn prolong(&self, xc: &[f64], x: &mut [f64], d: usize) {
        let bb = d * d;
        x.par_chunks_mut(d).enumerate().for_each(|(i, xi)| {
            for e in self.start[i] as usize..self.start[i + 1] as usize {
                let p = &self.blocks[e * bb..(e + 1) * bb];
                let g = self.to[e] as usize;
                let xg = &xc[g * d..(g + 1) * d];
                for row in 0..d {
                    xi[row] += dot(&p[row * d..(row + 1) * d], xg);
                }
            }
        });
    }
}

/// The smoothed-aggregation prolongation `(I − ω D⁻¹H) P₀` of the tentative (rigid) one `P₀`,
/// `ω = 4 / (3λ)`: a coarse motion is no longer rigid up to its group's border and jumps there,
/// but blends into its neighbors', so smooth low-energy modes (a thin plate bending) have
/// low-energy coarse representatives. (With the rigid `P₀` alone, a one-cell-thick terrain took
/// 30–50 conjugate-gradient iterations per Gauss-Newton step even with an exact coarse solve.)
fn smoothed(
    a: &BlockMatrix,
    inverse: &[f64],
    lambda: f64,
    group: &[u32],
    tentative: &[f64],
    coarse: usize,
) -> Prolongation {
    let d = a.dof;
    let bb = d * d;
    let omega = 4.0 / (3.0 * lambda);
    // The groups fine node `i` reaches, `S(i)`: its own first, then its neighbors' as met.
    let reach = |i: usize, out: &mut Vec<u32>| {
        out.clear();
        out.push(group[i]);
        for &e in &a.incident[a.start[i] as usize..a.start[i + 1] as usize] {
            let (k, side) = ((e >> 1) as usize, (e & 1) as usize);
            let g = group[a.edges[k][1 - side] as usize];
            if !out.contains(&g) {
                out.push(g);
            }
        }
    };
    let counts: Vec<u32> = (0..a.n)
        .into_par_iter()
        .map_init(Vec::new, |out, i| {
            reach(i, out);
            out.len() as u32
        })
        .collect();
    let mut start = Vec::with_capacity(a.n + 1);
    start.push(0u32);
    for c in &counts {
        start.push(start.last().copied().unwrap_or(0) + c);
    }
    let total = start[a.n] as usize;
    let mut to = vec![0u32; total];
    let mut blocks = vec![0.0; total * bb];
    // Rows in chunks, each chunk writing its own stretch of `to` and `blocks`.
    let chunk = 2048;
    let mut pieces = Vec::with_capacity(a.n.div_ceil(chunk));
    let (mut to_rest, mut blocks_rest) = (&mut to[..], &mut blocks[..]);
    for c in 0..a.n.div_ceil(chunk) {
        let (lo, hi) = (c * chunk, ((c + 1) * chunk).min(a.n));
        let len = (start[hi] - start[lo]) as usize;
        let (t, rest) = std::mem::take(&mut to_rest).split_at_mut(len);
        let (b, brest) = std::mem::take(&mut blocks_rest).split_at_mut(len * bb);
        (to_rest, blocks_rest) = (rest, brest);
        pieces.push((lo..hi, t, b));
    }
    // Each row's groups are found again here rather than kept from the count above: a short
    // scan of its neighbors, against a vector a row.
    pieces.into_par_iter().for_each(|(rows, to, blocks)| {
        let t = |j: usize| &tentative[j * bb..(j + 1) * bb];
        let mut groups = Vec::new();
        let mut at = 0;
        for i in rows {
            reach(i, &mut groups);
            let row = &mut blocks[at * bb..(at + groups.len()) * bb];
            to[at..at + groups.len()].copy_from_slice(&groups);
            // The neighbors' `H_ij P₀_j` summed by group (`P₀_j` is mostly zeros), then
            // `-ω D⁻¹` once a group: most neighbors share a group.
            for (j, hij) in a.row(i) {
                // `reach` put every neighbor's group in the row.
                let k = groups.iter().position(|&g| g == group[j]).unwrap_or(0);
                mul_add_sparse_right(&mut row[k * bb..(k + 1) * bb], &hij, t(j), d);
            }
            let dinv = &inverse[i * bb..(i + 1) * bb];
            for sum in row.chunks_mut(bb) {
                let mut m = matmul(dinv, sum, d);
                m.iter_mut().for_each(|v| *v *= -omega);
                sum.copy_from_slice(&m[..bb]);
            }
            // H_ii: D⁻¹ D P₀ = P₀, so the own group gets (1 − ω) P₀ᵢ more.
            row[..bb]
                .iter_mut()
                .zip(t(i))
                .for_each(|(o, v)| *o += (1.0 - omega) * v);
            at += groups.len();
        }
    });
    Prolongation::new(start, to, blocks, coarse)
}

/// `out += x y` for `d × d` blocks stored row by row, skipping the zero entries of `y` (a
/// rigid prolongation block: an identity and a lever's cross product).
fn mul_add_sparse_right(out: &mut [f64], x: &[f64], y: &[f64], d: usize) {
    for k in 0..d {
        for c in 0..d {
            let v = y[k * d + c];
            if v != 0.0 {
                for r in 0..d {
                    out[r * d + c] += x[r * d + k] * v;
                }
            }
        }
    }
}

/// The Galerkin product `Pᵀ H P`.
fn galerkin(a: &BlockMatrix, p: &Prolongation) -> BlockMatrix {
    let d = a.dof;
    let bb = d * d;
    let count = p.coarse;
    let pblocks = |i: usize| {
        (p.start[i] as usize..p.start[i + 1] as usize)
            .map(move |e| (p.to[e], &p.blocks[e * bb..(e + 1) * bb]))
    };
    // Each chunk of fine nodes sums its `P_iGᵀ (HP)_iH` into its own map of (G, H ≥ G).
    let chunk = 4096;
    let parts: Vec<(FxHashMap<u64, u32>, Vec<f64>)> = (0..a.n.div_ceil(chunk))
        .into_par_iter()
        .map(|c| {
            let mut map: FxHashMap<u64, u32> = FxHashMap::default();
            let mut blocks: Vec<f64> = Vec::new();
            let mut hp: Vec<(u32, Block)> = Vec::new();
            for i in c * chunk..((c + 1) * chunk).min(a.n) {
                hp.clear();
                for (g, pb) in pblocks(i) {
                    accumulate(&mut hp, g, &matmul(&a.diag[i * bb..(i + 1) * bb], pb, d));
                }
                for (j, hij) in a.row(i) {
                    for (g, pb) in pblocks(j) {
                        accumulate(&mut hp, g, &matmul(&hij, pb, d));
                    }
                }
                for (g, pb) in pblocks(i) {
                    for (h, m) in &hp {
                        if *h < g {
                            continue;
                        }
                        let key = ((g as u64) << 32) | *h as u64;
                        let at = *map.entry(key).or_insert_with(|| {
                            blocks.extend(std::iter::repeat_n(0.0, bb));
                            (blocks.len() / bb - 1) as u32
                        }) as usize;
                        mul_add(&mut blocks[at * bb..(at + 1) * bb], pb, true, m, d);
                    }
                }
            }
            (map, blocks)
        })
        .collect();
    let mut diag = vec![0.0; count * bb];
    let mut index: FxHashMap<u64, u32> = FxHashMap::default();
    let mut edges: Vec<[u32; 2]> = Vec::new();
    let mut blocks: Vec<f64> = Vec::new();
    for (map, part) in parts {
        for (key, at) in map {
            let m = &part[at as usize * bb..(at as usize + 1) * bb];
            let (g, h) = ((key >> 32) as u32, key as u32);
            if g == h {
                add(&mut diag[g as usize * bb..(g as usize + 1) * bb], m);
            } else {
                let e = *index.entry(key).or_insert_with(|| {
                    edges.push([g, h]);
                    blocks.extend(std::iter::repeat_n(0.0, bb));
                    (edges.len() - 1) as u32
                }) as usize;
                add(&mut blocks[e * bb..(e + 1) * bb], m);
            }
        }
    }
    // Symmetrize the diagonal blocks (sums of products round differently on each side).
    for g in 0..count {
        let m = &mut diag[g * bb..(g + 1) * bb];
        for r in 0..d {
            for c in 0..r {
                let v = 0.5 * (m[r * d + c] + m[c * d + r]);
                m[r * d + c] = v;
                m[c * d + r] = v;
            }
        }
    }
    // A group of pinned cells alone has no translational stiffness: keep those unknowns at 0.
    let scale = (0..count * d)
        .map(|u| diag[(u / d) * bb + (u % d) * (d + 1)])
        .fold(0.0f64, f64::max);
    for u in 0..count * d {
        let at = (u / d) * bb + (u % d) * (d + 1);
        if diag[at] <= 1e-14 * scale {
            diag[at] = scale.max(1.0);
        }
    }
    BlockMatrix::new(d, count, diag, edges, blocks)
}

#[cfg(test)]
#[path = "multilevel_tests.rs"]
mod tests;
