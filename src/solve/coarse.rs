//! Coarse to fine: a large complex is solved first on its parents, and the fine solve starts
//! from that solution carried down, so that its Gauss-Newton iterations only correct.
//!
//! [`coarsen`](super::coarsen) merges sibling cells of one role into their parent, one level at
//! a time (cells along a region's border, and the cells of pins and targets, stay as they
//! are). The coarsest complex goes through the load steps from rest; every finer one starts at
//! full load from its parents' motions ([`prolong`]): a fine cell takes the rigid motion of
//! the coarse cell holding it. The coarse stages stop at a looser tolerance
//! ([`COARSE_TOLERANCE`]): their minimum is not the fine one, they only have to bring the
//! motions near it.
//!
//! A turn that a coarse stage gives way to (a part a coarse cell or two thick untwists sooner)
//! is solved from rest on the cells themselves, except a half turn still to be tried the other
//! way round, whose coarse refusal is final.
//!
//! The first iteration on the fine cells still moves corners by about half a cell on the
//! vegetation scans of BENCHMARKS.md: the fine minimum holds detail the parents could not.
//! Blending each fine cell's rotation with the parent's neighbors' (so that rotations do not
//! jump across a parent's face) lowered the fine start's energy by a third there and saved no
//! iteration: not kept.

use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::{Dim, Motion, Rigid};

use super::system::System;
use super::{
    CELLS_ADVICE, Constraints, SolveParams, SolverInfo, coarsen, from_rest, minimize_with,
    prescribe, targets_at, timed,
};

/// A complex is solved coarse to fine (automatically) from this many cells on. Below it a
/// solve takes a few tenths of a second anyway; from it on, the bends of
/// BENCHMARKS.md §3 (the paper's models at 2k-12k cells, the lowest 15 % fixed, the highest
/// turned 60° and lifted) converged 1.2-7.5 times faster coarse to fine in ten of twelve
/// runs, the dragon at 5.5k cells in 17 iterations where from rest it crept through 89, and
/// 1.2 times slower in the other two, easy bends.
pub const COARSE_FROM: usize = 2_000;

/// Automatic stages go on down to fewer than this many cells (one stage at least).
pub const COARSE_STAGE: usize = 20_000;

/// Coarse stages at most.
pub const MAX_COARSE_LEVELS: u8 = 3;

/// The energy tolerance of a coarse stage (its move tolerance is a hundred times the fine
/// one's: a tenth of a finest cell by default).
pub const COARSE_TOLERANCE: f64 = 1e-4;

/// How many coarse stages a solve of `cells` cells takes: `params.coarse_levels` where given,
/// else none under [`COARSE_FROM`] cells and from there enough that the coarsest has fewer
/// than [`COARSE_STAGE`] cells (one at least), assuming each stage keeps a quarter of them (a
/// scan's or a shell's cells have about four children, a volume's eight), and none with
/// refinement, whose rounds start from a coarse complex of their own.
pub(super) fn levels(cells: usize, params: &SolveParams) -> u8 {
    if let Some(levels) = params.coarse_levels {
        return levels;
    }
    if params.refine_strain.is_some() || params.refine_fraction.is_some() {
        return 0;
    }
    if cells < COARSE_FROM {
        return 0;
    }
    let mut levels = 1;
    let mut left = cells / 4;
    while left >= COARSE_STAGE && levels < MAX_COARSE_LEVELS {
        levels += 1;
        left /= 4;
    }
    levels
}

/// The solve of `complex` coarse to fine over `levels` coarse stages: the coarsest
/// ([`coarsen`] by `levels`) from rest through the load steps, each finer one (by one level
/// fewer, down to `complex` itself) from the last one's motions at full load. `None` where no
/// coarsening merges a cell, or where a coarse stage gives way to a turn
/// ([`Error::TurnNotHeld`]): the caller then solves from rest. For a handle marked in
/// `either_way` (a half turn still to be tried the other way round), the coarse stage's
/// refusal is the error. The returned
/// [`SolverInfo`] holds every stage's iterations (the load steps are the coarsest's).
#[allow(clippy::type_complexity)]
pub(super) fn coarse_to_fine<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    levels: u8,
    params: &SolveParams,
    budget: Budget,
    observer: &dyn Observer,
    either_way: &[bool],
) -> Result<Option<(System<D>, Vec<Motion<D>>, SolverInfo)>>
where
    Dim<D>: Rigid<D>,
{
    // A coarse stage's minimum is not the fine one: it only has to come near it (on the
    // vegetation scan at 2.5 m, stopping its 13.6k cells at a move of a tenth of a finest cell
    // instead of a hundredth saved one of their four iterations and none of the fine ones).
    let stage_params = SolveParams {
        tolerance: params.tolerance.max(COARSE_TOLERANCE),
        move_tolerance: 100.0 * params.move_tolerance,
        coarse_levels: Some(0),
        ..*params
    };
    let mut solved: Option<(CellComplex<D>, Vec<Motion<D>>, SolverInfo)> = None;
    for k in (1..=levels).rev() {
        let (parents, on_parents) = coarsen(complex, constraints, k);
        // A stage between the last one and the cells themselves, or none.
        let coarser = solved.as_ref().map_or(0, |s| s.0.len());
        if parents.len() >= complex.len() || parents.len() <= coarser {
            continue;
        }
        let at = (&parents, &on_parents);
        let done = match solved.take() {
            None => from_rest(at.0, at.1, &stage_params, budget, observer, &[])
                .map(|(_, motions, info)| (motions, info)),
            Some((coarse, motions, mut info)) => {
                let coarse = (&coarse, motions.as_slice());
                stage(at, coarse, &stage_params, budget, &mut info, observer)
                    .map(|(_, motions)| (motions, info))
            }
        };
        match done {
            Ok((motions, info)) => solved = Some((parents, motions, info)),
            Err(Error::TurnNotHeld(r)) if either_way.get(r.handle) == Some(&true) => {
                return Err(Error::TurnNotHeld(r));
            }
            // Coarse cells give way to a twist sooner (a part a cell or two thick): the cells
            // themselves are solved from rest, and say for themselves whether they hold it.
            Err(Error::TurnNotHeld(_)) => return Ok(None),
            Err(e) => return Err(e),
        }
    }
    let Some((coarse, motions, mut info)) = solved else {
        return Ok(None);
    };
    let at = (complex, constraints);
    let (system, motions) = stage(at, (&coarse, &motions), params, budget, &mut info, observer)?;
    info.cells_initial = complex.len();
    Ok(Some((system, motions, info)))
}

/// One finer stage: the cells of `at` start at the `coarse` solution carried down
/// ([`prolong`]; the free cells' positions the optimum for its rotations) and are minimized
/// at full load. Returns their system and motions; `info` gets the stage's iterations.
fn stage<const D: usize>(
    (complex, constraints): (&CellComplex<D>, &Constraints<D>),
    coarse: (&CellComplex<D>, &[Motion<D>]),
    params: &SolveParams,
    budget: Budget,
    info: &mut SolverInfo,
    observer: &dyn Observer,
) -> Result<(System<D>, Vec<Motion<D>>)>
where
    Dim<D>: Rigid<D>,
{
    let mut motions = prolong(coarse.0, coarse.1, complex);
    let mut system = timed(&mut info.seconds_symbolic, || {
        System::new(complex, constraints, params.method, budget, CELLS_ADVICE)
    })?;
    prescribe(complex, constraints, &mut motions, 1.0);
    let targets = targets_at(constraints, 1.0);
    system.project_positions(complex, constraints, &mut motions, &targets);
    observer.stage(&format!("solving {} cells", complex.len()), 1);
    let it = minimize_with(
        &mut system,
        complex,
        constraints,
        &mut motions,
        1.0,
        params,
        info,
        observer,
    )?;
    info.iterations_per_step.push(it);
    observer.advance(1);
    Ok((system, motions))
}

/// The cell of `coarse`, a coarsening of the complex of `cell`, that holds `cell` (itself or an
/// ancestor of it).
pub(super) fn holder<const D: usize>(
    coarse: &CellComplex<D>,
    cell: &crate::cells::Cell<D>,
) -> Option<usize> {
    std::iter::successors(Some(cell.key), |k| k.parent()).find_map(|k| coarse.find(&k))
}

/// The motions of `fine`'s cells from those of `coarse`, a coarsening of it: each fine cell
/// moves with the coarse cell that holds it (a cell kept as it was keeps its motion).
pub(super) fn prolong<const D: usize>(
    coarse: &CellComplex<D>,
    motions: &[Motion<D>],
    fine: &CellComplex<D>,
) -> Vec<Motion<D>>
where
    Dim<D>: Rigid<D>,
{
    fine.cells
        .iter()
        .map(|cell| match holder(coarse, cell) {
            Some(c) => {
                let (m, at) = (&motions[c], &coarse.cells[c].center);
                Motion {
                    rot: m.rot,
                    pos: m.apply(at, &cell.center),
                }
            }
            None => Motion::rest(&cell.center),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn automatic_levels_follow_the_cells() {
        let params = SolveParams::default();
        assert_eq!(levels(COARSE_FROM - 1, &params), 0);
        assert_eq!(levels(COARSE_FROM, &params), 1);
        assert_eq!(levels(4 * COARSE_STAGE - 1, &params), 1);
        assert_eq!(levels(4 * COARSE_STAGE, &params), 2);
        assert_eq!(levels(1_000_000_000, &params), MAX_COARSE_LEVELS);
        let given = SolveParams {
            coarse_levels: Some(2),
            ..params
        };
        assert_eq!(levels(10, &given), 2);
        let refining = SolveParams {
            refine_strain: Some(0.1),
            ..params
        };
        assert_eq!(levels(1_000_000, &refining), 0);
    }
}
