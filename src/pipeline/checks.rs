//! The checks of a run's results that every face shares: fold-overs of the map, positions
//! that are not finite, samples beyond the field's margin, coordinates of the input that are
//! not finite.

use std::path::Path;

use crate::error::{Error, Result};
use crate::field::{FieldMap, Outside, Warp, foldovers};
use crate::io::Chunk;
use crate::rigid::Vect;
use crate::said::Said;
use crate::solve::Solution;

/// Samples checked for fold-overs at most: evenly strided, as the check costs a few warps (or
/// one Jacobian) per sample.
pub const FOLDOVER_SAMPLES: usize = 100_000;

/// The fold-overs of `warp` at up to [`FOLDOVER_SAMPLES`] of the world-coordinate `samples`
/// (every k-th), with a warning when there are any: how many samples were checked, and the
/// indices in `samples` of those that fold over, in order. The RBF and PU transfers, smooth,
/// give their Jacobians in closed form; the blend's, and the map's in the band where a fixed or
/// handle region blends into the field, are taken by central differences of a tenth of the
/// finest cell.
///
/// Why a tenth: the blend is continuous but not smooth. Its weights have kinks where neighbor
/// sets change, and at points equidistant from five or more centers (the corners of a regular
/// lattice of cells) the normalized weights depend on the direction of approach, so the map
/// steps by up to the cells' misfit there. With a thousandth of a cell those steps read as huge
/// derivatives: 326 of the 2,690 vertices of the demo bar, all on cell corners, "folded" under
/// a plain lift. Space folds over at the scale of cells, which a tenth of one resolves.
pub fn check_foldovers<const D: usize>(
    warp: &impl Warp<D>,
    solution: &Solution<D>,
    samples: &[Vect<D>],
    warnings: &mut Vec<Said>,
) -> (usize, Vec<usize>) {
    let stride = samples.len().div_ceil(FOLDOVER_SAMPLES).max(1);
    let checked: Vec<Vect<D>> = samples.iter().step_by(stride).copied().collect();
    let h = 0.1 * solution.complex.grid.finest_size();
    let folded: Vec<usize> = foldovers(warp, &solution.complex.grid.origin, &checked, h)
        .into_iter()
        .map(|k| k * stride)
        .collect();
    if !folded.is_empty() {
        warnings.push(Said::from(format!(
            "the deformation folds space over at {} of {} samples checked (the Jacobian \
             determinant is not positive there): the shape passes through itself; a smaller \
             edit, or stiffer cells where it folds (a stiffness region), avoid it",
            folded.len(),
            checked.len()
        )));
    }
    (checked.len(), folded)
}

/// Checks that every coordinate of a chunk is finite.
pub(super) fn check_finite(path: &Path, chunk: &Chunk) -> Result<()> {
    match chunk
        .positions
        .iter()
        .position(|p| !p.iter().all(|v| v.is_finite()))
    {
        Some(i) => Err(Error::format(
            path,
            format!(
                "sample {} has a coordinate that is not a finite number",
                chunk.first + i as u64
            ),
        )),
        None => Ok(()),
    }
}

/// [`Error::Outside`] when `warp` refuses samples beyond its margin and met some.
pub(super) fn refuse_outside(input: &Path, warp: &FieldMap<3>) -> Result<()> {
    let tally = warp.outside();
    if warp.outside_policy() != Outside::Refuse || tally.count == 0 {
        return Ok(());
    }
    Err(Error::Outside {
        path: input.to_path_buf(),
        count: tally.count,
        margin: warp.margin(),
        farthest: tally.farthest,
        at: crate::human::point(
            (tally.at + warp.origin()).as_slice(),
            warp.margin() / 1000.0,
        ),
    })
}

/// Refuses a transfer's result that is not finite, before it is written: the last guard
/// against writing NaN (the solve, the spec and field files are checked before; a field whose
/// RBF frame was damaged to 5e-324 reached the output as NaN).
pub(crate) fn check_moved<const D: usize>(first: u64, moved: &[Vect<D>]) -> Result<()> {
    match moved.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        Some(i) => Err(Error::solver(format!(
            "the transfer moved sample {} to a position that is not finite",
            first + i as u64
        ))),
        None => Ok(()),
    }
}
