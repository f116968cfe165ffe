//! The finest cell size of a build, decided in one place: given (`--cell-size`), searched for
//! a count of cells (`--cells N`, [`cell_size_for`]), or the default, the longest extent of
//! the input's box over [`DEFAULT_DIVISIONS`]; [`check_size`] bounds every size a user gives
//! (`--cell-size`, `--min-cell-size`).
//!
//! [`sized`] is what a build calls first: in memory on the samples themselves, streaming on a
//! proxy that the first pass gathers only when a count is asked for.

use std::borrow::Cow;

use super::{BuildInfo, BuildParams, CellComplex, bounds, build};
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::rigid::Vect;
use crate::said::{Opt, Said};

/// The default finest cell size is the longest extent of the input's box over this.
pub const DEFAULT_DIVISIONS: f64 = 32.0;

/// The finest cell size of a box whose longest extent is `longest` under `cell_size`: the
/// size given, checked ([`check_size`]), or the default.
pub(crate) fn finest(cell_size: Option<f64>, longest: f64) -> Result<f64> {
    match cell_size {
        Some(s) => check_size(s, None),
        None if longest > 0.0 => Ok(longest / DEFAULT_DIVISIONS),
        None => Ok(1.0),
    }
}

/// `size` when it is positive and at most [`crate::spec::LARGEST`]: past 1e15 the cells'
/// corners leave `f64` no digits for the shape (a size of 1e300 ends in an indefinite
/// Gauss-Newton system). `what` names the size in the error.
pub(crate) fn check_size(size: f64, what: Option<Opt>) -> Result<f64> {
    if size.is_finite() && size > 0.0 && size <= crate::spec::LARGEST {
        return Ok(size);
    }
    let said = match what {
        Some(o) => Said::new().set(o, crate::human::typed(size)),
        None => Said::from(format!("cell size {}", crate::human::typed(size))),
    };
    Err(Error::param(said.text(format!(
        " must be positive and at most {:e}",
        crate::spec::LARGEST
    ))))
}

/// What [`sized`] decided: the build's parameters with the finest cell size, what the search
/// says when it ran, and the complex its last try built when that try's size is the one
/// chosen (the search's points then make the same complex again, so a caller that builds on
/// those very points, in the same bounds, takes this one instead).
pub(crate) struct Sized<const D: usize> {
    pub params: BuildParams,
    pub note: Option<Said>,
    pub built: Option<(CellComplex<D>, BuildInfo)>,
}

/// `params` with the finest cell size decided, and how, when it was searched for: with a
/// target count (`--cells N`), the size is searched on the points `proxy` gives (the samples,
/// or a decimated copy of a streamed file's) after the target is checked against the budget;
/// else `params` as they are (the size given, or the default the grid takes).
#[allow(clippy::type_complexity)]
pub(crate) fn sized<'a, const D: usize>(
    params: &BuildParams,
    budget: Budget,
    proxy: impl FnOnce() -> Result<(Cow<'a, [Vect<D>]>, &'a [[u32; 3]])>,
) -> Result<Sized<D>> {
    let Some(n) = params.target_cells else {
        return Ok(Sized {
            params: *params,
            note: None,
            built: None,
        });
    };
    check_target(n, budget)?;
    let (points, triangles) = proxy()?;
    let (size, built) = search(&points, triangles, params, n, budget)?;
    let note = Said::new().set(Opt::Cells, n).text(format!(
        ": finest cell size {}",
        crate::human::length(size, size)
    ));
    let params = BuildParams {
        cell_size: Some(size),
        target_cells: None,
        ..*params
    };
    Ok(Sized {
        params,
        note: Some(note),
        built,
    })
}

/// What a build asked for `target` cells says when the shape gave far fewer (too few
/// samples, or too thin, to fill more at the finest size searched), or a count more than 2 %
/// off (the count jumps as the grid's alignment with a thin shape changes: a 10 × 1 × 1 bar of
/// 20k points has 1,082 cells at 0.2460 and 841 at 0.2487).
pub(crate) fn shortfall(target: Option<usize>, cells: usize) -> Option<Said> {
    let n = target?;
    if cells.saturating_mul(2) < n {
        return Some(Said::new().set(Opt::Cells, n).text(format!(
            ": the shape gives only {cells} cells at the finest size searched (too few samples, \
             or too thin, to fill more)"
        )));
    }
    let off = cells as f64 / n as f64 - 1.0;
    (off.abs() > 0.02).then(|| {
        Said::new().set(Opt::Cells, n).text(format!(
            ": {cells} cells ({:+.0} %), the nearest count of the sizes tried: the \
             count jumps as the cells' alignment with the shape changes",
            100.0 * off
        ))
    })
}

/// The finest cell size for which the complex of `points` (and `triangles`) has about `target`
/// cells (within 2 %, where the counts allow), between 1/4096 and 1/2 of the longest extent.
/// Streaming callers pass a decimated proxy of the samples (`sized`).
///
/// Each try is a whole build, so few are made: the count of a surface's cells goes about as
/// `size⁻²`, so a mesh's first try is the size at which its area holds
/// `target / CELLS_PER_SQUARE` squares of that size (points start from the default size),
/// and the search then steps by the secant of `log count` against `log size` through the
/// last two tries, kept inside the bracket of sizes known to give too many and too few cells
/// (and halving it in log space where the secant would leave it): 3.0 builds on average over
/// twelve meshes at counts from 700 to 50,000 (3.6 from the default size), where a bisection
/// takes 20.
///
/// Counting every candidate level from one pyramid would be cheaper, but a pyramid counts the
/// cells at sizes `2^k s₀` only, a factor of about 4 in count apart, while `--cells N` asks for
/// N: the sizes between levels need the builds anyway. What keeps the search fast is trying
/// sizes on a decimated proxy and sparse builds (memory ∝ cells): a 10M-point terrain with
/// `--cells 20000` sizes and voxelizes in 0.41 s of a 5.4 s deform, the 480k-vertex tube with
/// `--cells 5500` in 0.20 s (release, 2 cores).
pub fn cell_size_for<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    params: &BuildParams,
    target: usize,
    budget: Budget,
) -> Result<f64> {
    check_target(target, budget)?;
    Ok(search(points, triangles, params, target, budget)?.0)
}

/// [`cell_size_for`] once the target is known to fit the budget, with the complex of the
/// last try when the search ends on it (a count within 2 % of the target): the build at the
/// size returned, which need not be made again.
#[allow(clippy::type_complexity)]
fn search<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    params: &BuildParams,
    target: usize,
    budget: Budget,
) -> Result<(f64, Option<(CellComplex<D>, BuildInfo)>)> {
    let (lo, hi) = bounds(points)?;
    let longest = (hi - lo).max().max(f64::MIN_POSITIVE);
    // `small` gives too many cells (or fails), `large` at most `target`.
    let (mut small, mut large) = (longest / 4096.0, longest / 2.0);
    // Every try costs what its occupied cells cost, whatever the extent: the count of a
    // sparse shape (four samples, a scan flattened onto a plane) may never reach the target,
    // and the search ends at the finest size it tries. The final complex may then have fewer
    // cells than asked; its count is reported.
    let try_size = |size: f64| -> Result<Option<(CellComplex<D>, BuildInfo)>> {
        let at = BuildParams {
            cell_size: Some(size),
            target_cells: None,
            ..*params
        };
        match build(points, triangles, &at, budget) {
            Ok(built) => Ok(Some(built)),
            Err(Error::GridTooLarge { .. } | Error::Memory { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    };
    let goal = (target.max(1) as f64).ln();
    let mut last: Option<(f64, f64)> = None; // (ln size, ln count) of the previous try
    // The try closest to the target (|ln(count / target)|, size): the count need not fall as
    // the size grows. On a soup the inside cells come and go with the grid's alignment
    // (0.00946 gave 1.07M cells, 0.00947 gave 653k), and a search that kept narrowing the
    // bracket to 0.2 % built 12 complexes of a million cells (58 s) to return the worse end.
    let mut best: Option<(f64, f64)> = None;
    let mut size = first_size(points, triangles, target)
        .filter(|s| *s > small && *s < large)
        .unwrap_or(longest / 32.0);
    // At most 6 builds: the search reaches 2 % in 4–6 where the count falls steadily with
    // the size, and where it does not, more builds only cost time (the soup above: 12 builds
    // took 58 s; 6 keep the best of them).
    for _ in 0..6 {
        // 1 % in size is about 2 % in count, the tolerance.
        if large / small < 1.01 {
            break;
        }
        let built = try_size(size)?;
        let got = built.as_ref().map(|(complex, _)| complex.len());
        if let Some(c) = got {
            let miss = (c.max(1) as f64).ln() - goal;
            if best.is_none_or(|(b, _)| miss.abs() < b) {
                best = Some((miss.abs(), size));
            }
        }
        let ok = got.is_some_and(|c| c <= target);
        if ok {
            large = size
        } else {
            small = size
        }
        if let Some(c) = got
            && (c as f64 / target as f64 - 1.0).abs() <= 0.02
        {
            return Ok((size, built));
        }
        drop(built);
        let now = got.map(|c| (size.ln(), (c.max(1) as f64).ln()));
        let slope = match (last, now) {
            (Some((s0, c0)), Some((s1, c1))) if (s1 - s0).abs() > 1e-12 && c1 != c0 => {
                ((c1 - c0) / (s1 - s0)).min(-0.5)
            }
            _ => -2.0,
        };
        let next = match now {
            Some((s1, c1)) => (s1 + (goal - c1) / slope).exp(),
            None => (small * large).sqrt(),
        };
        size = if next > small && next < large {
            next
        } else {
            (small * large).sqrt()
        };
        if now.is_some() {
            last = now;
        }
    }
    Ok((best.map_or(large, |(_, size)| size), None))
}

/// Cells per `area / size²` of a surface: a mesh's cells hug its surface, and between 2,000
/// and 20,000 cells the paper's models and the scans' meshes take 1.4–2.3 of them for each
/// square of the finest size on their surface (1.0–1.7 for a thick-walled tube, whose inside
/// adds cells of its own); within that range the search's first try is off by at most 1.6× in
/// count, where the box's default size can be off by 10×.
const CELLS_PER_SQUARE: f64 = 1.9;

/// The search's first size for a 3D mesh: the size whose squares on the triangles' area
/// number `target / CELLS_PER_SQUARE`. None for points, flat shapes and 2D.
fn first_size<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    target: usize,
) -> Option<f64> {
    if D != 3 || triangles.is_empty() {
        return None;
    }
    let corner = |i: u32| {
        points
            .get(i as usize)
            .map(|p| nalgebra::Vector3::new(p[0], p[1], p[2]))
    };
    let area: f64 = triangles
        .iter()
        .filter_map(|t| {
            let (a, b, c) = (corner(t[0])?, corner(t[1])?, corner(t[2])?);
            Some(0.5 * (b - a).cross(&(c - a)).norm())
        })
        .sum();
    let size = (CELLS_PER_SQUARE * area / target.max(1) as f64).sqrt();
    (size.is_finite() && size > 0.0).then_some(size)
}

/// Bytes a complex needs per cell while it is built, its adjacency found and its cells written
/// (550 B measured by `rigidcells cells` at 800k cells, rounded up): the least a `--cells N`
/// run needs before any solve.
pub(crate) const BYTES_PER_TARGET_CELL: u64 = 1 << 10;

/// Refuses `--cells 0`, and a `--cells N` whose complex cannot fit the memory budget, before
/// any try is built (a target of 2⁶⁴−1 would have the search build ever finer trial grids
/// until an allocation failed).
pub(crate) fn check_target(target: usize, budget: Budget) -> Result<()> {
    if target == 0 {
        return Err(Error::param(
            Said::new()
                .set(Opt::Cells, 0)
                .text(" asks for no cells; ask for at least 1"),
        ));
    }
    budget.check(
        format!("a complex of {target} cells"),
        target as f64 * BYTES_PER_TARGET_CELL as f64,
        Said::from("ask for fewer ").opt(Opt::Cells),
    )
}
