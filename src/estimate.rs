//! What a run will take, estimated before it spends it: its cells, its peak memory and its
//! seconds ([`Estimate`]).
//!
//! Two estimates are made, each before the allocations it prices:
//!
//! - **The cells' forecast** ([`crate::cells::Forecast`]), once the occupied finest cells are
//!   known and the empty space is tiled, before the tiles are classified (a winding number
//!   each: most of a large build's time) or any leaf is made. [`check_forecast`] refuses a run
//!   whose cells cannot be solved within the budget even by the leanest path: the complex and
//!   the multilevel solver's finest level, `FLOOR_BYTES_PER_CELL` a cell.
//! - **The solve's estimate** (`solve::forecast`), once the complex and the roles are known,
//!   before the solve's first stage: the symbolic analysis of the free cells' graph (a node a
//!   cell, AMD, as the direct solver's own analysis orders the unknowns) gives the Cholesky
//!   factor's entries and multiply-adds; the multilevel hierarchy's levels are counted on the
//!   graph alone (the same groups, each coarse level's edges as its Galerkin product makes
//!   them) and its coarsest level analysed the same way, for every stage coarse to fine
//!   (`coarsen`). These counts are priced in bytes and seconds with the constants below, for
//!   the path `--solver auto` takes; a run over the budget is refused there, before any coarse
//!   stage is solved. `auto` starts with local-global iterations and may switch to
//!   Gauss-Newton's system, but only where that fits the budget: its memory and seconds are
//!   priced for that system where it fits (an upper bound where the run does not switch: the
//!   bust at cells of 0.01 is priced at 1.9 GB and 44 s and runs local-global in 320 MB and
//!   9 s; pricing the seconds of the sooner of the two instead said 47 s for the bar at 0.02,
//!   which switched and took over 130 s), else for the local-global iterations (451 MB and
//!   16.5 s under a 1 GiB limit; `LOCAL_GLOBAL_PER_NEWTON`).
//!
//! The prices are the constants below, measured on the development machine (2 cores, release
//! build; BENCHMARKS.md, "What a run will take"). They assume that machine's speed: the
//! seconds scale with the cores and the memory bandwidth, the bytes do not. The iterations
//! are the typical counts of a solve coarse to fine (`ITERATIONS_PER_LOAD_STEP` a load step
//! on the coarsest cells, `ITERATIONS_PER_STAGE` on each finer stage): an edit that needs
//! more (a twist of several turns, a stiff target) takes longer than estimated; the memory does
//! not depend on them.

use crate::cells::Forecast;
use crate::error::Result;
use crate::memory::Budget;
use crate::said::{Opt, Said};

/// The linear solver a solve's memory is priced for: what `--solver auto` comes to for its
/// cells (`solve::Method`'s `Direct`, `Multilevel` or `LocalGlobal`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Solver {
    /// The sparse Cholesky factorization.
    Direct,
    /// Conjugate gradients with the multilevel preconditioner.
    Multilevel,
    /// Local-global iterations on the position Laplacian, factored once.
    LocalGlobal,
}

impl Solver {
    /// `direct` or `multilevel`, as `--solver` names it.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Direct => "direct",
            Solver::Multilevel => "multilevel",
            Solver::LocalGlobal => "local-global",
        }
    }
}

/// What a run will take, estimated before its solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Cells of the complex (forecast from the occupied cells where `complete` is false).
    pub cells: usize,
    /// The run's peak memory, in bytes: the cells, the solver and its factor.
    pub bytes: u64,
    /// Seconds on the development machine (module docs): the solve's and the transfer's
    /// construction, and the cells' construction where the estimate is of samples
    /// ([`crate::pipeline::estimate`]; a solve announces what is left of its run).
    pub seconds: f64,
    /// Seconds of the solve alone, a part of `seconds`.
    pub solve_seconds: f64,
    /// The linear solver the solve takes.
    pub solver: Solver,
    /// Whether the estimate is of the built cells and the resolved spec (`false`: of the
    /// cells' forecast alone, [`Estimate::floor`], whose bytes and seconds are the least the
    /// run can take).
    pub complete: bool,
    /// The memory budget the estimate was made for: the path `--solver auto` takes depends on
    /// it.
    pub limit: u64,
}

impl Estimate {
    /// The least a run of the cells `forecast` can take ([`check_forecast`]'s bytes; the
    /// seconds of the build, and of 13 Gauss-Newton iterations of assembly and line search
    /// alone): what [`crate::pipeline::estimate`] says of cells it does not build because they
    /// cannot fit `budget`. `complete` is false.
    pub fn floor(forecast: &Forecast, direct: bool, budget: Budget) -> Self {
        let cells = forecast.cells() as f64;
        let build =
            forecast.blocks as f64 * WINDING_SECONDS_PER_BLOCK + cells * BUILD_SECONDS_PER_CELL;
        // A cell has about three face pairs.
        let solve = 13.0 * ITERATION_SECONDS_PER_ENTRY * 4.0 * cells;
        Self {
            cells: cells as usize,
            bytes: floor_bytes(forecast, direct) as u64,
            seconds: build + solve + TRANSFER_SECONDS_PER_CELL * cells,
            solve_seconds: solve,
            solver: match direct {
                true => Solver::Direct,
                false => Solver::Multilevel,
            },
            complete: false,
            limit: budget.limit(),
        }
    }

    /// Whether the estimated memory fits the budget it was made for.
    pub fn fits(&self) -> bool {
        self.bytes <= self.limit
    }

    /// [`crate::Error::Memory`] when the estimate does not fit `budget`, naming the solve, its
    /// cells and path, with `advice` (the parameters that shrink it).
    pub fn check(&self, budget: Budget, advice: &Said) -> Result<()> {
        let by = match self.solver {
            Solver::Multilevel => " by the multilevel solver",
            Solver::Direct => "",
            Solver::LocalGlobal => " by local-global iterations",
        };
        budget.check(
            format!(
                "solving {} cells{by}",
                crate::human::count(self.cells as u64)
            ),
            self.bytes as f64,
            advice,
        )
    }

    /// Whether the run is worth a word before it starts: it is expected to take longer than
    /// [`LONG_RUN_SECONDS`].
    pub fn is_long(&self) -> bool {
        self.seconds > LONG_RUN_SECONDS
    }

    /// `about 216,016 cells, ~5.7 min, ~6.3 GiB` (what the command line prints before a long
    /// solve).
    pub fn summary(&self) -> String {
        format!(
            "about {} cells, ~{}, ~{}",
            crate::human::count(self.cells as u64),
            duration(self.seconds),
            crate::memory::format_bytes(self.bytes as f64)
        )
    }
}

/// Runs expected to take longer than this many seconds are announced before their solve.
pub const LONG_RUN_SECONDS: f64 = 10.0;

/// `40 s`, `5.7 min`, `2.1 h`.
fn duration(seconds: f64) -> String {
    if seconds < 90.0 {
        format!("{:.0} s", seconds.max(1.0))
    } else if seconds < 5400.0 {
        format!("{:.1} min", seconds / 60.0)
    } else {
        format!("{:.1} h", seconds / 3600.0)
    }
}

// ----- Memory: bytes of the structures that grow with the cells. -----

/// The complex, the roles, the motions and their copies (the line search's trial, the load
/// step's start and prediction), the solver's layout, the field: bytes a cell, over
/// [`BYTES_PER_PAIR`] a face pair, the position system's factor and the linear solver.
pub(crate) const BYTES_PER_CELL: f64 = 1200.0;
/// A face pair: its entry in the complex, its quadrature and its slot in the system's layout.
pub(crate) const BYTES_PER_PAIR: f64 = 60.0;
/// A cell of the complex alone: the cell and its entry in the index of keys.
pub(crate) const COMPLEX_BYTES_PER_CELL: f64 = 150.0;
/// The least a cell costs a solve, the complex and the multilevel solver's finest level
/// included (its matrix in `f64` and `f32`, the block inverses, the smoothed prolongation):
/// what [`check_forecast`] refuses on before the cells are built.
pub(crate) const FLOOR_BYTES_PER_CELL: f64 = 6000.0;
/// The cells' construction: bytes an occupied finest cell (its code, the pyramid, the blocks
/// and their classification, the leaves), as `cells::build` checks it.
pub(crate) const BUILD_BYTES_PER_OCCUPIED: f64 = 1024.0;

// ----- Time: rates measured on the development machine. -----

/// Multiply-adds a second of the direct path's numeric Cholesky factorization (faer's
/// supernodal, 32-bit indices), as the symbolic analysis of the cells' graph counts them: the
/// bar at 0.02 factors 1.3e12 of them in 38–148 s, at 0.05 1.4e11 in 6–13 s, as the load of
/// the shared machine varies.
pub(crate) const FLOPS_PER_SECOND: f64 = 2.0e10;
/// Multiply-adds a second of the multilevel path's coarsest factorization (faer's `Llt`,
/// `usize` indices: 1.0e12 in 139 s, 1.1e11 in 13 s on a loaded machine).
pub(crate) const COARSEST_FLOPS_PER_SECOND: f64 = 1.2e10;
/// Seconds an assembled entry costs the direct path's symbolic analysis (AMD over the
/// unknowns, the pattern) and the position system's, once a stage.
pub(crate) const SYMBOLIC_SECONDS_PER_ENTRY: f64 = 2.2e-7;
/// Seconds a cell of the cells' construction (rasterizing, tiling, the leaves, adjacency).
pub(crate) const BUILD_SECONDS_PER_CELL: f64 = 3.0e-6;
/// Seconds a block of the empty space classified by its winding number.
pub(crate) const WINDING_SECONDS_PER_BLOCK: f64 = 1.2e-5;
/// Seconds a Gauss-Newton iteration spends a cell and a coupled pair on assembly, the line
/// search and the position projection.
pub(crate) const ITERATION_SECONDS_PER_ENTRY: f64 = 4.0e-6;
/// Seconds a factor entry costs the two triangular solves of a direct iteration.
pub(crate) const SOLVE_SECONDS_PER_FACTOR_ENTRY: f64 = 3.0e-9;
/// Seconds an entry of the coarsest factor costs a conjugate-gradient iteration (its
/// triangular solves in the V-cycle).
pub(crate) const CG_SECONDS_PER_COARSEST_ENTRY: f64 = 1.0e-9;
/// Seconds a block of the multilevel path's finest level (its matrix and prolongation) costs a
/// conjugate-gradient iteration (two smoothings, a residual, the restriction and the
/// prolongation).
pub(crate) const CG_SECONDS_PER_BLOCK: f64 = 3.5e-7;
/// Conjugate-gradient iterations of a Gauss-Newton step (multilevel path).
pub(crate) const CG_ITERATIONS: f64 = 6.0;
/// Seconds a block of the finest level costs the hierarchy's construction (the smoothed
/// prolongation, the Galerkin product), beside its coarsest factor.
pub(crate) const HIERARCHY_SECONDS_PER_BLOCK: f64 = 2.0e-6;
/// Seconds a cell of the transfer's construction (the PU's patches, the field).
pub(crate) const TRANSFER_SECONDS_PER_CELL: f64 = 1.0e-5;
/// Gauss-Newton iterations a load step takes on the coarsest cells.
pub(crate) const ITERATIONS_PER_LOAD_STEP: f64 = 3.0;
/// Gauss-Newton iterations each finer stage of a solve coarse to fine takes (the cells' own:
/// one more).
pub(crate) const ITERATIONS_PER_STAGE: f64 = 2.0;
/// Accelerated local-global iterations that do what one Gauss-Newton iteration of the counts
/// above does, where a solve takes those: with 20 the seconds came 1.3 and 1.7 times the
/// run's on the bar at 0.05 and the bust at 0.01, each kept to them by its budget
/// (BENCHMARKS.md, "What a run will take").
pub(crate) const LOCAL_GLOBAL_PER_NEWTON: f64 = 20.0;

/// Refuses a run whose forecast cells ([`Forecast`]) cannot be solved within `budget` by any
/// path (by the direct one with `direct`, `--solver direct`): the cells' construction, or the
/// complex and the leanest linear solver (`FLOOR_BYTES_PER_CELL` a cell). Called by the
/// build before the empty space is classified.
pub fn check_forecast(forecast: &Forecast, direct: bool, budget: Budget) -> Result<()> {
    let cells = forecast.cells();
    let size = crate::human::length(forecast.cell_size, forecast.cell_size);
    budget.check(
        format!(
            "solving about {} cells of size {size}",
            crate::human::count(cells as u64)
        ),
        floor_bytes(forecast, direct),
        Said::from("use a larger ")
            .opt(Opt::CellSize)
            .text(" (or fewer ")
            .opt(Opt::Cells)
            .text("), or raise ")
            .opt(Opt::MemoryLimit),
    )
}

/// The least bytes a run of the cells `forecast` takes: its build, or the complex and the
/// leanest linear solver ([`FLOOR_BYTES_PER_CELL`] a cell; the direct path, when asked for,
/// at least its assembled system, 20 bytes an entry and some 250 entries a cell).
fn floor_bytes(forecast: &Forecast, direct: bool) -> f64 {
    let per_cell = match direct {
        true => FLOOR_BYTES_PER_CELL.max(BYTES_PER_CELL + 5000.0),
        false => FLOOR_BYTES_PER_CELL,
    };
    let build = forecast.occupied as f64 * BUILD_BYTES_PER_OCCUPIED;
    (forecast.cells() as f64 * per_cell).max(build)
}
