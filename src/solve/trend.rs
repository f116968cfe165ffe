//! The control points' global trend (`trend` in the edit spec): a map `T` fitted to all of them
//! by weighted least squares, which carries what is global — a datum shift, a rotation, a
//! scale, a shear or a tilt, the motions that rigid cells resist by design — so that the cells
//! carry only what is local.
//!
//! The edit's map is `T ∘ F`. The cells solve `F` with each control point wanting `T⁻¹` of its
//! destination, the fixed and resting cells following `T⁻¹` and each handle's cells `T⁻¹ ∘ H`;
//! after `T`, fixed samples are where they were and handle samples where their maps send them,
//! exactly, because the exact layer holds the final maps (identity, `H`) and applies `T` to the
//! transfer's values only ([`crate::field::Field::trend`]). Where there is no control point
//! (no trend, or `trend = "none"`), `T` is the identity and nothing changes.
//!
//! 2D control points (`x, y → X, Y`) fit the horizontal rows only: the height row stays the
//! identity unless 3D points fit it. A direction the points do not span (points on a line; for
//! an affine trend, the heights of points on flat ground) keeps the identity: each row's fit is
//! pulled toward the identity's by a millionth of the points' own spread, which moves nothing
//! that the points determine.

use nalgebra::DMatrix;

use crate::rigid::{Affine, Mat, Vect};
use crate::spec::Trend;

/// A control point as the trend sees it (local coordinates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrendPoint<const D: usize> {
    /// The point.
    pub from: Vect<D>,
    /// Where it is wanted.
    pub to: Vect<D>,
    /// Its weight.
    pub weight: f64,
    /// A 2D point: it says nothing of the height (the last coordinate).
    pub horizontal: bool,
}

impl<const D: usize> TrendPoint<D> {
    /// Whether the point has a say in output coordinate `r`.
    fn fits(&self, r: usize) -> bool {
        !(self.horizontal && r == D - 1) && self.weight > 0.0
    }
}

/// The trend of `kind` through `points` (the identity without points, or for [`Trend::None`]).
pub fn fit<const D: usize>(kind: Trend, points: &[TrendPoint<D>]) -> Affine<D> {
    match kind {
        Trend::None => Affine::identity(),
        Trend::Shift => shift(points),
        Trend::Similarity => similarity(points),
        Trend::Affine => affine(points),
    }
}

/// Each row's weighted mean motion.
fn shift<const D: usize>(points: &[TrendPoint<D>]) -> Affine<D> {
    let mut out = Affine::identity();
    for r in 0..D {
        let (sum, weight) = points
            .iter()
            .filter(|p| p.fits(r))
            .fold((0.0, 0.0), |(s, w), p| {
                (s + p.weight * (p.to[r] - p.from[r]), w + p.weight)
            });
        if weight > 0.0 {
            out.translation[r] = sum / weight;
        }
    }
    out
}

/// Each row by weighted least squares, pulled toward the identity's row by a millionth of the
/// points' spread.
fn affine<const D: usize>(points: &[TrendPoint<D>]) -> Affine<D> {
    let mut out = Affine::identity();
    for r in 0..D {
        let used: Vec<&TrendPoint<D>> = points.iter().filter(|p| p.fits(r)).collect();
        let weight: f64 = used.iter().map(|p| p.weight).sum();
        if used.is_empty() || weight <= 0.0 {
            continue;
        }
        let center = used.iter().fold(Vect::<D>::zeros(), |s, p| s + p.from * p.weight) / weight;
        let wanted = used.iter().map(|p| p.weight * p.to[r]).sum::<f64>() / weight;
        let mut spread = Mat::<D>::zeros();
        let mut pull = Vect::<D>::zeros();
        for p in &used {
            let x = p.from - center;
            spread += x * x.transpose() * p.weight;
            pull += x * (p.weight * (p.to[r] - wanted));
        }
        let mut row = Vect::<D>::zeros();
        row[r] = 1.0;
        let lambda = 1e-6 * spread.trace();
        if lambda > 0.0 && lambda.is_finite() {
            let system = spread + Mat::<D>::identity() * lambda;
            if let Some(solved) = system.cholesky().map(|c| c.solve(&(pull + row * lambda))) {
                row = solved;
            }
        }
        for a in 0..D {
            out.linear[(r, a)] = row[a];
        }
        out.translation[r] = wanted - row.dot(&center);
    }
    out
}

/// A rotation, a uniform scale and a shift (Umeyama's least squares): in all coordinates for 3D
/// points, in the horizontal ones with the heights shifted by the 3D points' mean where there
/// are 2D points.
fn similarity<const D: usize>(points: &[TrendPoint<D>]) -> Affine<D> {
    let planar = D == 3 && points.iter().any(|p| p.horizontal);
    let k = if planar { D - 1 } else { D };
    let used: Vec<&TrendPoint<D>> = points.iter().filter(|p| p.weight > 0.0).collect();
    let weight: f64 = used.iter().map(|p| p.weight).sum();
    let mut out = shift(points);
    if used.len() < 2 || weight <= 0.0 {
        return out;
    }
    let mean = |f: &dyn Fn(&TrendPoint<D>) -> Vect<D>| {
        used.iter().fold(Vect::<D>::zeros(), |s, p| s + f(p) * p.weight) / weight
    };
    let (c, d) = (mean(&|p| p.from), mean(&|p| p.to));
    let mut cov = DMatrix::<f64>::zeros(k, k);
    let mut var = 0.0;
    for p in &used {
        let (x, y) = (p.from - c, p.to - d);
        for i in 0..k {
            var += p.weight * x[i] * x[i];
            for j in 0..k {
                cov[(i, j)] += p.weight * y[i] * x[j];
            }
        }
    }
    if !(var > 0.0 && var.is_finite()) {
        return out;
    }
    let svd = cov.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return out;
    };
    let mut sign = DMatrix::<f64>::identity(k, k);
    if (&u * &v_t).determinant() < 0.0 {
        sign[(k - 1, k - 1)] = -1.0;
    }
    let rotation = &u * &sign * &v_t;
    let scale = (0..k)
        .map(|i| svd.singular_values[i] * sign[(i, i)])
        .sum::<f64>()
        / var;
    for i in 0..k {
        for j in 0..k {
            out.linear[(i, j)] = scale * rotation[(i, j)];
        }
    }
    for i in 0..k {
        out.translation[i] = d[i] - (0..k).map(|j| out.linear[(i, j)] * c[j]).sum::<f64>();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn points(map: &Affine<3>, horizontal: bool) -> Vec<TrendPoint<3>> {
        let mut out = Vec::new();
        for (i, x) in [0.0, 300.0, 900.0].iter().enumerate() {
            for (j, y) in [0.0, 400.0, 800.0].iter().enumerate() {
                let from = Vector3::new(*x, *y, 10.0 * ((i * 3 + j) % 4) as f64);
                let mut to = map.apply(&from);
                if horizontal {
                    to.z = 0.0;
                }
                out.push(TrendPoint {
                    from,
                    to,
                    weight: 1.0 + (i + j) as f64,
                    horizontal,
                });
            }
        }
        out
    }

    fn close(a: &Affine<3>, b: &Affine<3>, tol: f64) -> bool {
        (a.linear - b.linear).amax() < tol && (a.translation - b.translation).amax() < tol * 1e3
    }

    #[test]
    fn an_affine_trend_recovers_an_affine_map() {
        let map = Affine {
            linear: Mat::<3>::new(1.0002, 0.0003, 0.001, -0.0004, 0.9997, 0.0, 2e-4, -1e-4, 1.0),
            translation: Vector3::new(0.5, -0.3, 0.12),
        };
        let fitted = fit(Trend::Affine, &points(&map, false));
        assert!(close(&fitted, &map, 1e-7), "{fitted:?}");
    }

    #[test]
    fn two_d_points_fit_the_horizontal_rows_and_leave_the_heights() {
        let map = Affine {
            linear: Mat::<3>::new(1.0002, 0.0003, 0.0, -0.0004, 0.9997, 0.0, 0.0, 0.0, 1.0),
            translation: Vector3::new(0.5, -0.3, 0.0),
        };
        for kind in [Trend::Affine, Trend::Similarity, Trend::Shift] {
            let fitted = fit(kind, &points(&map, true));
            assert_eq!(fitted.linear.row(2), Mat::<3>::identity().row(2), "{kind}");
            assert_eq!(fitted.translation.z, 0.0, "{kind}");
        }
        let fitted = fit(Trend::Affine, &points(&map, true));
        assert!(close(&fitted, &map, 1e-7), "{fitted:?}");
    }

    #[test]
    fn a_similarity_recovers_a_turn_a_scale_and_a_shift() {
        let turn = nalgebra::Rotation3::from_euler_angles(0.001, -0.002, 0.01);
        let map = Affine {
            linear: turn.matrix() * 1.0005,
            translation: Vector3::new(3.0, -2.0, 0.4),
        };
        let fitted = fit(Trend::Similarity, &points(&map, false));
        assert!(close(&fitted, &map, 1e-9), "{fitted:?}");
    }

    #[test]
    fn a_shift_is_the_weighted_mean_motion_and_one_point_is_a_shift() {
        let map = Affine {
            linear: Mat::<3>::identity(),
            translation: Vector3::new(0.25, 0.5, -1.0),
        };
        let all = points(&map, false);
        assert!(close(&fit(Trend::Shift, &all), &map, 1e-12));
        for kind in [Trend::Affine, Trend::Similarity] {
            let one = fit(kind, &all[3..4]);
            assert!(close(&one, &map, 1e-12), "{kind}: {one:?}");
        }
        assert!(fit(Trend::None, &all).is_identity());
    }

    /// Points on a line say nothing across it: the affine trend keeps the identity there.
    #[test]
    fn directions_the_points_do_not_span_keep_the_identity() {
        let pts: Vec<TrendPoint<3>> = (0..5)
            .map(|i| {
                let from = Vector3::new(100.0 * i as f64, 0.0, 0.0);
                TrendPoint {
                    from,
                    to: from * 1.001 + Vector3::new(0.2, 0.1, 0.0),
                    weight: 1.0,
                    horizontal: false,
                }
            })
            .collect();
        let fitted = fit(Trend::Affine, &pts);
        assert!((fitted.linear[(0, 0)] - 1.001).abs() < 1e-9, "{fitted:?}");
        for (r, a) in [(0, 1), (1, 1), (2, 2), (1, 2), (2, 1)] {
            let want = if r == a { 1.0 } else { 0.0 };
            assert!((fitted.linear[(r, a)] - want).abs() < 1e-9, "{r},{a}: {fitted:?}");
        }
    }
}
