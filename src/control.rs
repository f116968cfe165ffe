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
    /// A checkpoint: left out of the solve, scored apart ([`check_accuracy`]).
    pub check: bool,
    /// An exact control point (`exact = true`): its cell is pinned to it.
    pub exact: bool,
}

/// The checkpoints' accuracy, as ASPRS (2014) and the NSSDA state it: the RMSE per axis,
/// horizontally (`RMSE_r = √(RMSE_x² + RMSE_y²)`) and in height, and the accuracy at 95 %
/// confidence, `1.7308 × RMSE_r` and `1.96 × RMSE_z`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CheckAccuracy {
    /// Checkpoints scored.
    pub count: usize,
    /// RMSE in x.
    pub rmse_x: f64,
    /// RMSE in y.
    pub rmse_y: f64,
    /// Horizontal RMSE.
    pub rmse_r: f64,
    /// RMSE in height, over the 3D checkpoints (`None` without any).
    pub rmse_z: Option<f64>,
    /// Horizontal accuracy at 95 % confidence.
    pub accuracy_r_95: f64,
    /// Vertical accuracy at 95 % confidence.
    pub accuracy_z_95: Option<f64>,
}

/// The checkpoints' accuracy (`None` without checkpoints).
pub fn check_accuracy(points: &[ControlPoint]) -> Option<CheckAccuracy> {
    let checks: Vec<&ControlPoint> = points.iter().filter(|p| p.check).collect();
    let axis = |a: usize| rms(checks.iter().map(|p| p.got[a] - p.wanted[a]));
    let (rmse_x, rmse_y) = (axis(0)?, axis(1)?);
    let rmse_z = rms(checks
        .iter()
        .filter(|p| !p.horizontal && p.got.len() == 3)
        .map(|p| p.got[2] - p.wanted[2]));
    let rmse_r = rmse_x.hypot(rmse_y);
    Some(CheckAccuracy {
        count: checks.len(),
        rmse_x,
        rmse_y,
        rmse_r,
        rmse_z,
        accuracy_r_95: 1.7308 * rmse_r,
        accuracy_z_95: rmse_z.map(|z| 1.96 * z),
    })
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
                check: t.check,
                exact: t.exact && !t.check,
            }
        })
        .collect()
}

/// `points` with `got` as the output stores it (`written`, one per point: rounded to the
/// output's frame or precision) and their residuals measured from there, as a reader of the
/// output would measure them.
pub fn as_written<const D: usize>(points: &mut [ControlPoint], written: &[Vect<D>]) {
    for (p, w) in points.iter_mut().zip(written) {
        p.got = w.iter().copied().collect();
        let along = p.got.len() - usize::from(p.horizontal);
        p.residual = (0..along)
            .map(|a| (p.got[a] - p.wanted[a]).powi(2))
            .sum::<f64>()
            .sqrt();
    }
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

/// The root mean square of the control points' residuals, checkpoints left out (`None`
/// without control points).
pub fn rmse(points: &[ControlPoint]) -> Option<f64> {
    rms(points.iter().filter(|p| !p.check).map(|p| p.residual))
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
        if point.check {
            // A checkpoint is already left out.
            observer.advance(1);
            continue;
        }
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
        crate::progress::stop_if_cancelled(observer)?;
    }
    observer.finish();
    Ok(())
}

/// The control points as a table for people: the `rows` largest residuals (all with
/// `usize::MAX`; checkpoints after the control points), then the RMSE (and the leave-one-out
/// RMSE when computed), then the checkpoints' accuracy; `rounding` says what the points were
/// rounded to as written ([`as_written`]). Empty without control points.
pub fn table(points: &[ControlPoint], rows: usize, rounding: Option<&str>) -> String {
    use std::fmt::Write;
    let Some(rmse) = rmse(points) else {
        return String::new();
    };
    let mut order: Vec<&ControlPoint> = points.iter().collect();
    // Largest residual first as printed (to 0.1 mm), then the largest leave-one-out error:
    // under a spline trend every residual is zero and the check is what tells.
    let printed = |p: &ControlPoint| (p.residual * 1e4).round();
    // Checkpoints after the control points.
    order.sort_by(|a, b| {
        a.check
            .cmp(&b.check)
            .then(printed(b).total_cmp(&printed(a)))
            .then(
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
    let checks = points.iter().filter(|p| p.check).count();
    let controls = points.len() - checks;
    // The largest control points' rows, and every checkpoint's.
    let shown = rows.min(controls);
    let _ = writeln!(
        s,
        "control points: {controls}{} ({}largest residuals first{}{})",
        if checks > 0 {
            format!(", checkpoints: {checks}")
        } else {
            String::new()
        },
        match rounding {
            Some(r) => format!("residuals as written, to {r}; "),
            None => String::new(),
        },
        if loo { ", then left out" } else { "" },
        if shown < controls {
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
    for p in order.iter().take(shown).chain(&order[controls..]) {
        let _ = writeln!(
            s,
            "  {:<width$}  {:>10.4}  {:>10.4}{}  [{}] -> [{}] ([{}]){}{}{}",
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
            if p.check { " check" } else { "" },
            if p.exact { " exact" } else { "" },
        );
    }
    let _ = write!(s, "  RMSE {rmse:.4}");
    if let Some(l) = rmse_left_out(points) {
        let _ = write!(s, ", leave-one-out RMSE {l:.4}");
    }
    if let Some(a) = check_accuracy(points) {
        let _ = write!(
            s,
            "\ncheckpoints: {} (not solved for): RMSE x {:.4}, y {:.4}, horizontal {:.4}",
            a.count, a.rmse_x, a.rmse_y, a.rmse_r
        );
        if let Some(z) = a.rmse_z {
            let _ = write!(s, ", height {z:.4}");
        }
        let _ = write!(
            s,
            "\n  accuracy at 95 % (ASPRS, NSSDA): horizontal {:.4}",
            a.accuracy_r_95
        );
        if let Some(z) = a.accuracy_z_95 {
            let _ = write!(s, ", vertical {z:.4}");
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(check: bool, horizontal: bool, error: [f64; 3]) -> ControlPoint {
        ControlPoint {
            id: "C".into(),
            place: "gcp.csv line 2".into(),
            from: vec![0.0; 3],
            wanted: vec![10.0, 20.0, 30.0],
            got: vec![10.0 + error[0], 20.0 + error[1], 30.0 + error[2]],
            residual: error[0].abs(),
            snapped: 0.0,
            horizontal,
            left_out: None,
            check,
            exact: false,
        }
    }

    /// ASPRS and the NSSDA: RMSE per axis over the checkpoints only, heights over the 3D
    /// ones, and 1.7308 × RMSE_r, 1.96 × RMSE_z at 95 %.
    #[test]
    fn checkpoints_score_as_asprs_states() {
        let points = [
            point(false, false, [9.0, 9.0, 9.0]),
            point(true, false, [0.03, 0.0, 0.1]),
            point(true, false, [-0.03, 0.04, -0.1]),
            point(true, true, [0.0, 0.04, 5.0]),
        ];
        let a = check_accuracy(&points).unwrap();
        assert_eq!(a.count, 3);
        assert!((a.rmse_x - (0.0018f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((a.rmse_y - (0.0032f64 / 3.0).sqrt()).abs() < 1e-12);
        assert!((a.rmse_r - a.rmse_x.hypot(a.rmse_y)).abs() < 1e-15);
        assert!(
            (a.rmse_z.unwrap() - 0.1).abs() < 1e-12,
            "the 2D checkpoint's height is free"
        );
        assert!((a.accuracy_r_95 - 1.7308 * a.rmse_r).abs() < 1e-15);
        assert!((a.accuracy_z_95.unwrap() - 0.196).abs() < 1e-12);
        assert!(check_accuracy(&points[..1]).is_none());
        assert_eq!(
            rmse(&points),
            Some(9.0),
            "checkpoints are not in the control points' RMSE"
        );
    }
}
