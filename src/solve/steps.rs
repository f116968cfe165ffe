//! How many load steps an edit takes (enough that no handle turns by more than a step's angle
//! and nothing moves by more than a step's share of the shape per step), where each step
//! starts ([`predict`]), and what it prescribes ([`prescribe`], [`targets_at`]).

use super::SolveParams;
use super::constraints::{Constraints, Role};
use crate::cells::CellComplex;
use crate::error::{Error, Result};
use crate::rigid::Motion;
use crate::rigid::{Dim, Rigid, Vect};

/// The number of load steps: enough that no handle turns by more than `max_step_degrees` and
/// no handle cell, pin or target moves by more than `max_step_fraction` of the extent per step,
/// relative to the fixed cells (or, without any, to the constraints' common motion: a shape
/// moved whole needs no steps). A spread of motions past [`MAX_TRAVEL`] extents is refused: it
/// tears the shape apart and would cost thousands of load steps (a control point sent 4e9 away
/// from a shape 2 wide, a unit or coordinate mistake).
pub(super) fn load_steps<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    params: &SolveParams,
) -> Result<usize>
where
    Dim<D>: Rigid<D>,
{
    let mut lo = Vect::<D>::repeat(f64::MAX);
    let mut hi = Vect::<D>::repeat(f64::MIN);
    for c in &complex.cells {
        lo = lo.inf(&(c.center.add_scalar(-c.half)));
        hi = hi.sup(&(c.center.add_scalar(c.half)));
    }
    let extent = (hi - lo).max().max(f64::MIN_POSITIVE);
    let mut turn = 0.0f64;
    // Every constrained motion with what it belongs to, for the message.
    let mut moves: Vec<(Vect<D>, String)> = Vec::new();
    for (k, h) in constraints.handles.iter().enumerate() {
        turn = turn.max(h.motion.turn.1.abs().to_degrees());
        let map = constraints.handle_map(k, 1.0);
        for (c, role) in constraints.roles.iter().enumerate() {
            if *role == Role::Handle(k as u32) {
                let x = complex.cells[c].center;
                moves.push((map.apply(&x) - x, crate::error::handle_named(k, h.line)));
            }
        }
    }
    for (k, p) in constraints.pins.iter().enumerate() {
        moves.push((p.to - p.point, format!("pin #{}", k + 1)));
    }
    for (k, t) in constraints
        .targets
        .iter()
        .enumerate()
        .filter(|(_, t)| t.weight > 0.0)
    {
        moves.push((t.to - t.from, format!("target #{}", k + 1)));
    }
    let fixed = constraints.roles.contains(&Role::Fixed);
    let (mut dlo, mut dhi) = match fixed {
        true => (Vect::<D>::zeros(), Vect::<D>::zeros()),
        false => (Vect::<D>::repeat(f64::MAX), Vect::<D>::repeat(f64::MIN)),
    };
    for (d, _) in &moves {
        dlo = dlo.inf(d);
        dhi = dhi.sup(d);
    }
    // How far each motion takes its cells from the fixed ones, or from the middle of the
    // motions when nothing is fixed.
    let reference = if fixed {
        Vect::<D>::zeros()
    } else {
        (dlo + dhi) * 0.5
    };
    let farthest = moves
        .iter()
        .map(|(d, what)| ((d - reference).norm(), what))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    let travel = farthest.map_or(0.0, |f| f.0);
    if travel > MAX_TRAVEL * extent {
        let farthest = farthest.map_or("a constraint", |f| f.1.as_str());
        return Err(Error::param(format!(
            "{farthest} of the edit spec moves {} relative to the rest of the edit, {:.0} times \
             the cells' extent ({}): more than {MAX_TRAVEL} times is refused (it tears the shape \
             apart); check the spec's units and coordinates",
            crate::human::length(travel, extent),
            travel / extent,
            crate::human::length(extent, extent),
        )));
    }
    let by_turn = (turn / params.max_step_degrees.max(1e-3)).ceil();
    let by_travel = (travel / (params.max_step_fraction.max(1e-6) * extent)).ceil();
    Ok(by_turn.max(by_travel).clamp(1.0, 1000.0) as usize)
}

/// The most the constraints' motions may spread, in extents of the cells (at most 100 load
/// steps of a quarter extent).
pub const MAX_TRAVEL: f64 = 25.0;

/// The predictor of a load step: every free or pinned cell turns on by `alpha` times the
/// rotation it took over the last step (from `before` to `motions`), and moves on likewise (the
/// caller then puts the free cells where the predicted rotations want them, by variable
/// projection).
/// Advancing only the handles leaves the cells between them where the last step ended, and a
/// step that starts there may end on another branch (a part twisted past a half turn untwists
/// the short way round).
pub(super) fn predict<const D: usize>(
    constraints: &Constraints<D>,
    motions: &mut [Motion<D>],
    before: &[Motion<D>],
    alpha: f64,
) where
    Dim<D>: Rigid<D>,
{
    for (c, role) in constraints.roles.iter().enumerate() {
        if matches!(role, Role::Free | Role::Pin(_)) {
            let m = motions[c];
            let (axis, angle) =
                <Dim<D> as Rigid<D>>::axis_angle_of(&(m.rot * before[c].rot.transpose()));
            let next = Motion {
                rot: <Dim<D> as Rigid<D>>::axis_angle(&axis, alpha * angle) * m.rot,
                pos: m.pos + (m.pos - before[c].pos) * alpha,
            };
            // A rotation whose axis rounding loses (a half turn) keeps the cell where it is.
            if next
                .rot
                .iter()
                .chain(next.pos.iter())
                .all(|v| v.is_finite())
            {
                motions[c] = next;
            }
        }
    }
}

/// Where the soft targets pull at load fraction `f`.
pub(super) fn targets_at<const D: usize>(constraints: &Constraints<D>, f: f64) -> Vec<Vect<D>> {
    constraints
        .targets
        .iter()
        .map(|t| t.from + (t.to - t.from) * f)
        .collect()
}

/// Sets the motions of fixed, rest and handle cells for load fraction `f`.
pub(super) fn prescribe<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    motions: &mut [Motion<D>],
    f: f64,
) where
    Dim<D>: Rigid<D>,
{
    let maps: Vec<_> = (0..constraints.handles.len())
        .map(|k| constraints.handle_map(k, f))
        .collect();
    for (c, role) in constraints.roles.iter().enumerate() {
        let center = &complex.cells[c].center;
        match role {
            Role::Fixed | Role::Rest => {
                motions[c] = constraints.prescribed_motion(None, center, f);
            }
            Role::Handle(k) => {
                motions[c] = constraints.prescribed_motion(Some(&maps[*k as usize]), center, f);
            }
            _ => {}
        }
    }
}
