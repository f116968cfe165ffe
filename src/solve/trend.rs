//! The control points' global trend (`trend` in the edit spec): a map `T` fitted to all of them,
//! which carries what is global — a datum shift, a rotation, a scale, a shear, a tilt, a smooth
//! warp between the points, the motions that rigid cells resist by design — so that the cells
//! carry only what is local: fixed regions kept exact, handles, stiff parts.
//!
//! The edit's map is `T ∘ F`. The cells solve `F` with each control point wanting `T⁻¹` of its
//! destination, the fixed and resting cells following `T⁻¹` and each handle's cells `T⁻¹ ∘ H`;
//! after `T`, fixed samples are where they were and handle samples where their maps send them,
//! exactly, because the exact layer holds the final maps (identity, `H`) and applies `T` to the
//! transfer's values only ([`crate::field::Field::trend`]). Without control points, or with
//! `trend = "none"`, `T` is the identity and nothing changes.
//!
//! **Why a spline by default.** Between control points, rigid cells pulled at a few points
//! behave as a membrane: the motion concentrates around each point and relaxes toward a rigid
//! one between them, and smaller cells concentrate it more. A thin-plate spline minimizes
//! bending instead, the smoothest surface through the points; a surveyor's affine fit misses
//! any warp that is not affine. On a forest scan moved by a shift, a bilinear warp and a bump
//! (`tools/python/control_accuracy.py`, BENCHMARKS.md) the spline trend scores as the spline
//! does at the checkpoints, where the cells alone and the affine trend score worse.
//!
//! **Heights never enter the positions.** Every trend works over the horizontal plane (the
//! first two coordinates): `x' = a₀ + a₁ x + a₂ y (+ spline)`, and a height `z' = z + a₀ +
//! a₁ x + a₂ y (+ spline)`. A scan's control points lie near the ground, and how x and y
//! would change with height is what they determine worst (fitted, it turns a tree's top by
//! what the ground's points happen to say). 2D control points (`x, y → X, Y`) fit the
//! horizontal rows only: the height row stays the identity unless 3D points fit it. A
//! direction the points do not span (points on a line) keeps the identity: each affine row
//! is pulled toward the identity's by a millionth of the points' own spread.

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

/// The most control points a spline trend takes: its system is dense, `8 (n + 3)²` bytes
/// (200 MB at this count).
pub const SPLINE_POINTS_MOST: usize = 5000;

/// A trend: an affine map plus, for [`Trend::Spline`], a thin-plate spline over the horizontal
/// plane (the first two coordinates), `T(x) = A x + Σ_i w_i φ(|x_h − c_i| / L)` with
/// `φ(s) = s² ln s`.
#[derive(Debug, Clone, PartialEq)]
pub struct TrendMap<const D: usize> {
    /// The affine part.
    pub affine: Affine<D>,
    /// The spline's centers (horizontal coordinates, local frame), none for an affine trend.
    pub centers: Vec<[f64; 2]>,
    /// Each center's weight, per output coordinate.
    pub weights: Vec<Vect<D>>,
    /// The spline's length scale `L`.
    pub scale: f64,
}

impl<const D: usize> Default for TrendMap<D> {
    fn default() -> Self {
        Self::affine(Affine::identity())
    }
}

/// `φ(s) = s² ln s` and `φ'(s) / s = 2 ln s + 1` (0 at `s = 0`).
#[inline]
fn kernel(s2: f64) -> (f64, f64) {
    if s2 > 0.0 {
        let ln = 0.5 * s2.ln();
        (s2 * ln, 2.0 * ln + 1.0)
    } else {
        (0.0, 0.0)
    }
}

impl<const D: usize> TrendMap<D> {
    /// An affine trend.
    pub fn affine(affine: Affine<D>) -> Self {
        Self {
            affine,
            centers: Vec::new(),
            weights: Vec::new(),
            scale: 1.0,
        }
    }

    /// Whether the trend is exactly the identity.
    pub fn is_identity(&self) -> bool {
        self.centers.is_empty() && self.affine.is_identity()
    }

    /// Whether the trend is affine (no spline).
    pub fn is_affine(&self) -> bool {
        self.centers.is_empty()
    }

    /// `T(x)`.
    pub fn apply(&self, x: &Vect<D>) -> Vect<D> {
        let mut y = self.affine.apply(x);
        for (c, w) in self.centers.iter().zip(&self.weights) {
            let (dx, dy) = ((x[0] - c[0]) / self.scale, (x[1] - c[1]) / self.scale);
            y += w * kernel(dx * dx + dy * dy).0;
        }
        y
    }

    /// The Jacobian of `T` at `x`.
    pub fn jacobian(&self, x: &Vect<D>) -> Mat<D> {
        let mut j = self.affine.linear;
        for (c, w) in self.centers.iter().zip(&self.weights) {
            let (dx, dy) = ((x[0] - c[0]) / self.scale, (x[1] - c[1]) / self.scale);
            let slope = kernel(dx * dx + dy * dy).1 / self.scale;
            for r in 0..D {
                j[(r, 0)] += w[r] * slope * dx;
                j[(r, 1)] += w[r] * slope * dy;
            }
        }
        j
    }

    /// `T⁻¹(y)`, by Newton's method from `y` (exact for an affine trend; a spline trend's
    /// displacements vary slowly, and three steps take it to rounding). `None` where the
    /// Jacobian is singular.
    pub fn back(&self, y: &Vect<D>) -> Option<Vect<D>> {
        if self.is_affine() {
            return Some(self.affine.inverse()?.apply(y));
        }
        let mut x = *y;
        for _ in 0..4 {
            let step = self.jacobian(&x).try_inverse()? * (self.apply(&x) - y);
            x -= step;
        }
        x.iter().all(|v| v.is_finite()).then_some(x)
    }

    /// The affine map that agrees with `T` to first order at `x`.
    pub fn linearized(&self, x: &Vect<D>) -> Affine<D> {
        let linear = self.jacobian(x);
        Affine {
            linear,
            translation: self.apply(x) - linear * x,
        }
    }
}

/// The trend of `kind` through `points` (the identity without points, or for [`Trend::None`]).
pub fn fit<const D: usize>(kind: Trend, points: &[TrendPoint<D>]) -> TrendMap<D> {
    match kind {
        Trend::None => TrendMap::default(),
        Trend::Shift => TrendMap::affine(shift(points)),
        Trend::Similarity => TrendMap::affine(similarity(points)),
        Trend::Affine => TrendMap::affine(affine(points)),
        Trend::Spline => spline(points),
    }
}

/// The thin-plate spline through the points, row by row with its affine part over the
/// horizontal plane (heights never enter the positions): each coordinate's displacement is
/// interpolated exactly at its points. A row with fewer than three points not on one line
/// takes the affine trend's row instead.
fn spline<const D: usize>(points: &[TrendPoint<D>]) -> TrendMap<D> {
    let fallback = affine(points);
    let used: Vec<&TrendPoint<D>> = points.iter().filter(|p| p.weight > 0.0).collect();
    let n = used.len();
    if !(3..=SPLINE_POINTS_MOST).contains(&n) {
        return TrendMap::affine(fallback);
    }
    let mean = used
        .iter()
        .fold([0.0, 0.0], |m, p| [m[0] + p.from[0], m[1] + p.from[1]]);
    let mean = [mean[0] / n as f64, mean[1] / n as f64];
    let scale = used
        .iter()
        .map(|p| (p.from[0] - mean[0]).hypot(p.from[1] - mean[1]))
        .fold(0.0, f64::max);
    if !(scale > 0.0 && scale.is_finite()) {
        return TrendMap::affine(fallback);
    }
    let mut out = TrendMap {
        affine: fallback,
        centers: used.iter().map(|p| [p.from[0], p.from[1]]).collect(),
        weights: vec![Vect::<D>::zeros(); n],
        scale,
    };
    for r in 0..D {
        let rows: Vec<usize> = (0..n).filter(|&i| used[i].fits(r)).collect();
        let m = rows.len();
        if m < 3 {
            continue;
        }
        // [K P; Pᵀ 0] [w; a] = [d; 0], P = [1, u, v] in the scaled frame about the mean.
        let mut system = DMatrix::<f64>::zeros(m + 3, m + 3);
        let mut rhs = nalgebra::DVector::<f64>::zeros(m + 3);
        let at = |i: usize| {
            let p = &used[rows[i]].from;
            ((p[0] - mean[0]) / scale, (p[1] - mean[1]) / scale)
        };
        for i in 0..m {
            let (ui, vi) = at(i);
            for j in 0..m {
                let (uj, vj) = at(j);
                system[(i, j)] = kernel((ui - uj).powi(2) + (vi - vj).powi(2)).0;
            }
            for (k, value) in [1.0, ui, vi].into_iter().enumerate() {
                system[(i, m + k)] = value;
                system[(m + k, i)] = value;
            }
            let p = used[rows[i]];
            rhs[i] = p.to[r] - p.from[r];
        }
        let Some(solved) = system.lu().solve(&rhs) else {
            continue;
        };
        if !solved.iter().all(|v| v.is_finite()) {
            continue;
        }
        let mut weights = vec![0.0; n];
        for (i, &k) in rows.iter().enumerate() {
            weights[k] = solved[i];
        }
        // The affine row: x_r + a₀ + a₁ (x₀ − m₀)/L + a₂ (x₁ − m₁)/L.
        let (a0, a1, a2) = (solved[m], solved[m + 1] / scale, solved[m + 2] / scale);
        for k in 0..D {
            out.affine.linear[(r, k)] = if k == r { 1.0 } else { 0.0 };
        }
        out.affine.linear[(r, 0)] += a1;
        out.affine.linear[(r, 1)] += a2;
        out.affine.translation[r] = a0 - a1 * mean[0] - a2 * mean[1];
        for (w, v) in out.weights.iter_mut().zip(weights) {
            w[r] = v;
        }
    }
    out
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

/// Each row by weighted least squares over the horizontal plane (`x' = a₀ + a₁ x + a₂ y`, and
/// for a height `z' = z + a₀ + a₁ x + a₂ y`, an inclined plane), pulled toward the identity's
/// row by a millionth of the points' spread.
fn affine<const D: usize>(points: &[TrendPoint<D>]) -> Affine<D> {
    let mut out = Affine::identity();
    let plane = |x: &Vect<D>| nalgebra::Vector2::new(x[0], x[1]);
    for r in 0..D {
        let used: Vec<&TrendPoint<D>> = points.iter().filter(|p| p.fits(r)).collect();
        let weight: f64 = used.iter().map(|p| p.weight).sum();
        if used.is_empty() || weight <= 0.0 {
            continue;
        }
        // What the plane's terms must give: the coordinate itself, less the height it keeps.
        let wanted_of = |p: &TrendPoint<D>| p.to[r] - if r >= 2 { p.from[r] } else { 0.0 };
        let center = used.iter().fold(nalgebra::Vector2::zeros(), |s, p| {
            s + plane(&p.from) * p.weight
        }) / weight;
        let wanted = used.iter().map(|p| p.weight * wanted_of(p)).sum::<f64>() / weight;
        let mut spread = nalgebra::Matrix2::<f64>::zeros();
        let mut pull = nalgebra::Vector2::<f64>::zeros();
        for p in &used {
            let x = plane(&p.from) - center;
            spread += x * x.transpose() * p.weight;
            pull += x * (p.weight * (wanted_of(p) - wanted));
        }
        let mut row = nalgebra::Vector2::<f64>::zeros();
        if r < 2 {
            row[r] = 1.0;
        }
        let lambda = 1e-6 * spread.trace();
        if lambda > 0.0 && lambda.is_finite() {
            let system = spread + nalgebra::Matrix2::identity() * lambda;
            if let Some(solved) = system.cholesky().map(|c| c.solve(&(pull + row * lambda))) {
                row = solved;
            }
        }
        out.linear[(r, 0)] = row[0];
        out.linear[(r, 1)] = row[1];
        out.translation[r] = wanted - row.dot(&center);
    }
    out
}

/// A rotation, a uniform scale and a shift in the horizontal plane (Helmert's four parameters,
/// by Umeyama's least squares), and heights shifted by their points' weighted mean.
fn similarity<const D: usize>(points: &[TrendPoint<D>]) -> Affine<D> {
    let used: Vec<&TrendPoint<D>> = points.iter().filter(|p| p.weight > 0.0).collect();
    let weight: f64 = used.iter().map(|p| p.weight).sum();
    let mut out = shift(points);
    if used.len() < 2 || weight <= 0.0 {
        return out;
    }
    let mean = |f: &dyn Fn(&TrendPoint<D>) -> Vect<D>| {
        used.iter()
            .fold(Vect::<D>::zeros(), |s, p| s + f(p) * p.weight)
            / weight
    };
    let (c, d) = (mean(&|p| p.from), mean(&|p| p.to));
    let mut cov = nalgebra::Matrix2::<f64>::zeros();
    let mut var = 0.0;
    for p in &used {
        let (x, y) = (p.from - c, p.to - d);
        for i in 0..2 {
            var += p.weight * x[i] * x[i];
            for j in 0..2 {
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
    let mut sign = nalgebra::Matrix2::<f64>::identity();
    if (u * v_t).determinant() < 0.0 {
        sign[(1, 1)] = -1.0;
    }
    let rotation = u * sign * v_t;
    let scale =
        (svd.singular_values[0] * sign[(0, 0)] + svd.singular_values[1] * sign[(1, 1)]) / var;
    for i in 0..2 {
        for j in 0..2 {
            out.linear[(i, j)] = scale * rotation[(i, j)];
        }
    }
    for i in 0..2 {
        out.translation[i] = d[i] - (0..2).map(|j| out.linear[(i, j)] * c[j]).sum::<f64>();
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
            linear: Mat::<3>::new(1.0002, 0.0003, 0.0, -0.0004, 0.9997, 0.0, 2e-4, -1e-4, 1.0),
            translation: Vector3::new(0.5, -0.3, 0.12),
        };
        let fitted = fit(Trend::Affine, &points(&map, false)).affine;
        assert!(close(&fitted, &map, 1e-7), "{fitted:?}");
    }

    #[test]
    fn two_d_points_fit_the_horizontal_rows_and_leave_the_heights() {
        let map = Affine {
            linear: Mat::<3>::new(1.0002, 0.0003, 0.0, -0.0004, 0.9997, 0.0, 0.0, 0.0, 1.0),
            translation: Vector3::new(0.5, -0.3, 0.0),
        };
        for kind in [
            Trend::Affine,
            Trend::Similarity,
            Trend::Shift,
            Trend::Spline,
        ] {
            let fitted = fit(kind, &points(&map, true)).affine;
            assert_eq!(fitted.linear.row(2), Mat::<3>::identity().row(2), "{kind}");
            assert_eq!(fitted.translation.z, 0.0, "{kind}");
        }
        let fitted = fit(Trend::Affine, &points(&map, true)).affine;
        assert!(close(&fitted, &map, 1e-7), "{fitted:?}");
    }

    #[test]
    fn a_similarity_recovers_a_turn_a_scale_and_a_shift() {
        let turn = nalgebra::Rotation3::from_euler_angles(0.0, 0.0, 0.01);
        let mut linear = turn.matrix() * 1.0005;
        linear[(2, 2)] = 1.0;
        let map = Affine {
            linear,
            translation: Vector3::new(3.0, -2.0, 0.4),
        };
        let fitted = fit(Trend::Similarity, &points(&map, false)).affine;
        assert!(close(&fitted, &map, 1e-9), "{fitted:?}");
    }

    #[test]
    fn a_shift_is_the_weighted_mean_motion_and_one_point_is_a_shift() {
        let map = Affine {
            linear: Mat::<3>::identity(),
            translation: Vector3::new(0.25, 0.5, -1.0),
        };
        let all = points(&map, false);
        assert!(close(&fit(Trend::Shift, &all).affine, &map, 1e-12));
        for kind in [Trend::Affine, Trend::Similarity] {
            let one = fit(kind, &all[3..4]).affine;
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
        let fitted = fit(Trend::Affine, &pts).affine;
        assert!((fitted.linear[(0, 0)] - 1.001).abs() < 1e-9, "{fitted:?}");
        for (r, a) in [(0, 1), (1, 1), (2, 2), (1, 2), (2, 1)] {
            let want = if r == a { 1.0 } else { 0.0 };
            assert!(
                (fitted.linear[(r, a)] - want).abs() < 1e-9,
                "{r},{a}: {fitted:?}"
            );
        }
    }

    /// The spline passes through every point, reproduces an affine map exactly, and its
    /// inverse and Jacobian agree with it.
    #[test]
    fn a_spline_interpolates_its_points_and_inverts() {
        let map = Affine {
            linear: Mat::<3>::new(1.0002, 0.0003, 0.0, -0.0004, 0.9997, 0.0, 0.0, 0.0, 1.0),
            translation: Vector3::new(0.5, -0.3, 0.1),
        };
        let mut pts = points(&map, false);
        let affine = fit(Trend::Spline, &pts);
        let probe = Vector3::new(450.0, 130.0, 20.0);
        assert!(
            (affine.apply(&probe) - map.apply(&probe)).amax() < 1e-9,
            "{affine:?}"
        );
        for (k, p) in pts.iter_mut().enumerate() {
            p.to += Vector3::new(
                0.1 * (k % 3) as f64,
                -0.05 * (k % 2) as f64,
                0.02 * k as f64,
            );
        }
        let spline = fit(Trend::Spline, &pts);
        for p in &pts {
            assert!((spline.apply(&p.from) - p.to).amax() < 1e-9, "{:?}", p.from);
        }
        let y = spline.apply(&probe);
        assert!((spline.back(&y).unwrap() - probe).amax() < 1e-9);
        let h = 1e-3;
        for a in 0..2 {
            let mut e = Vector3::zeros();
            e[a] = h;
            let numeric = (spline.apply(&(probe + e)) - spline.apply(&(probe - e))) / (2.0 * h);
            assert!(
                (spline.jacobian(&probe).column(a) - numeric).amax() < 1e-8,
                "{a}"
            );
        }
    }
}
