//! The memory budget: everything that grows with the cells, the extent or the samples is
//! estimated before it is allocated, and a run whose estimate exceeds the budget stops with
//! [`Error::Memory`], naming the parameter to change, instead of ending in an allocation abort.
//!
//! The budget is `--memory-limit` (library: a [`Budget`], the `memory` of a run's
//! parameters), by default three quarters of the machine's physical memory, or of the control
//! group's limit where that is lower, and at most half the address-space limit
//! ([`default_limit`]). The estimates are of the large buffers only:
//!
//! - the cell construction (`cells::build`): 1 KiB per occupied finest cell (its code, the
//!   coarser levels, the empty blocks and the flood fill's maps, the leaves, the complex's
//!   cells and adjacency), checked as
//!   the occupied cells grow; 24 bytes per cell of the coarsest level, which is enumerated
//!   whole; 8 bytes per candidate cell of the triangles' boxes, counted before they are
//!   rasterized. Nothing is sized by the bounding box's volume;
//! - the run's cells, forecast once the occupied cells are known and the empty space tiled,
//!   before it is classified (`cells::Forecast`): a run that will solve them is refused there
//!   when no solver path can fit them ([`crate::estimate::check_forecast`], 6 KB a cell at
//!   least), before the build spends its time and memory on them;
//! - the whole solve, once the cells and the roles are known and before its first (coarse)
//!   stage ([`crate::solve::forecast`], priced by [`crate::estimate`]): the direct path's
//!   factor and the multilevel hierarchy's coarsest factor from symbolic analyses of the
//!   cells' graph, every stage coarse to fine; within 0.8–1.1 times the measured peak on the
//!   bar, the paper's meshes and a scan (BENCHMARKS.md, "What a run will take");
//! - with `--solver auto` (the default) the direct path where its factor fits, else the
//!   multilevel one;
//! - the solver, again at each stage: `SOLVER_BYTES_PER_CELL` per cell before anything is
//!   built (the motions, the energies, the position system), then, for the direct path, the
//!   assembled system's entries before they are allocated, and the sparse Cholesky factor
//!   exactly, from its symbolic analysis, before its values are (the factor's fill depends on
//!   the shape: 12–13 KB per cell on a terrain, 27 KB on the 10 × 1 × 1 bar at 0.02; a flat
//!   per-cell estimate refused a 1.1M-cell terrain that ran in 14.4 GB);
//! - the multilevel solver ([`crate::solve::Method::Multilevel`]): at least
//!   `MULTILEVEL_BYTES_PER_CELL` (the normal equations' blocks, the smoothed prolongation,
//!   the coarse level's factor; 10.4 KB per cell of process peak measured at 342k cells of a
//!   terrain, but 41 KB on the bar, whose coarsest level factors as a solid: the whole
//!   solve's estimate above counts it);
//! - the dense RBF: its `n × n` factor and the kernel sums ([`rbf_bytes`]).

use crate::error::{Error, Result};
use crate::said::Said;

/// The solver's memory per cell before its sparse factor (see the module docs).
pub(crate) const SOLVER_BYTES_PER_CELL: u64 = 4 << 10;

/// The multilevel solver's memory per cell (see the module docs).
pub(crate) const MULTILEVEL_BYTES_PER_CELL: u64 = 12 << 10;

/// The memory budget when none is given: three quarters of the physical memory, or of the
/// control group's limit where that is lower (24 GiB where neither can be read), and at most
/// half the address-space limit (`ulimit -v`, `RLIMIT_AS`) where one is set.
///
/// The address-space limit counts: a budget above it let an estimate pass that the allocator
/// then could not serve, and the run aborted instead of saying which parameter to change (the
/// fuzz harness, `tools/src/bin/fuzz.rs`, runs every case under such a limit). Half, because
/// address space is spent without memory: thread stacks, malloc's per-thread arenas, and the
/// dense kernels' per-thread scratch, which `faer`'s gemm sizes at twice the L3 cache (545 MB
/// per thread on this machine's reported L3) and never touches whole.
pub fn default_limit() -> u64 {
    let total = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        let line = s.lines().find(|l| l.starts_with("MemTotal:"))?;
        let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kb * 1024)
    });
    let cgroup = std::fs::read_to_string("/sys/fs/cgroup/memory.max")
        .ok()
        .and_then(|s| s.trim().parse::<u64>().ok());
    let physical = [total, cgroup]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(32 << 30);
    let budget = physical / 4 * 3;
    match address_space_limit() {
        Some(limit) => budget.min(limit / 2),
        None => budget,
    }
}

/// The process's address-space limit (`RLIMIT_AS`), when one is set.
#[cfg(unix)]
#[allow(unsafe_code)]
fn address_space_limit() -> Option<u64> {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes the struct it is given and nothing else.
    let ok = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut limit) } == 0;
    // `rlim_t` is u64 on Linux but not on every unix.
    #[allow(clippy::unnecessary_cast)]
    let current = limit.rlim_cur as u64;
    (ok && limit.rlim_cur != libc::RLIM_INFINITY).then_some(current)
}

#[cfg(not(unix))]
fn address_space_limit() -> Option<u64> {
    None
}

/// The memory budget of a run: one value for all its stages (the cells, the solver, the RBF),
/// held once in the run's parameters ([`crate::pipeline::DeformParams::memory`],
/// [`crate::pipeline::ApplyParams::memory`]) and handed to each stage that allocates.
/// [`Budget::default`] is the machine's share ([`default_limit`]), read when a stage asks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Budget(Option<u64>);

impl Budget {
    /// A budget of `bytes`.
    pub fn bytes(bytes: u64) -> Self {
        Self(Some(bytes))
    }

    /// The budget given (`--memory-limit`), or the machine's share where none was.
    pub fn given(bytes: Option<u64>) -> Self {
        Self(bytes)
    }

    /// [`Budget::given`], refused where it is no memory at all (no run fits in it): the command
    /// line and Python refuse a limit of 0, in their own words. (The Blender panel's 0 is its
    /// "automatic", as its cell size's 0 is: it gives no limit.)
    pub fn checked(bytes: Option<u64>) -> Result<Self> {
        if bytes == Some(0) {
            return Err(Error::param(
                Said::new().opt(crate::said::Opt::MemoryLimit).text(
                    " under a byte: no run fits in it; give a size such as 8G, or leave it out for \
                 three quarters of this machine's memory",
                ),
            ));
        }
        Ok(Self(bytes))
    }

    /// The budget in bytes.
    pub fn limit(self) -> u64 {
        self.0.unwrap_or_else(default_limit)
    }

    /// [`check`] against this budget.
    pub fn check(self, what: impl Into<Said>, bytes: f64, advice: impl Into<Said>) -> Result<()> {
        check(what, bytes, self.limit(), advice)
    }
}

/// [`Error::Memory`] when `bytes` exceed `limit`; `what` names the allocation, `advice` the
/// parameters that shrink it.
pub fn check(what: impl Into<Said>, bytes: f64, limit: u64, advice: impl Into<Said>) -> Result<()> {
    if bytes <= limit as f64 {
        Ok(())
    } else {
        Err(Error::Memory {
            what: what.into(),
            needed: format_bytes(bytes),
            limit: format_bytes(limit as f64),
            advice: advice.into(),
        })
    }
}

/// The estimated bytes of the dense RBF of `n` cells in `D` dimensions.
pub fn rbf_bytes(n: usize, dim: usize) -> f64 {
    let n = n as f64;
    8.0 * n * n + 8.0 * n * (4.0 * dim as f64 + 8.0)
}

/// `1.5 GiB`, `300 MiB`, `512 bytes`.
pub fn format_bytes(bytes: f64) -> String {
    const UNITS: [(&str, f64); 4] = [
        ("TiB", 1099511627776.0),
        ("GiB", 1073741824.0),
        ("MiB", 1048576.0),
        ("KiB", 1024.0),
    ];
    for (name, size) in UNITS {
        if bytes >= size {
            return format!("{:.1} {name}", bytes / size);
        }
    }
    format!("{bytes:.0} bytes")
}

/// Parses a size: a number of bytes, or a number with `K`, `M`, `G` or `T` (powers of 1024;
/// `KB`, `KiB`, `MB`, `MiB`, … are the same), e.g. `8G`, `512MiB`, `2.5g`.
pub fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let value: f64 = number
        .parse()
        .map_err(|_| format!("`{text}` is not a size (e.g. 8G, 512M, 1000000)"))?;
    let scale = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" | "kib" => 1024.0,
        "m" | "mb" | "mib" => 1048576.0,
        "g" | "gb" | "gib" => 1073741824.0,
        "t" | "tb" | "tib" => 1099511627776.0,
        _ => {
            return Err(format!(
                "`{text}`: unknown unit `{unit}` (use K, M, G or T)"
            ));
        }
    };
    let bytes = value * scale;
    // A size under a byte is a size, which the budget refuses (`Budget::checked`) as a value,
    // in the face's words.
    if !(0.0..1.8e19).contains(&bytes) {
        return Err(format!("`{text}` is not a usable size"));
    }
    Ok(bytes as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_print() {
        assert_eq!(parse_size("8G"), Ok(8 << 30));
        assert_eq!(parse_size("512MiB"), Ok(512 << 20));
        assert_eq!(parse_size("1000"), Ok(1000));
        assert_eq!(parse_size("2.5g"), Ok((2.5 * 1073741824.0) as u64));
        assert!(parse_size("lots").is_err());
        assert!(parse_size("8Q").is_err());
        assert_eq!(parse_size("0"), Ok(0));
        assert_eq!(parse_size("0.5"), Ok(0));
        assert!(Budget::checked(Some(0)).is_err());
        assert_eq!(Budget::checked(Some(1)).ok(), Some(Budget::bytes(1)));
        assert_eq!(format_bytes(1.5 * 1073741824.0), "1.5 GiB");
        assert!(default_limit() > 1 << 20);
        let e = check("the RBF", 2e9, 1 << 30, "use --transfer blend")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("1.9 GiB") && e.contains("1.0 GiB") && e.contains("--memory-limit"),
            "{e}"
        );
    }
}
