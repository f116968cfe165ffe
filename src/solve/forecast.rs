//! What a solve will take, counted on the cells and their roles before anything is assembled
//! ([`forecast`]; the prices are `crate::estimate`'s): the linear solver `--solver auto`
//! takes for them, the memory at the solve's peak and its seconds.
//!
//! The counts are those of the structures the solver builds: the direct path's assembled
//! entries and its Cholesky factor (the symbolic analysis of the free cells' graph, a node a
//! cell: its entries within 6 % of the system's own analysis on the bar at 0.05), the position
//! system's factor (the same analysis), and the multilevel hierarchy's levels, counted on the
//! graph by `multilevel::shape`, with its coarsest level analysed the same way.

use super::auto::{self, Fill, graph_fill};
use super::constraints::{Constraints, Role};
use super::merge::coarsen_stage;
use super::multilevel::{self, COARSEST, LIMITS};
use super::{Method, SolveParams, cells_advice, check_params, coarse, load_steps};
use crate::cells::CellComplex;
use crate::error::Result;
use crate::estimate::*;
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::{Dim, Rigid};

/// The estimate of solving `complex` under `constraints` with `params` within `budget`: the
/// stages coarse to fine as `coarse::coarse_to_fine` makes them (`coarsen_stage`), each by the path
/// `params.method` takes for it ([`Method::Auto`]: the direct path where its factor fits the
/// budget, as `System::new` decides). Counted, not checked: [`Estimate::check`] refuses it.
pub fn forecast<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    params: &SolveParams,
    budget: Budget,
) -> Result<Estimate>
where
    Dim<D>: Rigid<D>,
{
    forecast_stages(complex, constraints, params, budget).map(|(estimate, _)| estimate)
}

/// Whether Gauss-Newton's system fits the budget ([`newton_fits`]), by the cells of each
/// stage a [`forecast()`] counted: what a solve looks up where `auto` would switch to
/// Gauss-Newton, instead of counting the stage again (on the hilly strip at 1.25 m, 1.3 s of
/// graph analyses for its 431,585 cells).
pub(crate) type StageFits = Vec<(usize, bool)>;

/// [`forecast()`], and the [`StageFits`] of its stages.
fn forecast_stages<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    params: &SolveParams,
    budget: Budget,
) -> Result<(Estimate, StageFits)>
where
    Dim<D>: Rigid<D>,
{
    let load_steps = load_steps(complex, constraints, params)? as f64;
    let fine = stage(complex, constraints, params, budget);
    let mut stages: Vec<(SolveCounts, Method)> = Vec::new();
    for k in (1..=coarse::levels(complex.len(), params)).rev() {
        let (parents, on_parents) = coarsen_stage(complex, constraints, k);
        let coarser = stages.last().map_or(0, |s| s.0.cells as usize);
        if parents.len() >= complex.len() || parents.len() <= coarser {
            continue;
        }
        stages.push(stage(&parents, &on_parents, params, budget));
    }
    // `stage` prices local-global iterations where `auto`'s Gauss-Newton system does not fit.
    let fits = stages
        .iter()
        .chain(std::iter::once(&fine))
        .map(|(counts, method)| (counts.cells as usize, *method != Method::LocalGlobal))
        .collect();
    let estimate = solve_estimate(&stages, &fine, load_steps, budget.limit());
    Ok((estimate, fits))
}

/// [`forecast()`] of what `solve` is about to solve, refused past `budget` (the cells'
/// parameters named) and handed to `observer`: what a solve does before its first stage.
/// With the [`StageFits`] it found.
pub(super) fn announce<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    params: &SolveParams,
    budget: Budget,
    observer: &dyn Observer,
) -> Result<(Estimate, StageFits)>
where
    Dim<D>: Rigid<D>,
{
    check_params(params)?;
    let (estimate, fits) = forecast_stages(complex, constraints, params, budget)?;
    estimate.check(budget, &cells_advice())?;
    observer.estimate(&estimate);
    Ok((estimate, fits))
}

/// Gauss-Newton iterations [`newton_seconds`] counts on: what a load step on warm motions
/// takes (BENCHMARKS.md: 4–6 on the tube, the bar and the vegetation strip).
const NEWTON_ITERATIONS: f64 = 4.0;

/// What Gauss-Newton would take to finish a load step on `complex` from motions near its
/// minimum, by the path [`Method::Auto`] takes (its symbolic analysis, a hierarchy's
/// construction and [`NEWTON_ITERATIONS`] iterations), in accelerated local-global iterations
/// on the same cells: what local-global iterations are measured against ([`Method::Auto`]).
/// Estimated from the counts, not timed, so that a solve is the same every run. Infinite where
/// that path does not fit `budget`: `auto` then keeps to local-global iterations.
pub(super) fn newton_in_local_global<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    budget: Budget,
) -> f64
where
    Dim<D>: Rigid<D>,
{
    let (counts, method) = newton_path(complex, constraints, Method::Auto, budget);
    if !counts.fit(method, budget) {
        return f64::INFINITY;
    }
    let (iteration, setup) = counts.iteration_seconds(method);
    let symbolic = match method {
        Method::Multilevel => 0.0,
        _ => SYMBOLIC_SECONDS_PER_ENTRY * counts.entries,
    };
    let local_global =
        LOCAL_GLOBAL_SHARE * ITERATION_SECONDS_PER_ENTRY * (counts.cells + counts.coupled);
    (NEWTON_ITERATIONS * iteration + setup + symbolic) / local_global
}

/// An accelerated local-global iteration's time, as a share of the pass over the cells and
/// pairs a Gauss-Newton iteration makes (`ITERATION_SECONDS_PER_ENTRY` each): measured 0.08–0.12
/// from 1k to 5.5k cells of the tube, the bar and the vegetation strip.
const LOCAL_GLOBAL_SHARE: f64 = 0.1;

/// The counts of one stage's solve and the path its memory and seconds are priced by:
/// `params.method`, or for [`Method::Auto`] Gauss-Newton's system ([`newton_path`]) where it
/// fits `budget` (`auto` starts with local-global iterations where something holds the cells,
/// and may switch to it where their rate says so: then it takes about that system's time, and
/// where it does not switch, less), else the local-global iterations it then keeps to
/// ([`newton_fits`]).
fn stage<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    params: &SolveParams,
    budget: Budget,
) -> (SolveCounts, Method)
where
    Dim<D>: Rigid<D>,
{
    // Subdomains solve by local-global iterations; their blocks' factors hold about what the
    // whole factor does.
    let asked = match params.subdomains > 0 {
        true => Method::LocalGlobal,
        false => params.method,
    };
    if asked == Method::LocalGlobal {
        return (counts(complex, constraints).0, asked);
    }
    let (counts, method) = newton_path(complex, constraints, asked, budget);
    if asked != Method::Auto || !held(constraints) {
        return (counts, method);
    }
    match counts.fit(method, budget) {
        true => (counts, method),
        false => (counts, Method::LocalGlobal),
    }
}

/// The counts of a stage's Gauss-Newton solve and the linear solver it takes: `asked`, or for
/// [`Method::Auto`] what `System::set_up_auto` decides (the multilevel path for many cells of
/// one size or a dense factor, else the direct path where it fits `budget`).
fn newton_path<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    asked: Method,
    budget: Budget,
) -> (SolveCounts, Method)
where
    Dim<D>: Rigid<D>,
{
    let (counts, uniform) = counts(complex, constraints);
    let limit = budget.limit() as f64;
    // `System::new`'s own tests, with the factor forecast: the assembled entries, then the
    // factor, its scratch and the pattern (32 bytes an entry) against the whole budget.
    let direct_fits = || {
        let factor = 8.0 * counts.factor.len + 13.0 * counts.factor.largest_update;
        counts.entries < (1u64 << 31) as f64
            && counts.entries * 40.0 <= limit
            && counts.factor.len < u32::MAX as f64
            && factor + 32.0 * counts.entries <= limit
    };
    let fill = counts.factor.nodes_len * counts.dof / counts.free.max(1.0);
    let free = counts.free as usize;
    let method = match asked {
        Method::Direct | Method::LocalGlobal => Method::Direct,
        Method::Multilevel => Method::Multilevel,
        Method::Auto if uniform && free > auto::MULTILEVEL_FROM => Method::Multilevel,
        Method::Auto if uniform && free > COARSEST && fill > auto::MULTILEVEL_FILL as f64 => {
            Method::Multilevel
        }
        Method::Auto if direct_fits() => Method::Direct,
        Method::Auto => Method::Multilevel,
    };
    match method {
        Method::Multilevel => (with_hierarchy(counts, complex, constraints), method),
        _ => (counts, Method::Direct),
    }
}

/// Whether Gauss-Newton's system on `complex`, set up as [`Method::Auto`] sets it up, fits
/// `budget` by this forecast: where it does not, `auto` stays with local-global iterations
/// instead of switching to it.
pub(super) fn newton_fits<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    budget: Budget,
) -> bool
where
    Dim<D>: Rigid<D>,
{
    let (counts, method) = newton_path(complex, constraints, Method::Auto, budget);
    counts.fit(method, budget)
}

/// Whether something holds the free cells in place (a fixed or handle cell, a pin or a
/// target), so that the position Laplacian local-global iterations solve is factored.
fn held<const D: usize>(constraints: &Constraints<D>) -> bool {
    !constraints.targets.is_empty()
        || constraints
            .roles
            .iter()
            .any(|r| !matches!(r, Role::Free | Role::Rest | Role::Carried(_)))
}

/// The counts of every path but the multilevel hierarchy's, and whether the cells are all of
/// one size.
fn counts<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
) -> (SolveCounts, bool)
where
    Dim<D>: Rigid<D>,
{
    let dof = <Dim<D> as Rigid<D>>::DOF;
    let tri = dof * (dof + 1) / 2;
    let has_unknowns = |c: u32| matches!(constraints.roles[c as usize], Role::Free | Role::Pin(_));
    let free_cells: Vec<u32> = (0..complex.len() as u32)
        .filter(|&c| has_unknowns(c))
        .collect();
    let pairs: Vec<u32> = (0..complex.pairs.len() as u32)
        .filter(|&p| {
            let pr = &complex.pairs[p as usize];
            has_unknowns(pr.i) || has_unknowns(pr.j)
        })
        .collect();
    let edges = auto::free_edges(complex, &free_cells, &pairs);
    // A graph faer cannot analyse (past its indices) has no direct path: an infinite factor.
    let factor = graph_fill(free_cells.len(), &edges, dof).unwrap_or(Fill {
        len: f64::INFINITY,
        flops: f64::INFINITY,
        ..Default::default()
    });
    let level = complex.cells.first().map(|c| c.key.level);
    let uniform = complex.cells.iter().all(|c| Some(c.key.level) == level);
    let entries = free_cells.len() * tri + pairs.len() * (2 * tri + dof * dof);
    let counts = SolveCounts {
        cells: complex.len() as f64,
        pairs: complex.pairs.len() as f64,
        free: free_cells.len() as f64,
        coupled: pairs.len() as f64,
        dof: dof as f64,
        entries: entries as f64,
        factor,
        fine_blocks: (free_cells.len() + edges.len()) as f64,
        ..Default::default()
    };
    (counts, uniform)
}

/// `counts` with the multilevel hierarchy's: its levels counted on the free cells' graph
/// (`multilevel::shape`) and its coarsest factor analysed.
fn with_hierarchy<const D: usize>(
    counts: SolveCounts,
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
) -> SolveCounts
where
    Dim<D>: Rigid<D>,
{
    let dof = <Dim<D> as Rigid<D>>::DOF;
    let tri = dof * (dof + 1) / 2;
    let free_cells: Vec<u32> = (0..complex.len() as u32)
        .filter(|&c| matches!(constraints.roles[c as usize], Role::Free | Role::Pin(_)))
        .collect();
    let pairs: Vec<u32> = (0..complex.pairs.len() as u32).collect();
    let edges = auto::free_edges(complex, &free_cells, &pairs);
    let rest = free_cells
        .iter()
        .map(|&c| complex.cells[c as usize].center)
        .collect();
    let size = complex.grid.finest_size();
    let shape = multilevel::shape(rest, &edges, size, LIMITS);
    let &(nodes, coarse_edges) = shape.levels.last().expect("the finest level");
    let coarsest = match shape.levels.len() {
        1 => counts.factor,
        _ => graph_fill(nodes, &shape.coarsest_edges, dof).unwrap_or_default(),
    };
    let coarse_blocks: usize = shape.levels[1..].iter().map(|&(n, e)| n + e).sum();
    SolveCounts {
        prolongation: shape.prolongation as f64,
        coarse_blocks: coarse_blocks as f64,
        coarsest_entries: (nodes * tri + coarse_edges * dof * dof) as f64,
        coarsest,
        first_coarse_edges: shape.levels.get(1).map_or(0.0, |l| l.1 as f64),
        ..counts
    }
}

/// The counts a solve's memory and time go with.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct SolveCounts {
    /// Cells and face pairs of the complex.
    pub cells: f64,
    pub pairs: f64,
    /// Cells with unknowns, and the pairs coupling at least one of them.
    pub free: f64,
    pub coupled: f64,
    /// Unknowns a free cell.
    pub dof: f64,
    /// Entries of the direct path's assembled system (its value slots).
    pub entries: f64,
    /// The fine system's factor: `len`, `flops`, `largest_update` (scalar entries), and the
    /// position system's (`nodes_len`).
    pub factor: Fill,
    /// The multilevel path: blocks of its finest level (diagonal and edges), of its smoothed
    /// prolongation, of its coarse levels, and its coarsest factor.
    pub fine_blocks: f64,
    pub prolongation: f64,
    pub coarse_blocks: f64,
    pub coarsest_entries: f64,
    pub coarsest: Fill,
    /// The first coarse level's edges (the Galerkin product's partial sums).
    pub first_coarse_edges: f64,
}

impl SolveCounts {
    /// The complex alone: its cells, their index and its face pairs (what the cells of a
    /// solve hold while its coarse stages are solved).
    fn complex_bytes(&self) -> f64 {
        self.cells * COMPLEX_BYTES_PER_CELL + self.pairs * 16.0
    }

    /// The process's bytes during a stage's solve beside the linear solver: the complex, the
    /// motions, the layout, the position system's factor.
    pub fn base_bytes(&self) -> f64 {
        self.cells * BYTES_PER_CELL + self.pairs * BYTES_PER_PAIR + self.factor.nodes_len * 16.0
    }

    /// The direct path's bytes: its factor, faer's scratch (1.6 times the largest dense
    /// update, measured), and the assembled system (values, argsort, pattern and the
    /// iteration's matrix: 20 bytes an entry, measured; the entries' positions are freed before
    /// the factor's pages are touched).
    pub fn direct_bytes(&self) -> f64 {
        8.0 * self.factor.len + 13.0 * self.factor.largest_update + 20.0 * self.entries
    }

    /// The local-global path's bytes: the position Laplacian's factor (the cell graph's, one
    /// value an entry) and each pair's two sides' moments.
    pub fn local_global_bytes(&self) -> f64 {
        8.0 * self.factor.nodes_len + self.pairs * 2.0 * (self.dof * self.dof + 8.0) * 8.0
    }

    /// The multilevel path's bytes: its finest level (the matrix in `f64` and `f32`, the block
    /// inverses, the assembled values), the smoothed prolongation, the Galerkin product's
    /// partial sums, the coarse levels and the coarsest factor with its pattern.
    pub fn multilevel_bytes(&self) -> f64 {
        let bb = self.dof * self.dof;
        let coarsest = 8.0 * self.coarsest.len
            + 8.0 * self.coarsest.largest_update
            + 40.0 * self.coarsest_entries;
        if self.prolongation == 0.0 {
            // Few enough cells to factor the finest level itself.
            return self.fine_blocks * bb * 8.0 + self.entries * 8.0 + coarsest;
        }
        self.fine_blocks * bb * 12.0
            + self.free * bb * 8.0
            + self.entries * 8.0
            + self.prolongation * (bb * 8.0 + 12.0)
            + self.first_coarse_edges * bb * 8.0 * 3.0
            + self.coarse_blocks * bb * 12.0
            + coarsest
    }

    /// Whether a stage's solve by `method` fits `budget`.
    pub fn fit(&self, method: Method, budget: Budget) -> bool {
        self.base_bytes() + self.path_bytes(method) <= budget.limit() as f64
    }

    /// The bytes of the linear solver `method` takes, beside [`Self::base_bytes`].
    pub fn path_bytes(&self, method: Method) -> f64 {
        match method {
            Method::Multilevel => self.multilevel_bytes(),
            Method::LocalGlobal => self.local_global_bytes(),
            _ => self.direct_bytes(),
        }
    }

    /// Seconds of one Gauss-Newton iteration on these cells by `method` (by local-global
    /// iterations: the [`LOCAL_GLOBAL_PER_NEWTON`] that stand for one), and of a multilevel
    /// hierarchy's construction.
    pub fn iteration_seconds(&self, method: Method) -> (f64, f64) {
        let common = ITERATION_SECONDS_PER_ENTRY * (self.cells + self.coupled);
        match method {
            Method::LocalGlobal => {
                // The local step's pass over the cells and pairs, and the global step's
                // back substitution for each coordinate.
                let one = LOCAL_GLOBAL_SHARE * common
                    + self.dof.min(3.0) * SOLVE_SECONDS_PER_FACTOR_ENTRY * self.factor.nodes_len;
                (LOCAL_GLOBAL_PER_NEWTON * one, 0.0)
            }
            Method::Multilevel => {
                let blocks = self.fine_blocks + self.prolongation;
                let cg = CG_ITERATIONS
                    * (CG_SECONDS_PER_BLOCK * blocks
                        + CG_SECONDS_PER_COARSEST_ENTRY * self.coarsest.len);
                let setup = self.coarsest.flops / COARSEST_FLOPS_PER_SECOND
                    + HIERARCHY_SECONDS_PER_BLOCK * blocks;
                (common + cg, setup)
            }
            _ => (
                common
                    + self.factor.flops / FLOPS_PER_SECOND
                    + SOLVE_SECONDS_PER_FACTOR_ENTRY * self.factor.len,
                0.0,
            ),
        }
    }
}

/// The estimate of a solve coarse to fine: the `stages` (coarsest first) and the cells'
/// own `fine` stage, each with its counts and the path it takes, through `load_steps` load
/// steps on the coarsest. The peak is the largest stage's (a coarse stage's with the cells'
/// complex held beside it: a coarse stage may have more free cells than the cells themselves,
/// where it joins loose parts to the constrained ones); the seconds are every stage's
/// iterations ([`ITERATIONS_PER_LOAD_STEP`] a load step on the coarsest stage,
/// [`ITERATIONS_PER_STAGE`] on each finer one, one more on the cells' own), a multilevel
/// hierarchy's construction on each (two on the coarsest), the symbolic analyses and the
/// transfer's construction.
fn solve_estimate(
    stages: &[(SolveCounts, Method)],
    (fine, method): &(SolveCounts, Method),
    load_steps: f64,
    limit: u64,
) -> Estimate {
    let bytes_of = |(c, m): &(SolveCounts, Method)| c.base_bytes() + c.path_bytes(*m);
    let seconds_of = |(c, m): &(SolveCounts, Method), iterations: f64, builds: f64| {
        let (iteration, setup) = c.iteration_seconds(*m);
        let symbolic = match m {
            Method::Multilevel => 0.0,
            _ => SYMBOLIC_SECONDS_PER_ENTRY * c.entries,
        };
        iterations * iteration + builds * setup + symbolic
    };
    let coarsest_iterations = ITERATIONS_PER_LOAD_STEP * load_steps + 1.0;
    let mut bytes = bytes_of(&(*fine, *method));
    let mut solve = 0.0;
    for (k, stage) in stages.iter().enumerate() {
        bytes = bytes.max(fine.complex_bytes() + bytes_of(stage));
        solve += match k {
            0 => seconds_of(stage, coarsest_iterations, 2.0),
            _ => seconds_of(stage, ITERATIONS_PER_STAGE, 1.0),
        };
    }
    solve += match stages.is_empty() {
        true => seconds_of(&(*fine, *method), coarsest_iterations, 2.0),
        false => seconds_of(&(*fine, *method), ITERATIONS_PER_STAGE + 1.0, 1.0),
    };
    let transfer = TRANSFER_SECONDS_PER_CELL * fine.cells;
    Estimate {
        cells: fine.cells as usize,
        bytes: bytes as u64,
        seconds: solve + transfer,
        solve_seconds: solve,
        solver: match method {
            Method::Multilevel => Solver::Multilevel,
            Method::LocalGlobal => Solver::LocalGlobal,
            _ => Solver::Direct,
        },
        complete: true,
        limit,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::{BuildParams, build};
    use crate::rigid::Vect;
    use crate::solve::system::System;

    /// The direct path's factor as the forecast counts it is within 25 % of the system's own
    /// symbolic analysis (AMD over the unknowns, where the forecast orders the cells: 19 %
    /// fewer entries on these 1.5k cells of several sizes, 6 % more on the bar's 216k), and
    /// the estimate is of the cells; a budget below it refuses it.
    #[test]
    fn the_forecast_factor_is_the_systems() {
        // An ellipsoid's surface, 2 × 1 × 1: boundary cells and larger interior ones.
        let pts: Vec<Vect<3>> = (0..20_000)
            .map(|k| {
                let (u, v) = (k as f64 * 0.618_034 % 1.0, k as f64 / 20_000.0);
                let (theta, z) = (2.0 * std::f64::consts::PI * u, 2.0 * v - 1.0);
                let r = (1.0 - z * z).sqrt();
                Vect::<3>::new(2.0 * r * theta.cos(), r * theta.sin(), z)
            })
            .collect();
        let params = BuildParams {
            cell_size: Some(0.15),
            ..Default::default()
        };
        let complex = build(&pts, &[], &params, Budget::default()).unwrap().0;
        let n = complex.len();
        let mut roles = vec![Role::Free; n];
        roles[0] = Role::Fixed;
        let constraints = Constraints::held(&complex, roles);
        let (counts, uniform) = counts(&complex, &constraints);
        assert!(!uniform && counts.free as usize == n - 1);
        let system = System::new(
            &complex,
            &constraints,
            &SolveParams {
                method: Method::Direct,
                ..Default::default()
            },
            Budget::default(),
            &crate::said::Said::new(),
        )
        .unwrap();
        let len = system.factor_len().unwrap() as f64;
        assert!(
            (counts.factor.len / len - 1.0).abs() < 0.25,
            "forecast {} against {len}",
            counts.factor.len
        );
        // Auto takes the direct path for these cells, and the estimate is of them.
        let e = forecast(
            &complex,
            &constraints,
            &SolveParams::default(),
            Budget::default(),
        )
        .unwrap();
        assert_eq!((e.cells, e.solver, e.complete), (n, Solver::Direct, true));
        assert!(e.fits() && e.bytes > 8 * len as u64, "{e:?}");
        // A budget below the estimate refuses it, naming the cells.
        let tight = Budget::bytes(e.bytes / 10);
        let refused = forecast(&complex, &constraints, &SolveParams::default(), tight).unwrap();
        let error = refused.check(tight, &cells_advice()).unwrap_err();
        assert!(error.to_string().contains("--cell-size"), "{error}");
    }

    /// What the forecast says of each stage's Gauss-Newton system (`StageFits`, which a solve
    /// looks up instead of counting again) is what counting it again says, under a budget it
    /// fits and one it does not; the stages are the ones `coarse_to_fine` solves, the cells
    /// themselves last.
    #[test]
    fn the_stages_fits_are_counted_as_again() {
        let pts: Vec<Vect<3>> = (0..40_000)
            .map(|k| {
                let (u, v) = (k as f64 * 0.618_034 % 1.0, k as f64 / 40_000.0);
                Vect::<3>::new(8.0 * u, 2.0 * v, 0.05 * (7.0 * u).sin())
            })
            .collect();
        let params = BuildParams {
            cell_size: Some(0.05),
            ..Default::default()
        };
        let complex = build(&pts, &[], &params, Budget::default()).unwrap().0;
        let n = complex.len();
        let mut roles = vec![Role::Free; n];
        for (c, cell) in complex.cells.iter().enumerate() {
            if cell.center.x < 0.5 {
                roles[c] = Role::Fixed;
            }
        }
        let constraints = Constraints::held(&complex, roles);
        let solve = SolveParams::default();
        let levels = coarse::levels(n, &solve);
        assert!(levels >= 1, "{n} cells");
        let mut stages: Vec<(CellComplex<3>, Constraints<3>)> = Vec::new();
        for k in (1..=levels).rev() {
            let (parents, on_parents) = coarsen_stage(&complex, &constraints, k);
            let coarser = stages.last().map_or(0, |s| s.0.len());
            if parents.len() < n && parents.len() > coarser {
                stages.push((parents, on_parents));
            }
        }
        let (e, _) = forecast_stages(&complex, &constraints, &solve, Budget::default()).unwrap();
        let mut answers = [false, false];
        for (k, budget) in [Budget::default(), Budget::bytes(e.bytes / 4)]
            .into_iter()
            .enumerate()
        {
            let (_, fits) = forecast_stages(&complex, &constraints, &solve, budget).unwrap();
            let counted: Vec<(usize, bool)> = stages
                .iter()
                .map(|(c, k)| (c, k))
                .chain(std::iter::once((&complex, &constraints)))
                .map(|(c, k)| (c.len(), newton_fits(c, k, budget)))
                .collect();
            assert_eq!(fits, counted);
            answers[k] = fits.last().unwrap().1;
        }
        assert_eq!(
            answers,
            [true, false],
            "one budget fits the cells' system, one does not"
        );
    }
}
