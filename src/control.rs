//! Control points after the solve: where each `[[target]]` point went, its residual, the RMSE,
//! and the leave-one-out check a surveyor uses to trust a rubber-sheeting.
//!
//! A control point's *got* is where the output puts its `from` (after snapping): the transfer's
//! value there, the same map the samples went through. Its *residual* is the distance from
//! there to where it was wanted, horizontally for a 2D control point (its height is free).
//!
//! The leave-one-out check solves again without each point in turn, starting from the solution
//! with all of them (Gauss-Newton on the same cells, no load steps, no refinement; the trend
//! fitted again to the others), and predicts the point by its cell's rigid motion and the
//! others' trend; the *prediction error* is that prediction's
//! distance from where the point was wanted. A small residual with a large prediction error is
//! a point the others do not support: a blunder, or a place that needs more control.

use serde::Serialize;

use crate::error::Result;
use crate::rigid::{Dim, Rigid, Vect};
use crate::solve::{self, Solution, SolveParams};
use crate::spec::EditSpec;

/// One control point after the solve.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ControlPoint {
    /// The point's name (the file's ID column, else `#k`).
    pub id: String,
    /// Where it was given (`gcp.csv line 9`).
    pub place: String,
    /// The point, after snapping (input coordinates).
    pub from: Vec<f64>,
    /// Where it was wanted (for a 2D control point, at its snapped height).
    pub wanted: Vec<f64>,
    /// Where the output puts it.
    pub got: Vec<f64>,
    /// `|got − wanted|` (horizontally for a 2D control point).
    pub residual: f64,
    /// How far snapping moved the point (0 when it was not snapped).
    pub snapped: f64,
    /// Whether the point pulls horizontally only.
    pub horizontal: bool,
    /// The leave-one-out prediction error (with `--check-gcp`; `None` when not asked for, or
    /// when nothing else constrains the point's part of the shape).
    pub left_out: Option<f64>,
}

/// The control points of `spec` solved in `solution`: `got[i]` is where the output puts the
/// `i`-th target's `from` (world coordinates, after snapping).
pub fn control_points<const D: usize>(
    spec: &EditSpec<D>,
    solution: &Solution<D>,
    got: &[Vect<D>],
) -> Vec<ControlPoint> {
    let origin = solution.constraints.origin;
    spec.targets
        .iter()
        .zip(&solution.constraints.targets)
        .zip(got)
        .map(|((t, local), got)| {
            let from = local.from + origin;
            let wanted = local.wanted + origin;
            let moved = t.pulled(from - t.from).norm();
            ControlPoint {
                id: t.id.clone(),
                place: t.place.clone(),
                from: from.iter().copied().collect(),
                wanted: wanted.iter().copied().collect(),
                got: got.iter().copied().collect(),
                residual: t.pulled(got - wanted).norm(),
                snapped: moved,
                horizontal: t.horizontal,
                left_out: None,
            }
        })
        .collect()
}

/// The targets' `from` points in world coordinates (after snapping), in the spec's order.
pub fn from_points<const D: usize>(solution: &Solution<D>) -> Vec<Vect<D>> {
    let origin = solution.constraints.origin;
    solution
        .constraints
        .targets
        .iter()
        .map(|t| t.from + origin)
        .collect()
}

/// The root mean square of the residuals (`None` without control points).
pub fn rmse(points: &[ControlPoint]) -> Option<f64> {
    rms(points.iter().map(|p| p.residual))
}

/// The root mean square of the leave-one-out prediction errors that were computed.
pub fn rmse_left_out(points: &[ControlPoint]) -> Option<f64> {
    rms(points.iter().filter_map(|p| p.left_out))
}

fn rms(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    (n > 0).then(|| (sum / n as f64).sqrt())
}

/// Fills in each control point's leave-one-out prediction error (module docs). The cells are
/// those of `solution`; each solve starts from its motions and stays within the memory `budget`.
pub fn leave_one_out<const D: usize>(
    spec: &EditSpec<D>,
    solution: &Solution<D>,
    params: &SolveParams,
    budget: crate::memory::Budget,
    points: &mut [ControlPoint],
    observer: &dyn crate::progress::Observer,
) -> Result<()>
where
    Dim<D>: Rigid<D>,
{
    let complex = &solution.complex;
    let constraints = &solution.constraints;
    let params = SolveParams {
        refine_strain: None,
        refine_fraction: None,
        coarsen_levels: 0,
        ..*params
    };
    observer.stage("leave-one-out", points.len() as u64);
    for (i, point) in points.iter_mut().enumerate() {
        if let Some(without) = constraints.without_target(complex, i) {
            let motions =
                solve::minimize_from(complex, &without, &solution.motions, &params, budget)?;
            let t = &constraints.targets[i];
            let c = t.cell as usize;
            let moved = motions[c].apply(&complex.cells[c].center, &t.from);
            // The others' trend, refitted without the point, then the cells' motion.
            let predicted = without.trend.apply(&moved);
            point.left_out = Some(spec.targets[i].pulled(predicted - t.wanted).norm());
        }
        observer.advance(1);
        crate::progress::check(observer)?;
    }
    observer.finish();
    Ok(())
}

/// The control points as a table for people: the `rows` largest residuals (all with
/// `usize::MAX`), then the RMSE (and the leave-one-out RMSE when computed). Empty without
/// control points.
pub fn table(points: &[ControlPoint], rows: usize) -> String {
    use std::fmt::Write;
    let Some(rmse) = rmse(points) else {
        return String::new();
    };
    let mut order: Vec<&ControlPoint> = points.iter().collect();
    // Largest residual first as printed (to 0.1 mm), then the largest leave-one-out error:
    // under a spline trend every residual is zero and the check is what tells.
    let printed = |p: &ControlPoint| (p.residual * 1e4).round();
    order.sort_by(|a, b| {
        printed(b).total_cmp(&printed(a)).then(
            b.left_out
                .unwrap_or(0.0)
                .total_cmp(&a.left_out.unwrap_or(0.0)),
        )
    });
    let loo = points.iter().any(|p| p.left_out.is_some());
    let width = order.iter().map(|p| p.id.len()).max().unwrap_or(2).max(2);
    let num = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut s = String::new();
    let shown = rows.min(order.len());
    let _ = writeln!(
        s,
        "control points: {} (largest residuals first{}{})",
        points.len(),
        if loo { ", then left out" } else { "" },
        if shown < order.len() {
            format!("; {shown} shown, all in --report")
        } else {
            String::new()
        }
    );
    let _ = writeln!(
        s,
        "  {:<width$}  {:>10}  {:>10}{}  from -> wanted (got)",
        "id",
        "residual",
        "snapped",
        if loo { "   left out" } else { "" },
    );
    for p in order.iter().take(shown) {
        let _ = writeln!(
            s,
            "  {:<width$}  {:>10.4}  {:>10.4}{}  [{}] -> [{}] ([{}]){}",
            p.id,
            p.residual,
            p.snapped,
            match (loo, p.left_out) {
                (true, Some(v)) => format!("  {v:>10.4}"),
                (true, None) => format!("  {:>10}", "-"),
                _ => String::new(),
            },
            num(&p.from),
            num(&p.wanted),
            num(&p.got),
            if p.horizontal { " 2D" } else { "" },
        );
    }
    let _ = write!(s, "  RMSE {rmse:.4}");
    if let Some(l) = rmse_left_out(points) {
        let _ = write!(s, ", leave-one-out RMSE {l:.4}");
    }
    s
}
