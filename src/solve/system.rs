//! The Gauss-Newton normal equations on rigid motions (paper §4).
//!
//! Each cell with freedom is linearized by a linear velocity `v_i` and an angular velocity `ω_i`
//! about its rotation center `z_i` (its rest center `c_i` when free, the pinned point when pinned):
//!
//! ```text
//! T_i(x) ≈ T_i(x) + v_i + ω_i × R_i (x − z_i)        (v_i = 0 for a pinned cell)
//! ```
//!
//! Every quadrature point `q` of a pair (see [`super::energy::quadrature`]) gives the residual
//! `√(s w α) (T_i(q) − T_j(q))`, every soft target the residual `√λ (T_i(q) − q')`. The normal
//! equations `(JᵀJ + μ diag(JᵀJ) + ε I) δ = −Jᵀr` are sparse with `DOF × DOF` blocks
//! (6×6 in 3D, 3×3 in 2D) and are factored by faer's supernodal Cholesky. The sparsity pattern
//! depends only on the cell topology and the roles, so the symbolic analysis (AMD ordering,
//! elimination tree, supernodes) is computed once per [`System`] and reused by every iteration
//! and load step; it is rebuilt only when refinement changes the cells. The numeric factor's
//! storage and scratch are kept with it too. The ordering is AMD's, with faer's default
//! supernode relaxation: the other orderings measured filled the factor more and solved no
//! faster (BENCHMARKS.md §13).
//!
//! Assembly writes each pair's blocks into its own fixed-size slot of the value array (in
//! parallel, no locking); faer's `new_from_argsort` sums the duplicate entries. The pattern,
//! the argsort and the symbolic factorization use 32-bit indices, half the memory of `usize`
//! ones (measured at 1.14M cells in BENCHMARKS.md).

use faer::Side;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::prelude::*;
use faer::sparse::linalg::cholesky::{
    SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{Argsort, Pair, SparseColMat, SymbolicSparseColMat};
use rayon::prelude::*;

use super::blocks::{BlockMatrix, CoarseFactor};
use super::constraints::{Constraints, Role};
use super::energy::quadrature;
use super::iteration::Ask;
use super::local_global::Layout;
use super::multilevel::{Hierarchy, Nodes};
use super::positions::Positions;
use super::{Method, SolveParams, auto, schwarz};
use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::rigid::{Dim, MAX_DOF, Motion, Rigid, Vect};
use crate::said::{Opt, Said};
use std::sync::atomic::{AtomicUsize, Ordering};

mod buffers;
mod paths;
mod terms;

use buffers::Buffers;
pub(super) use paths::first;
use terms::{accumulate_curvature, accumulate_diag, positive_part};

/// Degrees of freedom of a cell and where they start in the global vector.
#[derive(Debug, Clone, Copy)]
struct Slot {
    offset: usize,
    len: usize,
}

/// The sparse system of one cell topology.
pub(crate) struct System<const D: usize> {
    slots: Vec<Slot>,
    /// Pairs with at least one side having freedom.
    pairs: Vec<u32>,
    /// Cells with freedom.
    free_cells: Vec<u32>,
    /// Targets of each free cell: ranges into `target_order`.
    target_order: Vec<u32>,
    target_range: Vec<(u32, u32)>,
    n: usize,
    symbolic: Option<(Argsort<u32>, SymbolicCholesky<u32>)>,
    /// What each iteration writes, kept between iterations.
    buffers: Buffers,
    /// Solve by the multilevel iteration instead of the sparse factorization.
    multilevel: Option<Multilevel>,
    /// The position-only system, for variable projection and local-global iterations.
    positions: Positions,
    /// The local-global iterations' constant parts, made when they are first taken.
    layout: std::sync::OnceLock<Layout<D>>,
    /// Whether this system takes local-global iterations instead of Gauss-Newton steps.
    local_global: bool,
    /// The budget and advice Gauss-Newton's system is to be set up with, where
    /// [`Method::Auto`] took local-global iterations first.
    deferred: Option<(Budget, Said)>,
}

/// Where one Gauss-Newton step's time went, in seconds (damping retries included).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepCost {
    /// The pairs' and targets' blocks, the gradient and the curvature, and the matrix made of
    /// them.
    pub assembly: f64,
    /// The numeric Cholesky factorization, or the multilevel hierarchy's construction (its
    /// prolongations, Galerkin products, smoothers and coarsest factor) or refresh.
    pub setup: f64,
    /// The triangular solves, or the preconditioned conjugate gradients.
    pub linear: f64,
    /// Whether the step kept Newton's exact curvature (it was asked for and left the matrix
    /// positive definite); else it was a Gauss-Newton step.
    pub newton: bool,
}

/// The multilevel path's view of the unknowns: node `k` is the free cell `free_cells[k]`; the
/// pairs of each node (`2 · pair slot + side`, over `pair_start`), and the pairs joining two
/// nodes, with their nodes.
struct Multilevel {
    pair_start: Vec<u32>,
    pair_incident: Vec<u32>,
    edges: Vec<[u32; 2]>,
    edge_pairs: Vec<u32>,
    /// Conjugate-gradient iterations of the last solve and levels of its hierarchy.
    iterations: AtomicUsize,
    levels: AtomicUsize,
    /// The last hierarchy and the iterations of its first solve.
    kept: std::sync::Mutex<Option<(Hierarchy, usize)>>,
    /// The coarsest analysis of a hierarchy dropped for its age, for the next one.
    analysis: std::sync::Mutex<Option<CoarseFactor>>,
    /// The last solved system's gradient norm ([`forcing`](super::multilevel::forcing)).
    forcing: std::sync::Mutex<Option<f64>>,
    /// The last step's matrix, whose storage the next step of the same minimization is
    /// assembled into (288 bytes a block: 2.3 GB at the 1.14M cells of BENCHMARKS.md §4,
    /// which the kernel would otherwise map and zero anew every step).
    spare: std::sync::Mutex<Option<BlockMatrix>>,
}

/// Entries of a diagonal block's lower triangle, and of a full block, for `DOF` unknowns.
const fn tri(n: usize) -> usize {
    n * (n + 1) / 2
}

impl<const D: usize> System<D>
where
    Dim<D>: Rigid<D>,
{
    const DOF: usize = <Dim<D> as Rigid<D>>::DOF;
    const CELL_SLOT: usize = tri(Self::DOF);
    const PAIR_SLOT: usize = 2 * tri(Self::DOF) + Self::DOF * Self::DOF;

    /// The layout and symbolic factorization for `complex` under `constraints`, solved as
    /// `params` say (`method`, or local-global by `subdomains`) within the memory `budget`.
    pub fn new(
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        params: &SolveParams,
        budget: Budget,
        advice: &Said,
    ) -> Result<Self> {
        let (method, positions) = if params.subdomains > 0 {
            let workers = params.workers.map(schwarz::registered).transpose()?;
            let positions = Positions::by_subdomains(
                complex,
                constraints,
                params.subdomains,
                workers.as_deref(),
            )?;
            (Method::LocalGlobal, positions)
        } else {
            (params.method, Positions::new(complex, constraints))
        };
        let mut n = 0;
        let slots: Vec<Slot> = constraints
            .roles
            .iter()
            .map(|r| {
                let len = match r {
                    Role::Free => Self::DOF,
                    Role::Pin(_) => <Dim<D> as Rigid<D>>::ROT,
                    _ => 0,
                };
                let s = Slot { offset: n, len };
                n += len;
                s
            })
            .collect();
        let free_cells: Vec<u32> = (0..slots.len() as u32)
            .filter(|&c| slots[c as usize].len > 0)
            .collect();
        let pairs: Vec<u32> = (0..complex.pairs.len() as u32)
            .filter(|&p| {
                let pr = &complex.pairs[p as usize];
                slots[pr.i as usize].len + slots[pr.j as usize].len > 0
            })
            .collect();
        let mut by_cell: Vec<Vec<u32>> = vec![Vec::new(); slots.len()];
        for (t, target) in constraints.targets.iter().enumerate() {
            by_cell[target.cell as usize].push(t as u32);
        }
        let mut target_order = Vec::new();
        let target_range = free_cells
            .iter()
            .map(|&c| {
                let start = target_order.len() as u32;
                target_order.extend(&by_cell[c as usize]);
                (start, target_order.len() as u32)
            })
            .collect();
        let mut system = Self {
            slots,
            pairs,
            free_cells,
            target_order,
            target_range,
            n,
            symbolic: None,
            buffers: Buffers::default(),
            multilevel: None,
            positions,
            layout: std::sync::OnceLock::new(),
            local_global: false,
            deferred: None,
        };
        if n > 0 {
            match method {
                // Without a factored position Laplacian (a free part nothing holds in place)
                // the global step is not defined: Gauss-Newton, factored.
                Method::LocalGlobal if system.positions.is_factored() => {
                    system.local_global = true;
                }
                Method::LocalGlobal => {
                    system.set_up_direct(complex, budget, advice, None)?;
                }
                Method::Multilevel => system.set_up_multilevel(complex),
                Method::Direct => {
                    system.set_up_direct(complex, budget, advice, None)?;
                }
                // Cells of one size (a scan, a shell) past `MULTILEVEL_FROM` free cells: the
                // multilevel path (BENCHMARKS.md, "Which solver `auto` takes": faster from
                // there, in half the memory). Otherwise the factorization where it fits, else
                // the multilevel path (memory linear in the cells).
                // Local-global iterations first, Gauss-Newton's system set up where their
                // rate says it finishes sooner (`switch_to_gauss_newton`).
                Method::Auto if system.positions.is_factored() => {
                    system.local_global = true;
                    system.deferred = Some((budget, advice.clone()));
                }
                Method::Auto => system.set_up_auto(complex, budget, advice)?,
            }
        }
        Ok(system)
    }

    /// The multilevel path's layout and value array.
    fn set_up_multilevel(&mut self, complex: &CellComplex<D>) {
        self.multilevel = Some(self.multilevel_layout(complex));
        self.buffers.values =
            vec![0.0; self.free_cells.len() * Self::CELL_SLOT + self.pairs.len() * Self::PAIR_SLOT];
    }

    /// The direct path's pattern, symbolic factorization and storage, each checked against the
    /// memory budget before it is allocated. With `most_fill`, a factor of more entries per
    /// unknown is not allocated and the answer is `false` (the multilevel path is the faster).
    fn set_up_direct(
        &mut self,
        complex: &CellComplex<D>,
        budget: Budget,
        advice: &Said,
        most_fill: Option<usize>,
    ) -> Result<bool> {
        let n = self.n;
        let limit = budget.limit();
        let entries = self.free_cells.len() * Self::CELL_SLOT + self.pairs.len() * Self::PAIR_SLOT;
        // The pattern's (row, column) pairs, faer's sorted copy and argsort, the values.
        crate::memory::check(
            format!("assembling the solver's system of {} cells", complex.len()),
            entries as f64 * 40.0,
            limit,
            advice,
        )?;
        // faer's argsort keeps a flag in the top bit of its 32-bit indices.
        if entries >= 1 << 31 {
            let what = format!("{entries} entries are too many for the direct solver's");
            return Err(past_indices(what, advice));
        }
        if most_fill.is_some_and(|most| {
            auto::cell_fill(complex, &self.free_cells, &self.pairs, Self::DOF) > most
        }) {
            return Ok(false);
        }
        let indices = self.pattern(complex);
        let (sym, argsort) = SymbolicSparseColMat::try_new_from_indices(n, n, &indices)
            .map_err(|e| Error::solver(format!("sparsity pattern: {e:?}")))?;
        let llt = crate::with_faer(|| {
            factorize_symbolic_cholesky(
                sym.as_ref(),
                Side::Lower,
                SymmetricOrdering::Amd,
                Default::default(),
            )
        })
        .map_err(|e| match e {
            faer::sparse::FaerError::IndexOverflow => past_indices(
                format!(
                    "the Cholesky factor of {} cells has more entries than the direct solver's",
                    complex.len()
                ),
                advice,
            ),
            e => Error::solver(format!("symbolic Cholesky: {e:?}")),
        })?;
        let par = faer::get_global_parallelism();
        let scratch = llt
            .factorize_numeric_llt_scratch::<f64>(par, Default::default())
            .or(llt.solve_in_place_scratch::<f64>(1, par));
        // The symbolic analysis knows the factor's size exactly: check it before the
        // numeric factor and its scratch are allocated.
        crate::memory::check(
            format!("factoring the solver's system of {} cells", complex.len()),
            (llt.len_val() * 8 + scratch.size_bytes() + indices.len() * 32) as f64,
            limit,
            advice,
        )?;
        self.buffers = Buffers {
            values: vec![0.0; indices.len()],
            factor: vec![0.0; llt.len_val()],
            scratch: MemBuffer::new(scratch),
            pattern: Some(sym),
            ..Buffers::default()
        };
        self.symbolic = Some((argsort, llt));
        Ok(true)
    }

    /// Sets the free cells' positions to their optimum for the current rotations.
    pub fn project_positions(
        &self,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        motions: &mut [Motion<D>],
        targets_to: &[Vect<D>],
    ) -> Result<()> {
        self.positions
            .project(complex, constraints, motions, targets_to)
    }

    /// The nonzeros of the direct path's Cholesky factor (its symbolic analysis knows them):
    /// what a numeric factorization costs grows with them. `None` on the multilevel path.
    pub fn factor_len(&self) -> Option<usize> {
        self.symbolic.as_ref().map(|(_, llt)| llt.len_val())
    }

    /// Number of unknowns.
    pub fn unknowns(&self) -> usize {
        self.n
    }

    /// The multilevel path's last conjugate-gradient iterations and levels, if it is taken.
    pub fn multilevel_stats(&self) -> Option<(usize, usize)> {
        self.multilevel.as_ref().map(|m| {
            (
                m.iterations.load(Ordering::Relaxed),
                m.levels.load(Ordering::Relaxed),
            )
        })
    }

    /// The multilevel path's incidence of pairs and nodes.
    fn multilevel_layout(&self, complex: &CellComplex<D>) -> Multilevel {
        let mut node = vec![u32::MAX; self.slots.len()];
        for (k, &c) in self.free_cells.iter().enumerate() {
            node[c as usize] = k as u32;
        }
        let n = self.free_cells.len();
        let mut pair_start = vec![0u32; n + 1];
        let mut edges = Vec::new();
        let mut edge_pairs = Vec::new();
        for (k, &p) in self.pairs.iter().enumerate() {
            let pr = &complex.pairs[p as usize];
            let (a, b) = (node[pr.i as usize], node[pr.j as usize]);
            for x in [a, b] {
                if x != u32::MAX {
                    pair_start[x as usize + 1] += 1;
                }
            }
            if a != u32::MAX && b != u32::MAX {
                edges.push([a, b]);
                edge_pairs.push(k as u32);
            }
        }
        for a in 0..n {
            pair_start[a + 1] += pair_start[a];
        }
        let mut fill = pair_start.clone();
        let mut pair_incident = vec![0u32; pair_start[n] as usize];
        for (k, &p) in self.pairs.iter().enumerate() {
            let pr = &complex.pairs[p as usize];
            for (side, c) in [pr.i, pr.j].into_iter().enumerate() {
                let x = node[c as usize];
                if x != u32::MAX {
                    pair_incident[fill[x as usize] as usize] = 2 * k as u32 + side as u32;
                    fill[x as usize] += 1;
                }
            }
        }
        Multilevel {
            pair_start,
            pair_incident,
            edges,
            edge_pairs,
            iterations: AtomicUsize::new(0),
            levels: AtomicUsize::new(0),
            kept: std::sync::Mutex::new(None),
            analysis: std::sync::Mutex::new(None),
            forcing: std::sync::Mutex::new(None),
            spare: std::sync::Mutex::new(None),
        }
    }

    /// The damped normal equations as blocks, and their multilevel solve (`None`: not positive
    /// definite at this damping).
    #[allow(clippy::too_many_arguments)]
    fn multilevel_step(
        &self,
        ml: &Multilevel,
        values: &[f64],
        grad: &[f64],
        diag: &[f64],
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        motions: &[Motion<D>],
        mu: f64,
        floor: f64,
        ask: Ask,
        cost: &mut StepCost,
    ) -> Option<Vec<f64>> {
        let assembling = std::time::Instant::now();
        let dof = Self::DOF;
        let bb = dof * dof;
        let (cell_vals, pair_vals) = values.split_at(self.free_cells.len() * Self::CELL_SLOT);
        let unpack = |out: &mut [f64], tri_vals: &[f64]| {
            let mut k = 0;
            for x in 0..dof {
                for y in 0..=x {
                    out[x * dof + y] += tri_vals[k];
                    if x != y {
                        out[y * dof + x] += tri_vals[k];
                    }
                    k += 1;
                }
            }
        };
        let n = self.free_cells.len();
        // A spare of another shape is dropped (by `filter`) before a new matrix is allocated.
        let spare = (ml.spare.lock().unwrap_or_else(|e| e.into_inner()).take())
            .filter(|m| m.n == n && m.edges.len() == ml.edges.len());
        let (mut blocks, mut edge_blocks) = match spare {
            Some(m) => (m.diag, m.blocks),
            None => (vec![0.0; n * bb], vec![0.0; ml.edges.len() * bb]),
        };
        blocks.par_chunks_mut(bb).enumerate().for_each(|(k, out)| {
            out.fill(0.0);
            unpack(
                out,
                &cell_vals[k * Self::CELL_SLOT..(k + 1) * Self::CELL_SLOT],
            );
            let (lo, hi) = (ml.pair_start[k] as usize, ml.pair_start[k + 1] as usize);
            for &e in &ml.pair_incident[lo..hi] {
                let (p, side) = ((e >> 1) as usize, (e & 1) as usize);
                let at = p * Self::PAIR_SLOT + side * Self::CELL_SLOT;
                unpack(out, &pair_vals[at..at + Self::CELL_SLOT]);
            }
            let s = self.slots[self.free_cells[k] as usize];
            for a in 0..dof {
                out[a * dof + a] += if a < s.len {
                    mu * diag[s.offset + a] + floor
                } else {
                    1.0
                };
            }
        });
        edge_blocks
            .par_chunks_mut(bb)
            .zip(&ml.edge_pairs)
            .for_each(|(out, &p)| {
                let at = p as usize * Self::PAIR_SLOT + 2 * Self::CELL_SLOT;
                out.copy_from_slice(&pair_vals[at..at + bb]);
            });
        let matrix = BlockMatrix::new(dof, n, blocks, ml.edges.clone(), edge_blocks);
        let nodes = Nodes {
            rest: self
                .free_cells
                .iter()
                .map(|&c| complex.cells[c as usize].center)
                .collect(),
            deformed: self
                .free_cells
                .iter()
                .map(|&c| motions[c as usize].pos)
                .collect(),
            pinned: self
                .free_cells
                .iter()
                .map(|&c| matches!(constraints.roles[c as usize], Role::Pin(_)))
                .collect(),
        };
        cost.assembly += assembling.elapsed().as_secs_f64();
        let setting_up = std::time::Instant::now();
        let kept = ml.kept.lock().unwrap_or_else(|e| e.into_inner()).take();
        let (hierarchy, first) = match kept {
            Some((mut h, first)) if ask.settled => {
                h.refresh(matrix);
                (h, Some(first))
            }
            kept => {
                let size = complex.grid.finest_size();
                let aged = ml.analysis.lock().unwrap_or_else(|e| e.into_inner()).take();
                let reuse = kept.and_then(|(h, _)| h.into_coarsest()).or(aged);
                (
                    Hierarchy::new::<D>(matrix, nodes, size, super::multilevel::LIMITS, reuse),
                    None,
                )
            }
        };
        let mut rhs = vec![0.0; self.free_cells.len() * dof];
        for (k, &c) in self.free_cells.iter().enumerate() {
            let s = self.slots[c as usize];
            for a in 0..s.len {
                rhs[k * dof + a] = -grad[s.offset + a];
            }
        }
        cost.setup += setting_up.elapsed().as_secs_f64();
        let solving = std::time::Instant::now();
        let gradient = rhs.iter().map(|v| v * v).sum::<f64>().sqrt();
        let previous = *ml.forcing.lock().unwrap_or_else(|e| e.into_inner());
        let tolerance = super::multilevel::forcing(gradient, previous, ask.enough);
        let solved = hierarchy.solve_to(&rhs, tolerance);
        cost.linear += solving.elapsed().as_secs_f64();
        let super::multilevel::Solved {
            x,
            iterations,
            to_loosest,
        } = solved?;
        *ml.forcing.lock().unwrap_or_else(|e| e.into_inner()) = Some(gradient);
        ml.iterations.store(iterations, Ordering::Relaxed);
        ml.levels.store(hierarchy.depth(), Ordering::Relaxed);
        // Kept for the next step unless it has aged: three times the iterations it first took
        // to the residual every solve reaches ([`LOOSEST`](super::multilevel::LOOSEST)), plus
        // two.
        let first = first.unwrap_or(to_loosest);
        let mut hierarchy = hierarchy;
        *ml.spare.lock().unwrap_or_else(|e| e.into_inner()) = hierarchy.shed_finest();
        if to_loosest <= 3 * first + 2 {
            *ml.kept.lock().unwrap_or_else(|e| e.into_inner()) = Some((hierarchy, first));
        } else {
            *ml.analysis.lock().unwrap_or_else(|e| e.into_inner()) = hierarchy.into_coarsest();
        }
        let mut step = vec![0.0; self.n];
        for (k, &c) in self.free_cells.iter().enumerate() {
            let s = self.slots[c as usize];
            step[s.offset..s.offset + s.len].copy_from_slice(&x[k * dof..k * dof + s.len]);
        }
        Some(step)
    }

    /// Frees what an iteration keeps only for the next one: the pairs' terms and the finest
    /// multilevel matrix's storage (the values and the kept hierarchy stay).
    pub fn release_spare(&mut self) {
        self.buffers.pair_grad = Vec::new();
        self.buffers.pair_curv = Vec::new();
        if let Some(ml) = &self.multilevel {
            *ml.spare.lock().unwrap_or_else(|e| e.into_inner()) = None;
        }
    }

    /// The (row, column) of every value slot, lower triangle; unused slots point at (0, 0) and
    /// always carry 0.
    fn pattern(&self, complex: &CellComplex<D>) -> Vec<Pair<u32, u32>> {
        let mut idx = Vec::with_capacity(
            self.free_cells.len() * Self::CELL_SLOT + self.pairs.len() * Self::PAIR_SLOT,
        );
        let dummy = Pair { row: 0, col: 0 };
        let diag = |idx: &mut Vec<Pair<u32, u32>>, s: Slot| {
            for a in 0..Self::DOF {
                for b in 0..=a {
                    idx.push(if a < s.len {
                        Pair {
                            row: (s.offset + a) as u32,
                            col: (s.offset + b) as u32,
                        }
                    } else {
                        dummy
                    });
                }
            }
        };
        for &c in &self.free_cells {
            diag(&mut idx, self.slots[c as usize]);
        }
        for &p in &self.pairs {
            let pr = &complex.pairs[p as usize];
            let (si, sj) = (self.slots[pr.i as usize], self.slots[pr.j as usize]);
            diag(&mut idx, si);
            diag(&mut idx, sj);
            for a in 0..Self::DOF {
                for b in 0..Self::DOF {
                    idx.push(if a < si.len && b < sj.len {
                        let (r, c) = (si.offset + a, sj.offset + b);
                        Pair {
                            row: r.max(c) as u32,
                            col: r.min(c) as u32,
                        }
                    } else {
                        dummy
                    });
                }
            }
        }
        idx
    }

    /// The Jacobian columns of `T_i(q)` for cell `c` (`len` of them), `T_i(q)` itself, and the
    /// lever `R_i (q − z_i)` of its rotation (`z_i` its rotation center: the rest center of a
    /// free cell, the point of a pinned one; `None` for a cell that does not turn).
    #[inline]
    fn jacobian(
        &self,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        motions: &[Motion<D>],
        c: usize,
        q: &Vect<D>,
    ) -> ([Vect<D>; MAX_DOF], Vect<D>, Option<Vect<D>>) {
        let cell = &complex.cells[c];
        let m = &motions[c];
        let value = m.apply(&cell.center, q);
        let mut cols = [Vect::<D>::zeros(); MAX_DOF];
        let rot = <Dim<D> as Rigid<D>>::ROT;
        let (center, first) = match constraints.roles[c] {
            Role::Free => {
                for a in 0..D {
                    cols[a][a] = 1.0;
                }
                (cell.center, D)
            }
            Role::Pin(k) => (constraints.pins[k as usize].point, 0),
            _ => return (cols, value, None),
        };
        let arm = m.rot * (q - center);
        let w = <Dim<D> as Rigid<D>>::cross_jacobian(&arm);
        cols[first..first + rot].copy_from_slice(&w[..rot]);
        (cols, value, Some(arm))
    }

    /// Adds `sign ·` each free cell's rotational curvature block (`curvature[cell]`, the lower
    /// triangle; with `positive`, its positive semidefinite part) to the cell's own rotation
    /// block.
    fn add_curvature(
        &self,
        cell_vals: &mut [f64],
        curvature: &[[f64; 6]],
        positive: bool,
        sign: f64,
    ) {
        let rot = <Dim<D> as Rigid<D>>::ROT;
        for (k, &c) in self.free_cells.iter().enumerate() {
            let s = self.slots[c as usize];
            let first = s.len - rot;
            let vals = &mut cell_vals[k * Self::CELL_SLOT..(k + 1) * Self::CELL_SLOT];
            let m = &curvature[c as usize];
            let m = if positive { positive_part(m, rot) } else { *m };
            for x in 0..rot {
                for y in 0..=x {
                    vals[tri(first + x) + first + y] += sign * m[tri(x) + y];
                }
            }
        }
    }

    /// Assembles and solves the damped normal equations at `motions`; returns the step `δ`
    /// (one entry per unknown), or an error when even strong damping cannot make the system
    /// positive definite.
    pub fn step(
        &mut self,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        motions: &[Motion<D>],
        targets_to: &[Vect<D>],
        newton: bool,
        ask: Ask,
    ) -> Result<(Vec<f64>, StepCost)> {
        let cell_part = self.free_cells.len() * Self::CELL_SLOT;
        let mut cost = StepCost::default();
        let mut buffers = std::mem::take(&mut self.buffers);
        let result = self.step_into(
            &mut buffers,
            cell_part,
            complex,
            constraints,
            motions,
            targets_to,
            newton,
            ask,
            &mut cost,
        );
        self.buffers = buffers;
        Ok((result?, cost))
    }

    #[allow(clippy::too_many_arguments)]
    fn step_into(
        &self,
        buffers: &mut Buffers,
        cell_part: usize,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        motions: &[Motion<D>],
        targets_to: &[Vect<D>],
        newton: bool,
        ask: Ask,
        cost: &mut StepCost,
    ) -> Result<Vec<f64>> {
        let started = std::time::Instant::now();
        let dof = Self::DOF;
        let Buffers {
            values,
            factor,
            scratch,
            pattern,
            pair_grad,
            pair_curv,
        } = buffers;
        let (cell_vals, pair_vals) = values.split_at_mut(cell_part);
        // Every pair's chunk is zeroed below before it is summed into.
        pair_grad.resize(self.pairs.len() * 2 * dof, 0.0);
        pair_curv.resize(self.pairs.len() * 2, [0.0; 6]);
        let this = self;
        pair_vals
            .par_chunks_exact_mut(Self::PAIR_SLOT)
            .zip(pair_grad.par_chunks_exact_mut(2 * dof))
            .zip(pair_curv.par_chunks_exact_mut(2))
            .zip(this.pairs.par_iter())
            .for_each(|(((vals, grad), curv), &p)| {
                vals.fill(0.0);
                grad.fill(0.0);
                curv.fill([0.0; 6]);
                let pr = &complex.pairs[p as usize];
                let (i, j) = (pr.i as usize, pr.j as usize);
                let (ni, nj) = (this.slots[i].len, this.slots[j].len);
                let s = (constraints.stiffness[i] * constraints.stiffness[j]).sqrt() * pr.weight;
                let (ci, cj) = (&complex.cells[i], &complex.cells[j]);
                let (hii, rest) = vals.split_at_mut(Self::CELL_SLOT);
                let (hjj, hij) = rest.split_at_mut(Self::CELL_SLOT);
                for (q, w) in quadrature(ci, cj) {
                    let a = s * w;
                    let (ji, ti, arm_i) = this.jacobian(complex, constraints, motions, i, &q);
                    let (jj, tj, arm_j) = this.jacobian(complex, constraints, motions, j, &q);
                    let r = ti - tj;
                    if let Some(arm) = arm_i {
                        accumulate_curvature(&mut curv[0], &r, &arm, a);
                    }
                    if let Some(arm) = arm_j {
                        accumulate_curvature(&mut curv[1], &r, &arm, -a);
                    }
                    accumulate_diag(hii, &ji, ni, a);
                    accumulate_diag(hjj, &jj, nj, a);
                    for x in 0..ni {
                        grad[x] += a * ji[x].dot(&r);
                        for y in 0..nj {
                            hij[x * dof + y] -= a * ji[x].dot(&jj[y]);
                        }
                    }
                    for y in 0..nj {
                        grad[dof + y] -= a * jj[y].dot(&r);
                    }
                }
            });

        let mut grad = vec![0.0f64; self.n];
        let mut diag = vec![0.0f64; self.n];
        let mut curvature = vec![[0.0f64; 6]; self.slots.len()];
        for (k, &p) in self.pairs.iter().enumerate() {
            let pr = &complex.pairs[p as usize];
            let vals = &pair_vals[k * Self::PAIR_SLOT..(k + 1) * Self::PAIR_SLOT];
            for (side, cell, base) in [(0, pr.i, 0), (1, pr.j, Self::CELL_SLOT)] {
                let s = self.slots[cell as usize];
                if s.len > 0 {
                    let c = &mut curvature[cell as usize];
                    c.iter_mut()
                        .zip(&pair_curv[2 * k + side])
                        .for_each(|(c, v)| *c += v);
                }
                for a in 0..s.len {
                    grad[s.offset + a] += pair_grad[k * 2 * dof + side * dof + a];
                    diag[s.offset + a] += vals[base + tri(a + 1) - 1];
                }
            }
        }
        // Soft targets and the damping live in the free cells' own slots.
        for (k, &c) in self.free_cells.iter().enumerate() {
            let vals = &mut cell_vals[k * Self::CELL_SLOT..(k + 1) * Self::CELL_SLOT];
            vals.fill(0.0);
            let s = self.slots[c as usize];
            let (lo, hi) = self.target_range[k];
            for &t in &self.target_order[lo as usize..hi as usize] {
                let target = &constraints.targets[t as usize];
                let (mut jc, value, arm) =
                    self.jacobian(complex, constraints, motions, c as usize, &target.from);
                // The residual is `M r` with `M = diag(mask)` (a horizontal control point
                // barely holds its height): its Jacobian is `M J`, and the curvature term
                // `(M r) · M ∂²x` takes `M² r`.
                let r = (value - targets_to[t as usize]).component_mul(&target.mask);
                jc.iter_mut()
                    .for_each(|j| j.component_mul_assign(&target.mask));
                accumulate_diag(vals, &jc, s.len, target.weight);
                if let Some(arm) = arm {
                    let r2 = r.component_mul(&target.mask);
                    accumulate_curvature(&mut curvature[c as usize], &r2, &arm, target.weight);
                }
                for a in 0..s.len {
                    grad[s.offset + a] += target.weight * jc[a].dot(&r);
                    diag[s.offset + a] += target.weight * jc[a].norm_squared();
                }
            }
        }
        // The direct path falls back to the curvature's positive part where the exact one
        // makes the matrix indefinite; the multilevel path falls back to Gauss-Newton (with the
        // positive part its conjugate gradients took 7 iterations instead of 5 on the 1.25 m
        // corridor, and twice as long; with the exact curvature, 4 instead of 5 at 2.5 m).
        let mut newton = newton;
        let cells = &mut values[..cell_part];
        match (newton, self.multilevel.is_some()) {
            (true, _) => self.add_curvature(cells, &curvature, false, 1.0),
            (false, false) => self.add_curvature(cells, &curvature, true, 1.0),
            (false, true) => {}
        }
        let scale = diag
            .iter()
            .fold(0.0f64, |m, &d| m.max(d))
            .max(f64::MIN_POSITIVE);
        let scale_floor = 1e-12 * scale;
        cost.assembly += started.elapsed().as_secs_f64();
        if let Some(ml) = &self.multilevel {
            let mut mu = 0.0;
            for _ in 0..12 {
                if let Some(step) = self.multilevel_step(
                    ml,
                    values,
                    &grad,
                    &diag,
                    complex,
                    constraints,
                    motions,
                    mu,
                    scale_floor,
                    Ask {
                        settled: ask.settled && mu == 0.0,
                        ..ask
                    },
                    cost,
                ) {
                    cost.newton = newton;
                    return Ok(step);
                }
                if newton {
                    self.add_curvature(&mut values[..cell_part], &curvature, false, -1.0);
                    newton = false;
                    continue;
                }
                mu = (mu * 100.0).max(1e-6);
            }
            return Err(Error::solver(
                "the Gauss-Newton system stayed indefinite under damping",
            ));
        }
        let (argsort, llt) = self.symbolic.as_ref().expect("a system with unknowns");
        let mut mu = 0.0;
        for _ in 0..13 {
            let assembling = std::time::Instant::now();
            // Levenberg–Marquardt on the diagonal, plus a floor for singular directions.
            self.damp(&mut values[..cell_part], &diag, mu, 1e-12 * scale);
            let sym = pattern.take().ok_or_else(|| {
                Error::solver("the system's pattern was lost to a failed allocation")
            })?;
            let matrix = SparseColMat::new_from_argsort(sym, argsort, values)
                .map_err(|e| Error::solver(format!("assembly: {e:?}")))?;
            let rhs = Mat::<f64>::from_fn(self.n, 1, |r, _| -grad[r]);
            cost.assembly += assembling.elapsed().as_secs_f64();
            let solved = crate::with_faer(|| {
                let par = faer::get_global_parallelism();
                let stack = MemStack::new(scratch);
                let factoring = std::time::Instant::now();
                let l = llt.factorize_numeric_llt(
                    factor,
                    matrix.as_ref(),
                    Side::Lower,
                    Default::default(),
                    par,
                    stack,
                    Default::default(),
                );
                cost.setup += factoring.elapsed().as_secs_f64();
                let l = l?;
                let solving = std::time::Instant::now();
                let mut x = rhs;
                l.solve_in_place_with_conj(faer::Conj::No, x.as_mut(), par, stack);
                cost.linear += solving.elapsed().as_secs_f64();
                Ok::<_, faer::sparse::linalg::LltError>(x)
            });
            *pattern = Some(matrix.into_parts().0);
            if let Ok(x) = solved {
                let step: Vec<f64> = (0..self.n).map(|r| x[(r, 0)]).collect();
                if step.iter().all(|v| v.is_finite()) {
                    cost.newton = newton;
                    return Ok(step);
                }
            }
            // Undo this round's damping before trying a stronger one; an indefinite Newton
            // system first falls back to the curvature's positive part, undamped.
            self.damp(&mut values[..cell_part], &diag, -mu, -1e-12 * scale);
            if newton {
                self.add_curvature(&mut values[..cell_part], &curvature, false, -1.0);
                self.add_curvature(&mut values[..cell_part], &curvature, true, 1.0);
                newton = false;
                continue;
            }
            mu = (mu * 100.0).max(1e-6);
        }
        Err(Error::solver(
            "the Gauss-Newton system stayed indefinite under damping",
        ))
    }

    /// Adds `mu · diag + floor` to the diagonal of every free cell's own block.
    fn damp(&self, cell_vals: &mut [f64], diag: &[f64], mu: f64, floor: f64) {
        for (k, &c) in self.free_cells.iter().enumerate() {
            let s = self.slots[c as usize];
            let vals = &mut cell_vals[k * Self::CELL_SLOT..(k + 1) * Self::CELL_SLOT];
            for a in 0..s.len {
                vals[tri(a + 1) - 1] += mu * diag[s.offset + a] + floor;
            }
        }
    }

    /// `motions` advanced by `t·δ`: `p += t v`, `R ← polar(I + [t ω]×) R` (pinned cells keep
    /// their pinned point in place at `pin_to`).
    pub fn advance(
        &self,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        motions: &[Motion<D>],
        pins_to: &[Vect<D>],
        delta: &[f64],
        t: f64,
    ) -> Vec<Motion<D>> {
        let rot = <Dim<D> as Rigid<D>>::ROT;
        motions
            .par_iter()
            .enumerate()
            .map(|(c, m)| {
                let s = self.slots[c];
                let d = &delta[s.offset..s.offset + s.len];
                match constraints.roles[c] {
                    Role::Free => {
                        let w: [f64; 3] =
                            std::array::from_fn(|r| if r < rot { t * d[D + r] } else { 0.0 });
                        Motion {
                            rot: <Dim<D> as Rigid<D>>::step_rotation(&w) * m.rot,
                            pos: m.pos + Vect::<D>::from_fn(|a, _| t * d[a]),
                        }
                    }
                    Role::Pin(k) => {
                        let w: [f64; 3] =
                            std::array::from_fn(|r| if r < rot { t * d[r] } else { 0.0 });
                        let r = <Dim<D> as Rigid<D>>::step_rotation(&w) * m.rot;
                        let pin = &constraints.pins[k as usize];
                        Motion {
                            rot: r,
                            pos: r * (complex.cells[c].center - pin.point) + pins_to[k as usize],
                        }
                    }
                    _ => *m,
                }
            })
            .collect()
    }
}

/// `what` (`… entries are too many for the direct solver's`) past the 32-bit indices, with
/// `advice` and the multilevel solver as the ways out.
fn past_indices(what: String, advice: &Said) -> Error {
    Error::solver(
        Said::from(format!("{what} 32-bit indices: "))
            .then(advice.clone())
            .aside(Said::from(", or ").set(Opt::Solver, "multilevel")),
    )
}
