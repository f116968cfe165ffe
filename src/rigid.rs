//! Rigid motions in 2D and 3D, and the one place where the two dimensions differ.
//!
//! Everything else in the crate is generic over `const D: usize` and asks [`Rigid`] for the
//! handful of operations that depend on the dimension:
//!
//! - the angular part of a velocity: `ω ∈ ℝ³` in 3D (3 DoF), a scalar in 2D (1 DoF);
//! - the linearized rotation `δ(R y) = ω × y` and its Jacobian with respect to `ω`;
//! - the update `R ← polar(I + [ω]×) · R`, the projection of the affine step onto the
//!   rotations (paper §4; Horn's shape matching of `A_i(C_i)` and `T_i(C_i)` reduces to this
//!   polar decomposition for a box). `I + [ω]×` is a normal matrix whose polar rotation is the
//!   rotation by `atan |ω|` about `ω`, so the projection is closed-form and caps a single step's
//!   rotation below 90°, a natural damping of large Gauss-Newton steps;
//! - the rotation nearest to a general linear map (polar decomposition; SVD in 3D, closed form
//!   in 2D), used for handles with scale or a general affine matrix.

use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};

/// A point or vector in `D` dimensions (f64).
pub type Vect<const D: usize> = SVector<f64, D>;
/// A `D × D` matrix (f64).
pub type Mat<const D: usize> = SMatrix<f64, D, D>;

/// Marker type for a supported dimension; see [`Rigid`].
#[derive(Debug, Clone, Copy)]
pub struct Dim<const D: usize>;

/// The largest number of degrees of freedom of a rigid motion (3D: 3 translational + 3 rotational).
pub const MAX_DOF: usize = 6;

/// Dimension-specific operations on rigid motions. Implemented for `Dim<2>` and `Dim<3>`.
pub trait Rigid<const D: usize>: Send + Sync + 'static {
    /// Rotational degrees of freedom: 1 in 2D, 3 in 3D.
    const ROT: usize;
    /// Degrees of freedom of a free rigid motion: `D + ROT`.
    const DOF: usize = D + Self::ROT;

    /// The derivative of the rotated offset `y` with respect to each angular velocity component:
    /// `∂(ω × y)/∂ω_r` for `r < ROT` (unused columns are zero).
    fn cross_jacobian(y: &Vect<D>) -> [Vect<D>; 3];

    /// `polar(I + [ω]×)`: the rotation by `atan |ω|` about `ω` (2D: by `atan ω`).
    fn step_rotation(omega: &[f64]) -> Mat<D>;

    /// The rotation nearest to `m` in the Frobenius norm (polar decomposition), with
    /// determinant +1. Returns the identity for a matrix with no definite orientation.
    fn nearest_rotation(m: &Mat<D>) -> Mat<D>;

    /// The rotation by `radians` about `axis` (the axis is ignored in 2D). `axis` need not be
    /// normalized; a zero axis gives the identity.
    fn axis_angle(axis: &Vect<D>, radians: f64) -> Mat<D>;

    /// The rotation angle of `r` in radians, in `[0, π]`.
    fn angle(r: &Mat<D>) -> f64;

    /// The determinant of `m`.
    fn determinant(m: &Mat<D>) -> f64;

    /// An axis and a signed angle with `axis_angle(axis, angle) == r` (2D: the axis is unused).
    /// In 3D the angle is in `[0, π]`; past a quarter turn the axis comes from the symmetric
    /// part of `r`, which rounding does not blur as it blurs the antisymmetric part near a half
    /// turn (there `2 sin θ` is of the order of the matrix's rounding), and the antisymmetric
    /// part only gives its sign. At a half turn the sign is a free choice.
    fn axis_angle_of(r: &Mat<D>) -> (Vect<D>, f64);

    /// `r` as a unit quaternion, either sign (2D: a turn about z).
    fn quaternion(r: &Mat<D>) -> UnitQuaternion<f64>;

    /// `axis` as a unit vector in 3D (2D: z, the axis of every turn). Zero for a zero axis.
    fn axis_3d(axis: &Vect<D>) -> Vector3<f64>;

    /// The signed angle in (−π, π] by which `r` turns about `axis`: the twist of its
    /// swing-twist decomposition (2D: the rotation's angle; the axis is unused).
    fn twist(r: &Mat<D>, axis: &Vect<D>) -> f64;
}

impl Rigid<2> for Dim<2> {
    const ROT: usize = 1;

    fn cross_jacobian(y: &Vect<2>) -> [Vect<2>; 3] {
        [
            Vect::<2>::new(-y.y, y.x),
            Vect::<2>::zeros(),
            Vect::<2>::zeros(),
        ]
    }

    fn step_rotation(omega: &[f64]) -> Mat<2> {
        rotation_2d(omega[0].atan())
    }

    fn nearest_rotation(m: &Mat<2>) -> Mat<2> {
        // Polar factor of a 2×2 matrix: the rotation whose angle maximizes tr(Rᵀ M).
        let (s, c) = (m[(1, 0)] - m[(0, 1)], m[(0, 0)] + m[(1, 1)]);
        if s == 0.0 && c == 0.0 {
            return Matrix2::identity();
        }
        rotation_2d(s.atan2(c))
    }

    fn axis_angle(_axis: &Vect<2>, radians: f64) -> Mat<2> {
        rotation_2d(radians)
    }

    fn angle(r: &Mat<2>) -> f64 {
        r[(1, 0)].atan2(r[(0, 0)]).abs()
    }

    fn determinant(m: &Mat<2>) -> f64 {
        m.determinant()
    }

    fn axis_angle_of(r: &Mat<2>) -> (Vect<2>, f64) {
        (Vect::<2>::zeros(), r[(1, 0)].atan2(r[(0, 0)]))
    }

    fn twist(r: &Mat<2>, _axis: &Vect<2>) -> f64 {
        r[(1, 0)].atan2(r[(0, 0)])
    }

    fn quaternion(r: &Mat<2>) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), r[(1, 0)].atan2(r[(0, 0)]))
    }

    fn axis_3d(_axis: &Vect<2>) -> Vector3<f64> {
        Vector3::z()
    }
}

/// Newton's iterations for a polar factor before the 3D `nearest_rotation` takes the SVD's.
const POLAR_ITERATIONS: usize = 12;

impl Rigid<3> for Dim<3> {
    const ROT: usize = 3;

    fn cross_jacobian(y: &Vect<3>) -> [Vect<3>; 3] {
        // ω × y = −[y]× ω; the columns of −[y]× are e_r × y.
        [
            Vector3::new(0.0, -y.z, y.y),
            Vector3::new(y.z, 0.0, -y.x),
            Vector3::new(-y.y, y.x, 0.0),
        ]
    }

    fn step_rotation(omega: &[f64]) -> Mat<3> {
        let w = Vector3::new(omega[0], omega[1], omega[2]);
        let n = w.norm();
        if n == 0.0 {
            return Matrix3::identity();
        }
        Self::axis_angle(&w, n.atan())
    }

    /// Where `det m > 0` the nearest rotation is the polar factor of `m`, which Newton's
    /// iteration `X ← (γX + X⁻ᵀ/γ) / 2` reaches in a few 3 × 3 inversions (γ Higham's scaling,
    /// `sqrt(|X⁻¹| / |X|)`, while far from a rotation): six or seven for a local-global step's
    /// Procrustes matrices (products of the faces' moments and near-rotations), one or two for
    /// a near-rotation, a fifth of an SVD's time. Any other matrix, or one the iteration does not
    /// settle in `POLAR_ITERATIONS`, gets the SVD's answer.
    fn nearest_rotation(m: &Mat<3>) -> Mat<3> {
        if !m.iter().all(|v| v.is_finite()) || m.norm() == 0.0 {
            return Matrix3::identity();
        }
        if m.determinant() > 0.0 {
            let mut x = *m;
            for k in 0..POLAR_ITERATIONS {
                let Some(inv) = x.try_inverse() else { break };
                let g = if k < 3 {
                    (inv.norm() / x.norm()).sqrt()
                } else {
                    1.0
                };
                let next = (x * g + inv.transpose() / g) * 0.5;
                // Quadratic convergence: a change of 1e-8 leaves an error near 1e-16.
                let settled = (next - x).norm() <= 1e-8;
                x = next;
                if settled {
                    return x;
                }
            }
        }
        let svd = m.svd(true, true);
        let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
            return Matrix3::identity();
        };
        let mut r = u * vt;
        if r.determinant() < 0.0 {
            // Flip the axis of the smallest singular value (nalgebra sorts them descending).
            let mut u2 = u;
            let k = (0..3)
                .min_by(|&a, &b| svd.singular_values[a].total_cmp(&svd.singular_values[b]))
                .unwrap_or(2);
            u2.column_mut(k).neg_mut();
            r = u2 * vt;
        }
        r
    }

    fn axis_angle(axis: &Vect<3>, radians: f64) -> Mat<3> {
        let n = axis.norm();
        if n == 0.0 || radians == 0.0 {
            return Matrix3::identity();
        }
        let k = axis / n;
        let (s, c) = radians.sin_cos();
        let kx = Matrix3::new(0.0, -k.z, k.y, k.z, 0.0, -k.x, -k.y, k.x, 0.0);
        Matrix3::identity() + kx * s + kx * kx * (1.0 - c)
    }

    fn angle(r: &Mat<3>) -> f64 {
        ((r.trace() - 1.0) * 0.5).clamp(-1.0, 1.0).acos()
    }

    fn determinant(m: &Mat<3>) -> f64 {
        m.determinant()
    }

    fn axis_angle_of(r: &Mat<3>) -> (Vect<3>, f64) {
        // r − rᵀ = 2 sin θ [n]×, and r + rᵀ − (tr r − 1) I = 2 (1 − cos θ) n nᵀ.
        let w = Vector3::new(
            r[(2, 1)] - r[(1, 2)],
            r[(0, 2)] - r[(2, 0)],
            r[(1, 0)] - r[(0, 1)],
        );
        let (sin2, cos2) = (w.norm(), r.trace() - 1.0);
        let angle = sin2.atan2(cos2);
        if angle == 0.0 || !angle.is_finite() {
            return (Vector3::x(), 0.0);
        }
        if cos2 >= 0.0 {
            return (w / sin2, angle);
        }
        let b = r + r.transpose() - Matrix3::identity() * cos2;
        let k = (0..3)
            .max_by(|&i, &j| b[(i, i)].total_cmp(&b[(j, j)]))
            .unwrap_or(0);
        let n = b.column(k).normalize();
        (if n.dot(&w) < 0.0 { -n } else { n }, angle)
    }

    fn twist(r: &Mat<3>, axis: &Vect<3>) -> f64 {
        let n = axis.norm();
        if n == 0.0 {
            return 0.0;
        }
        let q = Self::quaternion(r);
        let along = q.i * axis.x + q.j * axis.y + q.k * axis.z;
        // The quaternion's sign is free: ±q give angles 2π apart, the same after wrapping.
        let t = 2.0 * (along / n).atan2(q.w);
        if t > std::f64::consts::PI {
            t - std::f64::consts::TAU
        } else if t <= -std::f64::consts::PI {
            t + std::f64::consts::TAU
        } else {
            t
        }
    }

    fn quaternion(r: &Mat<3>) -> UnitQuaternion<f64> {
        UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(*r))
    }

    fn axis_3d(axis: &Vect<3>) -> Vector3<f64> {
        axis.try_normalize(0.0).unwrap_or_else(Vector3::zeros)
    }
}

fn rotation_2d(theta: f64) -> Mat<2> {
    let (s, c) = theta.sin_cos();
    Matrix2::new(c, -s, s, c)
}

/// A rigid motion of one cell: `T(x) = R (x − c) + p`, with `c` the cell's rest center and `p`
/// where the center goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion<const D: usize> {
    /// The rotation `R`.
    pub rot: Mat<D>,
    /// The deformed position `p = T(c)` of the rest center `c`.
    pub pos: Vect<D>,
}

impl<const D: usize> Motion<D> {
    /// The motion that leaves the cell centered at `center` in place.
    pub fn rest(center: &Vect<D>) -> Self {
        Self {
            rot: Mat::<D>::identity(),
            pos: *center,
        }
    }

    /// `T(x) = R (x − c) + p` for the cell with rest center `center`.
    #[inline]
    pub fn apply(&self, center: &Vect<D>, x: &Vect<D>) -> Vect<D> {
        self.rot * (x - center) + self.pos
    }
}

/// An affine map `A(x) = L x + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Affine<const D: usize> {
    /// The linear part `L`.
    pub linear: Mat<D>,
    /// The translation `t`.
    pub translation: Vect<D>,
}

impl<const D: usize> Affine<D> {
    /// The identity map.
    pub fn identity() -> Self {
        Self {
            linear: Mat::<D>::identity(),
            translation: Vect::<D>::zeros(),
        }
    }

    /// `A(x) = L x + t`.
    #[inline]
    pub fn apply(&self, x: &Vect<D>) -> Vect<D> {
        self.linear * x + self.translation
    }

    /// The rigid motion a cell with rest center `center` follows under this map (paper §4):
    /// its center goes to `A(c)` and it turns by the rotation nearest to `L`.
    pub fn cell_motion(&self, center: &Vect<D>) -> Motion<D>
    where
        Dim<D>: Rigid<D>,
    {
        Motion {
            rot: <Dim<D> as Rigid<D>>::nearest_rotation(&self.linear),
            pos: self.apply(center),
        }
    }

    /// `self ∘ other`: `other` first.
    pub fn after(&self, other: &Self) -> Self {
        Self {
            linear: self.linear * other.linear,
            translation: self.linear * other.translation + self.translation,
        }
    }

    /// The inverse map (`None` when the linear part is singular).
    pub fn inverse(&self) -> Option<Self> {
        let linear = self.linear.try_inverse()?;
        Some(Self {
            linear,
            translation: -(linear * self.translation),
        })
    }

    /// The map a fraction `f` of the way from the identity to this one (entry by entry).
    pub fn towards(&self, f: f64) -> Self {
        let identity = Mat::<D>::identity();
        Self {
            linear: identity + (self.linear - identity) * f,
            translation: self.translation * f,
        }
    }

    /// Whether this is exactly the identity.
    pub fn is_identity(&self) -> bool {
        *self == Self::identity()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_rotation_is_polar_of_linearized_step() {
        let w = [0.3, -0.7, 0.2];
        let lin = Matrix3::identity()
            + Matrix3::new(0.0, -w[2], w[1], w[2], 0.0, -w[0], -w[1], w[0], 0.0);
        let polar = <Dim<3> as Rigid<3>>::nearest_rotation(&lin);
        let closed = <Dim<3> as Rigid<3>>::step_rotation(&w);
        assert!((polar - closed).norm() < 1e-12);

        let lin2 = Matrix2::new(1.0, -0.4, 0.4, 1.0);
        let polar2 = <Dim<2> as Rigid<2>>::nearest_rotation(&lin2);
        assert!((polar2 - <Dim<2> as Rigid<2>>::step_rotation(&[0.4])).norm() < 1e-12);
    }

    #[test]
    fn cross_jacobian_matches_cross_product() {
        let y = Vector3::new(0.3, -1.2, 2.0);
        let w = Vector3::new(-0.5, 0.25, 1.5);
        let j = <Dim<3> as Rigid<3>>::cross_jacobian(&y);
        let lin = j[0] * w.x + j[1] * w.y + j[2] * w.z;
        assert!((lin - w.cross(&y)).norm() < 1e-15);
    }

    #[test]
    fn twist_is_the_turn_about_the_axis() {
        let axis = Vector3::new(0.0, 2.0, 0.0);
        for deg in [-179.0f64, -90.0, -1.0, 0.0, 30.0, 150.0, 179.5] {
            let r = <Dim<3> as Rigid<3>>::axis_angle(&axis, deg.to_radians());
            let t = <Dim<3> as Rigid<3>>::twist(&r, &axis);
            assert!(
                (t.to_degrees() - deg).abs() < 1e-9,
                "{deg}: {}",
                t.to_degrees()
            );
            // A swing about another axis leaves the twist (nearly) alone for small swings.
            let swing = <Dim<3> as Rigid<3>>::axis_angle(&Vector3::x(), 0.01);
            let t = <Dim<3> as Rigid<3>>::twist(&(swing * r), &axis);
            assert!(
                (t.to_degrees() - deg).abs() < 0.01,
                "{deg}: {}",
                t.to_degrees()
            );
        }
        // 270° is −90° as a rotation.
        let r = <Dim<3> as Rigid<3>>::axis_angle(&axis, 270f64.to_radians());
        assert!((<Dim<3> as Rigid<3>>::twist(&r, &axis).to_degrees() + 90.0).abs() < 1e-9);
        let r2 = rotation_2d(2.0);
        assert!((<Dim<2> as Rigid<2>>::twist(&r2, &Vect::<2>::zeros()) - 2.0).abs() < 1e-12);
    }

    /// Near a half turn the axis comes from the symmetric part: an exact half turn keeps its
    /// angle, and one rounded to single precision (as Blender's matrices are) keeps its axis.
    #[test]
    fn axis_and_angle_survive_a_half_turn() {
        let of = <Dim<3> as Rigid<3>>::axis_angle_of;
        let at = <Dim<3> as Rigid<3>>::axis_angle;
        for axis in [
            Vector3::z(),
            Vector3::new(1.0, 2.0, -0.5).normalize(),
            Vector3::new(-0.3, 0.1, 0.9).normalize(),
        ] {
            for degrees in [0.5, 30.0, 89.0, 91.0, 150.0, 179.0, 179.999, 180.0] {
                let r = at(&axis, f64::to_radians(degrees));
                let (a, angle) = of(&r);
                assert!((at(&a, angle) - r).norm() < 1e-12, "{degrees}");
                assert!((angle.to_degrees() - degrees).abs() < 1e-9, "{degrees}");
                assert!(a.dot(&axis).abs() > 1.0 - 1e-9, "{degrees}: {a}");
                // Rounded to single precision: the axis stays, the angle within its rounding.
                let single = r.map(|v| v as f32 as f64);
                let (a, angle) = of(&<Dim<3> as Rigid<3>>::nearest_rotation(&single));
                assert!(a.dot(&axis).abs() > 1.0 - 1e-6, "{degrees}: {a}");
                assert!((angle.to_degrees() - degrees).abs() < 1e-4, "{degrees}");
            }
        }
    }

    #[test]
    fn polar_iteration_is_the_svds_nearest_rotation() {
        use rand::{Rng, SeedableRng, rngs::StdRng};
        let mut rng = StdRng::seed_from_u64(7);
        let rotation = <Dim<3> as Rigid<3>>::axis_angle;
        for k in 0..2000 {
            // Rotations times symmetric stretches up to 1e4 apart, turned up to a half turn;
            // every tenth with a negative determinant (the SVD's case).
            let axis = Vector3::new(rng.random(), rng.random(), rng.random());
            let r = rotation(&axis, rng.random_range(0.0..3.1));
            let q = rotation(
                &Vector3::new(rng.random(), rng.random(), 1.0),
                rng.random_range(0.0..3.1),
            );
            let scales = Matrix3::from_diagonal(&Vector3::new(
                10f64.powf(rng.random_range(-2.0..2.0)),
                10f64.powf(rng.random_range(-2.0..2.0)),
                if k % 10 == 0 { -1.0 } else { 1.0 },
            ));
            let m = r * q * scales * q.transpose();
            let got = <Dim<3> as Rigid<3>>::nearest_rotation(&m);
            let svd = m.svd(true, true);
            let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
            let mut want = u * vt;
            if want.determinant() < 0.0 {
                let mut u = u;
                let smallest = svd.singular_values.imin();
                u.column_mut(smallest).neg_mut();
                want = u * vt;
            }
            // Both to rounding of a matrix whose stretches are up to 1e4 apart.
            assert!((got - want).norm() < 1e-10, "{k}: {m} {got} {want}");
            assert!((got.transpose() * got - Matrix3::identity()).norm() < 1e-14);
        }
    }

    #[test]
    fn nearest_rotation_of_scaled_rotation() {
        let r = <Dim<3> as Rigid<3>>::axis_angle(&Vector3::new(1.0, 2.0, -0.5), 2.5);
        let got = <Dim<3> as Rigid<3>>::nearest_rotation(&(r * 3.0));
        assert!((got - r).norm() < 1e-12);
        assert!((<Dim<3> as Rigid<3>>::angle(&r) - 2.5).abs() < 1e-12);
        let m = Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0);
        assert!((<Dim<3> as Rigid<3>>::nearest_rotation(&m).determinant() - 1.0).abs() < 1e-12);
    }
}
