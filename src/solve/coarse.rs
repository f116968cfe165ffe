//! Coarse to fine: a large complex is solved first on its parents, and the fine solve starts
//! from that solution carried down, so that its Gauss-Newton iterations only correct.
//!
//! [`coarsen_stage`](super::coarsen_stage) merges sibling cells of one role into their parent, one level at
//! a time (cells along a region's border, and the cells of pins and targets, stay as they
//! are). The coarsest complex goes through the load steps from rest; every finer one starts at
//! full load from its parents' motions ([`prolong`]): a fine cell takes the rigid motion of
//! the coarse cell holding it. The coarse stages stop at a looser tolerance
//! ([`COARSE_TOLERANCE`]): their minimum is not the fine one, they only have to bring the
//! motions near it.
//!
//! **A turn the coarse cells give way under** ([`Error::TurnNotHeld`]) is refused there, before
//! the cells themselves are solved, where two cell sizes agree that the shape cannot hold it
//! ([`confirmed`]): the turn asked lies more than [`COARSE_REFUSAL_MARGIN`] past the turn the
//! coarse cells held, and cells one level coarser give way to it too, no more than that
//! sooner. Else the cells themselves are solved from rest and say for themselves whether they
//! hold it. Cells that resolve the part give way at about the same turn whatever their size
//! (measured through the load steps, in release builds):
//!
//! | shape, turn | cell size | cells: held | coarse cells: held |
//! |---|---|---|---|
//! | bar 2 × 1 × 1, one end twisted 360° | 0.125 | 1,632: 217° | – |
//! | | 0.0625 | 7,320: 212° | 2,126: 225° |
//! | | 0.05 | 9,210: 240° | 1,823: 240° |
//! | dragon (11k vertices), head twisted 360° about its neck | 4.85 | 3,342: 210° | 824: 188° |
//! | | 3 | 10,245: 212° | 2,216: 197° |
//! | dragon, head bent −180° about its neck | 4.85 | 3,342: −163° | 824: −163° |
//! | bust (`mannequin.ply`), head bent −180° | 0.047 | 4,200: −174° | 1,049: −174° |
//!
//! Cells that do not resolve the part give way much sooner: the 10 × 1 × 1 bar at cells of
//! 0.25 twisted by 720° holds, but gives way past 570° on its parents' parents (cells of 1, one
//! across the bar). That is why one coarse stage's refusal alone is not trusted (it refused the
//! bar's 720°); the check on coarser cells costs a quarter of the coarse stage's load steps.
//! Refusing from the coarse cells refuses a whole turn of the short bar at cells of 0.05 after
//! 2 s instead of 28 s, and the dragon's at cells of 3 after 3 s instead of 33 s (BENCHMARKS.md,
//! "Half turns, and refusing early"). Extrapolating the held turn from the first load steps was
//! not an option: the turn the cells carry follows the handle's exactly until the step where
//! the shape snaps back, and the energy gives no warning of it. The cells themselves start from
//! rest, not from where the coarse cells gave way, which would carry the coarse cells' failure
//! down (BENCHMARKS.md §13). A turn refused within
//! the margin (the bust's head bent −180°, held to −174° on coarse and fine cells alike) still
//! costs the solve of the cells themselves up to where they give way.
//!
//! The first iteration on the fine cells still moves corners by about half a cell on the
//! vegetation scans of BENCHMARKS.md: the fine minimum holds detail the parents could not. Each
//! fine cell starts from its parent's motion as it is (smoother starts measured saved no
//! iteration; BENCHMARKS.md §13).
//!
//! **A finer stage that loses the turn.** Coarse cells may carry a turn that the cells
//! themselves do not hold: the dragon's body (`dragon_11k_binary.ply`, fixed below y = −720,
//! the part above −620 turned about y) twisted by 320° at cells of 3 is held by its 2,318
//! coarse cells (they give way past 345°), and its 10,245 cells, started there, untwisted to
//! −40°. A finer stage that carries a turn more than a quarter turn off the one asked
//! (`turns::lost_turn`) is therefore stopped there and given up like an unconfirmed refusal:
//! the cells are solved from rest through the load steps, and hold the turn or refuse it (the
//! dragon: refused past 311°; BENCHMARKS.md, "A finer stage that loses the turn").
//!
//! **Newton from the first iteration.** A finer stage starts at full load, where no handle
//! jumps, so its first iteration takes Newton's whole curvature, not Gauss-Newton's matrix
//! ([`SolveParams::newton_at_start`]). Where a bend leaves the pairs' residuals large this is
//! what the first step needs: the bent plate of BENCHMARKS.md §3 (313k cells, turned 10°) went
//! from its carried-down start to 96.06 by a Gauss-Newton step and to 87.54 by Newton's (the
//! minimum 87.17), and the Gauss-Newton step's multilevel hierarchy, refreshed for the Newton
//! steps after it, missed their curvature (34 conjugate-gradient iterations, then built again):
//! five iterations and 47 s became four and 34 s. Where the first Gauss-Newton step already
//! did as well (the 1 km strips, the 10M-point terrain, the paper's models) the iterations
//! are the same.

use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::{Dim, Motion, Rigid};
use rayon::prelude::*;

use super::system::System;
use super::turns::{self, TurnGauge, TurnRefusal};
use super::{
    Constraints, SolveParams, SolverInfo, cells_advice, coarsen_stage, from_rest, minimize_watched,
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

/// A coarse stage's refusal of a turn is the solve's where the turn asked is more than this
/// many degrees past the turn the coarse cells held, and cells one level coarser give way no
/// more than this sooner (the module docs: cells that resolve the part gave way within 45° of
/// each other).
pub(crate) const COARSE_REFUSAL_MARGIN: f64 = 60.0;

/// The energy tolerance of a coarse stage (its move tolerance is a hundred times the fine
/// one's: a tenth of a finest cell by default).
pub(crate) const COARSE_TOLERANCE: f64 = 1e-4;

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
/// coarsening merges a cell, where a coarse stage gives way to a turn
/// ([`Error::TurnNotHeld`]) that is not [`confirmed`], or where a finer stage loses a turn its
/// parents carried ([`stage`]): the caller then solves from rest. A
/// confirmed refusal, or one of a handle marked in `either_way` (a half turn still to be tried
/// the other way round), is the error. The returned
/// [`SolverInfo`] holds every stage's iterations (the load steps are the coarsest's) and
/// `fits`, what a forecast found of the stages ([`SolverInfo::newton_fits`]).
#[allow(clippy::type_complexity)]
pub(super) fn coarse_to_fine<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    levels: u8,
    params: &SolveParams,
    budget: Budget,
    observer: &dyn Observer,
    (either_way, fits): (&[bool], &[(usize, bool)]),
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
        let (parents, on_parents) = coarsen_stage(complex, constraints, k);
        // A stage between the last one and the cells themselves, or none.
        let coarser = solved.as_ref().map_or(0, |s| s.0.len());
        if parents.len() >= complex.len() || parents.len() <= coarser {
            continue;
        }
        let at = (&parents, &on_parents);
        let done = match solved.take() {
            None => Some(
                from_rest(at.0, at.1, &stage_params, budget, observer, (&[], fits))
                    .map(|(_, motions, info)| (motions, info)),
            ),
            Some((coarse, motions, mut info)) => {
                let coarse = (&coarse, motions.as_slice());
                stage(at, coarse, &stage_params, budget, &mut info, observer)
                    .map(|staged| staged.map(|(_, motions)| (motions, info)))
                    .transpose()
            }
        };
        // A stage that lost a turn its parents carried: the cells are solved from rest.
        let Some(done) = done else {
            return Ok(None);
        };
        match done {
            Ok((motions, info)) => solved = Some((parents, motions, info)),
            Err(Error::TurnNotHeld(r)) => {
                let coarse = (parents.len(), k, &r);
                let at = (complex, constraints);
                // A soft inside by default is given up for a solid one at once, on these cells
                // as on the caller's (`SolveParams::soft_inside`).
                let refused = either_way.get(r.handle) == Some(&true)
                    || params.soft_inside.is_some()
                    || confirmed(at, coarse, &stage_params, budget, observer)?;
                // Else the cells themselves are solved from rest, and say for themselves
                // whether they hold the turn.
                return match refused {
                    true => Err(Error::TurnNotHeld(r)),
                    false => Ok(None),
                };
            }
            Err(e) => return Err(e),
        }
    }
    let Some((coarse, motions, mut info)) = solved else {
        return Ok(None);
    };
    let at = (complex, constraints);
    let staged = stage(at, (&coarse, &motions), params, budget, &mut info, observer)?;
    Ok(staged.map(|(system, motions)| {
        info.cells_initial = complex.len();
        (system, motions, info)
    }))
}

/// Whether the refusal `r` of the cells of `at` coarsened by `k` levels (`cells` of them) is the
/// solve's: the turn asked lies more than [`COARSE_REFUSAL_MARGIN`] past the turn they held,
/// and the cells coarsened by one level more give way to it too, no more than that sooner — two
/// cell sizes agree, so the cells' size does not decide where the shape gives way (where the
/// coarser cells give way much sooner, or cannot be merged further, it may).
fn confirmed<const D: usize>(
    at: (&CellComplex<D>, &Constraints<D>),
    (cells, k, r): (usize, u8, &TurnRefusal),
    params: &SolveParams,
    budget: Budget,
    observer: &dyn Observer,
) -> Result<bool>
where
    Dim<D>: Rigid<D>,
{
    if r.asked_degrees.abs() - r.held_degrees.abs() <= COARSE_REFUSAL_MARGIN {
        return Ok(false);
    }
    let (coarser, on_coarser) = coarsen_stage(at.0, at.1, k + 1);
    if coarser.len() >= cells {
        return Ok(false);
    }
    let checking = Checking(observer, coarser.len());
    match from_rest(&coarser, &on_coarser, params, budget, &checking, (&[], &[])) {
        Err(Error::TurnNotHeld(c)) => Ok(c.handle == r.handle
            && c.held_degrees.abs() >= r.held_degrees.abs() - COARSE_REFUSAL_MARGIN),
        Ok(_) => Ok(false),
        Err(e) => Err(e),
    }
}

/// The observer of [`confirmed`]'s load steps, which names their stage for what it does.
struct Checking<'a>(&'a dyn Observer, usize);

impl Observer for Checking<'_> {
    fn stage(&self, _name: &str, len: u64) {
        let name = format!(
            "checking where the shape gives way on {} coarser cells",
            self.1
        );
        self.0.stage(&name, len);
    }
    fn advance(&self, n: u64) {
        self.0.advance(n);
    }
    fn message(&self, text: &str) {
        self.0.message(text);
    }
    fn finish(&self) {
        self.0.finish();
    }
    fn cancelled(&self) -> bool {
        self.0.cancelled()
    }
}

/// One finer stage: the cells of `at` start at the `coarse` solution carried down
/// ([`prolong`]; the free cells' positions the optimum for its rotations) and are minimized
/// at full load. Returns their system and motions, or `None` where they lost a turn their
/// parents carried (some turning handle's turn carried more than a quarter turn off the turn
/// asked, `turns::lost_turn` at full load); `info` gets the stage's iterations.
fn stage<const D: usize>(
    (complex, constraints): (&CellComplex<D>, &Constraints<D>),
    coarse: (&CellComplex<D>, &[Motion<D>]),
    params: &SolveParams,
    budget: Budget,
    info: &mut SolverInfo,
    observer: &dyn Observer,
) -> Result<Option<(System<D>, Vec<Motion<D>>)>>
where
    Dim<D>: Rigid<D>,
{
    let (mut system, mut motions) =
        carried_down((complex, constraints), coarse, params, budget, info)?;
    observer.stage(&format!("solving {} cells", complex.len()), 1);
    // The cells start at full load, where their parents' minimum puts them: near their own,
    // with no handle jumping, so Newton's curvature is taken from the first iteration
    // ([`SolveParams::newton_at_start`]; the module docs say what it saved).
    let params = &SolveParams {
        newton_at_start: true,
        ..*params
    };
    // A stage that loses a turn stops there: the iterations that would untwist the part on
    // (27 of them, 7.7 s, on the dragon of the module docs) are not spent.
    let gauge = turns::turning(constraints)
        .next()
        .map(|_| TurnGauge::new(complex));
    let untwisted = |motions: &[Motion<D>]| {
        gauge
            .as_ref()
            .and_then(|gauge| turns::lost_turn(gauge, constraints, motions, 1.0))
            .is_some()
    };
    let it = minimize_watched(
        &mut system,
        (complex, constraints),
        &mut motions,
        1.0,
        (params, &untwisted),
        info,
        observer,
    )?;
    info.iterations_per_step.push(it);
    observer.advance(1);
    if untwisted(&motions) {
        return Ok(None);
    }
    Ok(Some((system, motions)))
}

/// A finer stage's start: the system of the cells of `at`, and their motions carried down from
/// the `coarse` solution ([`prolong`]) at full load, the free cells' positions the optimum for
/// their rotations.
fn carried_down<const D: usize>(
    (complex, constraints): (&CellComplex<D>, &Constraints<D>),
    coarse: (&CellComplex<D>, &[Motion<D>]),
    params: &SolveParams,
    budget: Budget,
    info: &mut SolverInfo,
) -> Result<(System<D>, Vec<Motion<D>>)>
where
    Dim<D>: Rigid<D>,
{
    let mut motions = prolong(coarse.0, coarse.1, complex);
    let system = timed(&mut info.seconds_symbolic, || {
        System::new(complex, constraints, params, budget, &cells_advice())
    })?;
    prescribe(complex, constraints, &mut motions, 1.0);
    let targets = targets_at(constraints, 1.0);
    system.project_positions(complex, constraints, &mut motions, &targets)?;
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
    prolong_held(coarse, motions, fine, &holders(coarse, fine))
}

/// For each of `fine`'s cells, the cell of `coarse` (a coarsening of it) that holds it.
pub(super) fn holders<const D: usize>(
    coarse: &CellComplex<D>,
    fine: &CellComplex<D>,
) -> Vec<Option<u32>> {
    fine.cells
        .par_iter()
        .map(|cell| holder(coarse, cell).map(|c| c as u32))
        .collect()
}

/// [`prolong`] with the `holders` of `fine`'s cells known (a drag's stage keeps them).
pub(super) fn prolong_held<const D: usize>(
    coarse: &CellComplex<D>,
    motions: &[Motion<D>],
    fine: &CellComplex<D>,
    holders: &[Option<u32>],
) -> Vec<Motion<D>>
where
    Dim<D>: Rigid<D>,
{
    fine.cells
        .par_iter()
        .zip(holders)
        .map(|(cell, held)| match held {
            Some(c) => {
                let (m, at) = (&motions[*c as usize], &coarse.cells[*c as usize].center);
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
    use crate::rigid::Vect;

    /// A solid block 2 × 1 × 1 in cells of 0.25, the cells below x = 0.3 fixed and those past
    /// 1.7 turned by `degrees` about the block's axis.
    fn short_bar(degrees: f64) -> (CellComplex<3>, Constraints<3>) {
        let pts: Vec<Vect<3>> = (0..=40)
            .flat_map(|i| (0..=20).flat_map(move |j| (0..=20).map(move |k| (i, j, k))))
            .map(|(i, j, k)| Vect::<3>::new(i as f64, j as f64, k as f64) * 0.05)
            .collect();
        let text = format!(
            "[[fixed]]\nbox = {{ min = [-1, -1, -1], max = [0.3, 2, 2] }}\n\
             [[handle]]\nbox = {{ min = [1.7, -1, -1], max = [3, 2, 2] }}\n\
             rotate = {{ axis = [1, 0, 0], degrees = {degrees} }}\npivot = [2, 0.5, 0.5]\n"
        );
        super::super::turns::tests::edited(&pts, 0.25, &text)
    }

    /// A finer stage that starts where its parents carry a turn the cells cannot hold, and
    /// untwists, is no solution (`None`: the caller solves the cells from rest), and stops at
    /// the first iteration that loses the turn. The same start at a turn they hold is a
    /// solution.
    #[test]
    fn a_finer_stage_that_loses_the_turn_is_given_up() {
        for (degrees, held) in [(60.0, true), (400.0, false)] {
            let (complex, constraints) = short_bar(degrees);
            let (parents, on_parents) = coarsen_stage(&complex, &constraints, 1);
            assert!(parents.len() < complex.len());
            // The parents carry the turn evenly along the free span.
            let origin = on_parents.origin;
            let motions: Vec<Motion<3>> = parents
                .cells
                .iter()
                .map(|c| {
                    let along = ((c.center.x + origin.x - 0.3) / 1.4).clamp(0.0, 1.0);
                    let rot = <Dim<3> as Rigid<3>>::axis_angle(
                        &Vect::<3>::x(),
                        (degrees * along).to_radians(),
                    );
                    // The point of the block's axis level with the cell.
                    let on_axis = Vect::<3>::new(c.center.x, 0.5 - origin.y, 0.5 - origin.z);
                    Motion {
                        rot,
                        pos: on_axis + rot * (c.center - on_axis),
                    }
                })
                .collect();
            let mut info = SolverInfo::default();
            let staged = stage(
                (&complex, &constraints),
                (&parents, &motions),
                &SolveParams::default(),
                Budget::default(),
                &mut info,
                &crate::progress::Silent,
            )
            .unwrap();
            assert_eq!(staged.is_some(), held, "{degrees}°");
            if held {
                continue;
            }
            // Unwatched, the same start iterates on to the untwisted minimum.
            let params = SolveParams {
                newton_at_start: true,
                ..Default::default()
            };
            let mut whole = SolverInfo::default();
            let (mut system, mut start) = carried_down(
                (&complex, &constraints),
                (&parents, &motions),
                &params,
                Budget::default(),
                &mut whole,
            )
            .unwrap();
            let unwatched = super::super::minimize_with(
                &mut system,
                &complex,
                &constraints,
                &mut start,
                1.0,
                &params,
                &mut whole,
                &crate::progress::Silent,
            )
            .unwrap();
            let watched = info.iterations_per_step[0];
            assert!(watched < unwatched, "{watched} of {unwatched} iterations");
        }
    }

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
