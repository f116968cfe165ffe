//! An edit spec made in code, checked as the parser checks a written one.
//!
//! [`crate::spec::parse_spec`] refuses a malformed spec line by line; a caller that builds an
//! [`EditSpec`] in Rust gets the same checks from [`EditSpec::validate`], which every library
//! entry point taking a spec runs before any work (so a NaN translation is refused at once, not
//! as a solver's failure, and a rotation that is not one, not as a stretched shape). The
//! handle's motion is best made by its constructors ([`HandleMotion::turning`],
//! [`HandleMotion::affine`]), which keep its rotation and its turn one map.

use super::entries::HandleMotion;
use super::parse::{LARGEST, MAX_TURN_DEGREES};
use super::{EditSpec, Region};
use crate::error::{Error, Result};
use crate::rigid::{Dim, Mat, Rigid, Vect};
use crate::said::Said;

/// How far a rotation may be from orthonormal, and from the rotation its turn gives, in the
/// largest entry of the difference: a rotation made in single precision (Blender's) is within
/// 1e-7.
const ROTATION_SLACK: f64 = 1e-6;

impl<const D: usize> HandleMotion<D>
where
    Dim<D>: Rigid<D>,
{
    /// The motion that turns by `degrees` about `axis` (ignored in 2D) around `pivot` (`None`:
    /// the centroid of the handle's samples), scales by `scale` about it and then moves by
    /// `translate`: what a spec's `rotate`, `scale`, `pivot` and `translate` say. Refused as
    /// the parser refuses them: a zero axis in 3D, a turn past ±3600°, a scale that is not
    /// positive, numbers that are not finite or beyond [`LARGEST`].
    pub fn turning(
        axis: Vect<D>,
        degrees: f64,
        scale: f64,
        pivot: Option<Vect<D>>,
        translate: Vect<D>,
    ) -> std::result::Result<Self, String> {
        finite_vector(&translate, "translate")?;
        if let Some(p) = &pivot {
            finite_vector(p, "pivot")?;
        }
        if !(scale.is_finite() && scale > 0.0 && scale <= LARGEST) {
            return Err(format!(
                "scale {scale} must be positive and at most {LARGEST:e}"
            ));
        }
        let degrees = checked_turn(&axis, degrees)?;
        let radians = degrees.to_radians();
        Ok(Self {
            pivot,
            rotation: rotation_of(&axis, radians),
            turn: (axis, radians),
            stretch: Mat::<D>::identity() * scale,
            translate,
            from_matrix: false,
        })
    }

    /// The affine map `x ↦ linear · x + translation`, as a spec's `matrix` says it: split into
    /// a rotation and a stretch by polar decomposition, its turn the rotation's angle (a matrix
    /// says no winding). Refused where `linear` does not keep orientation or a number is not
    /// finite or beyond [`LARGEST`].
    pub fn affine(linear: Mat<D>, translation: Vect<D>) -> std::result::Result<Self, String> {
        finite_vector(&translation, "`matrix`'s translation")?;
        if !linear.iter().all(|v| v.is_finite() && v.abs() <= LARGEST) {
            return Err(format!(
                "`matrix`'s entries must be finite and at most {LARGEST:e}"
            ));
        }
        if <Dim<D> as Rigid<D>>::determinant(&linear) <= 0.0 {
            return Err("`matrix` must keep orientation (positive determinant)".into());
        }
        let rotation = <Dim<D> as Rigid<D>>::nearest_rotation(&linear);
        Ok(Self {
            pivot: None,
            rotation,
            turn: <Dim<D> as Rigid<D>>::axis_angle_of(&rotation),
            stretch: rotation.transpose() * linear,
            translate: translation,
            from_matrix: true,
        })
    }

    /// Whether the motion is one map: finite, its rotation a rotation and the one its turn
    /// gives, its stretch symmetric and positive definite.
    pub fn check(&self) -> std::result::Result<(), String> {
        finite_vector(&self.translate, "translate")?;
        if let Some(p) = &self.pivot {
            finite_vector(p, "pivot")?;
        }
        let r = &self.rotation;
        let orthonormal = (r.transpose() * r - Mat::<D>::identity()).amax();
        if !(orthonormal <= ROTATION_SLACK && <Dim<D> as Rigid<D>>::determinant(r) > 0.0) {
            return Err("the rotation is not a rotation (orthonormal, determinant 1)".into());
        }
        let (axis, radians) = self.turn;
        checked_turn(&axis, radians.to_degrees())?;
        let turned = rotation_of(&axis, radians);
        let apart = (turned - r).amax();
        if apart.is_nan() || apart > ROTATION_SLACK {
            return Err(format!(
                "the turn ({:.6}° about {:?}) is not the rotation; make the motion with \
                 `HandleMotion::turning` or `HandleMotion::affine`",
                radians.to_degrees(),
                axis.as_slice()
            ));
        }
        // Symmetric, and positive but for rounding: a matrix's stretch (its polar factor) of a
        // nearly singular matrix, which the parser takes, may round a little below zero.
        let p = &self.stretch;
        let slack = ROTATION_SLACK * p.amax();
        let positive = p.iter().all(|v| v.is_finite())
            && (p - p.transpose()).amax() <= ROTATION_SLACK * p.amax().max(1.0)
            && (p + Mat::<D>::identity() * slack).cholesky().is_some();
        if !positive {
            return Err("the stretch is not symmetric positive definite".into());
        }
        Ok(())
    }
}

/// The rotation by `radians` about `axis`: the identity for no turn, whatever the axis.
fn rotation_of<const D: usize>(axis: &Vect<D>, radians: f64) -> Mat<D>
where
    Dim<D>: Rigid<D>,
{
    match radians {
        0.0 => Mat::<D>::identity(),
        _ => <Dim<D> as Rigid<D>>::axis_angle(axis, radians),
    }
}

/// `degrees` when it is a turn the spec may ask for about `axis`.
fn checked_turn<const D: usize>(axis: &Vect<D>, degrees: f64) -> std::result::Result<f64, String> {
    if !degrees.is_finite() {
        return Err("the turn's degrees must be finite".into());
    }
    if degrees.abs() > MAX_TURN_DEGREES {
        return Err(format!(
            "a turn of {degrees}° is more than ten whole turns (at most ±{MAX_TURN_DEGREES}°)"
        ));
    }
    finite_vector(axis, "the turn's axis")?;
    if D == 3 && degrees != 0.0 && axis.norm() == 0.0 {
        return Err("the turn's axis is zero".into());
    }
    Ok(degrees)
}

fn finite_vector<const D: usize>(v: &Vect<D>, what: &str) -> std::result::Result<(), String> {
    match v.iter().all(|x| x.is_finite() && x.abs() <= LARGEST) {
        true => Ok(()),
        false => Err(format!(
            "{what} must be {D} finite numbers of at most {LARGEST:e}, got {}",
            crate::human::list(v.as_slice())
        )),
    }
}

/// Whether `region` selects as a written one may: no NaN, corners in order, a radius of at
/// least 0, a nonzero normal, polygons of three vertices or more. Regions are not bounded by
/// [`LARGEST`] (a box to ±1e308 says "everything"), as the parser does not bound them.
fn check_region<const D: usize>(region: &Region<D>) -> std::result::Result<(), String> {
    let finite = |v: &Vect<D>, what: &str| match v.iter().all(|x| x.is_finite()) {
        true => Ok(()),
        false => Err(format!(
            "{what} must be {D} finite numbers, got {}",
            crate::human::list(v.as_slice())
        )),
    };
    let numbers = |v: &Vect<D>, what: &str| match v.iter().any(|x| x.is_nan()) {
        true => Err(format!(
            "{what} is not a number: {}",
            crate::human::list(v.as_slice())
        )),
        false => Ok(()),
    };
    let rings = |polygon: &super::Polygon| {
        for ring in &polygon.rings {
            if ring.len() < 3 || !ring.iter().flatten().all(|x| x.is_finite()) {
                return Err("a polygon's ring needs three finite vertices or more".to_string());
            }
        }
        match polygon.z {
            Some([lo, hi]) if lo.is_nan() || hi.is_nan() || lo > hi => Err(format!(
                "the polygon's heights [{lo}, {hi}] are not in order"
            )),
            _ => Ok(()),
        }
    };
    match region {
        Region::Box { min, max } => {
            numbers(min, "box.min")?;
            numbers(max, "box.max")?;
            match (0..D).any(|a| min[a] > max[a]) {
                true => Err("box.min exceeds box.max".into()),
                false => Ok(()),
            }
        }
        Region::Sphere { center, radius } => {
            finite(center, "sphere.center")?;
            match radius.is_finite() && *radius >= 0.0 {
                true => Ok(()),
                false => Err(format!("sphere.radius {radius} must be ≥ 0")),
            }
        }
        Region::Plane { point, normal } => {
            finite(point, "plane.point")?;
            finite(normal, "plane.normal")?;
            match normal.norm() > 0.0 {
                true => Ok(()),
                false => Err("plane.normal is zero".into()),
            }
        }
        Region::Polygon(polygon) => rings(polygon),
        Region::Screen { view, polygon, .. } => {
            match view.iter().flatten().all(|x| x.is_finite()) {
                true => rings(polygon),
                false => Err("the screen's view matrix must be finite".into()),
            }
        }
        Region::All(all) if all.is_empty() => Err("an entry needs a region".into()),
        Region::All(all) => all.iter().try_for_each(check_region),
        Region::Not(inner) => check_region(inner),
        Region::Indices { .. } | Region::Classification(_) => Ok(()),
    }
}

impl<const D: usize> EditSpec<D>
where
    Dim<D>: Rigid<D>,
{
    /// Refuses what the parser would refuse in a written spec ([`Error::Spec`], naming the
    /// entry): regions with NaN or corners out of order, handle motions that are not one map
    /// ([`HandleMotion::check`]), pins, targets and weights that are not finite, stiffness
    /// scales that are not positive.
    pub fn validate(&self) -> Result<()> {
        let fail = |what: Said, message: String| {
            let path = if self.name.as_os_str().is_empty() {
                "<edit spec>".into()
            } else {
                self.name.clone()
            };
            Error::spec(path, None, what.text(format!(": {message}")))
        };
        for (k, e) in self.fixed.iter().enumerate() {
            let what = entry("fixed", k, e.line);
            check_region(&e.region).map_err(|m| fail(what, m))?;
        }
        for (k, e) in self.handles.iter().enumerate() {
            let what = || entry("handle", k, e.line);
            check_region(&e.region).map_err(|m| fail(what(), m))?;
            e.value.check().map_err(|m| fail(what(), m))?;
        }
        for (k, e) in self.stiffness.iter().enumerate() {
            let what = || entry("stiffness", k, e.line);
            check_region(&e.region).map_err(|m| fail(what(), m))?;
            if !(e.value.is_finite() && e.value > 0.0) {
                return Err(fail(what(), format!("scale {} must be positive", e.value)));
            }
        }
        for (k, p) in self.pins.iter().enumerate() {
            let what = || entry("pin", k, p.line);
            finite_vector(&p.point, "point").map_err(|m| fail(what(), m))?;
            finite_vector(&p.to, "to").map_err(|m| fail(what(), m))?;
        }
        for (k, t) in self.targets.iter().enumerate() {
            let what = || entry("target", k, t.line);
            // A horizontal point's height is found on the samples.
            let mut from = t.from;
            if t.horizontal {
                from[D - 1] = 0.0;
            }
            finite_vector(&from, "from").map_err(|m| fail(what(), m))?;
            finite_vector(&t.to, "to").map_err(|m| fail(what(), m))?;
            if !(t.weight.is_finite() && t.weight >= 0.0) {
                return Err(fail(what(), format!("weight {} must be ≥ 0", t.weight)));
            }
            if let Some(s) = t.snap
                && !(s.is_finite() && s >= 0.0)
            {
                return Err(fail(what(), format!("snap {s} must be ≥ 0")));
            }
        }
        Ok(())
    }
}

/// An entry named for messages ([`crate::said::Part::Entry`]): `handle #2`, with its line
/// when it was written in a file.
fn entry(kind: &'static str, k: usize, line: usize) -> Said {
    Said::new().entry(kind, k, line)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::Entry;

    fn spec_with(motion: HandleMotion<3>) -> EditSpec<3> {
        EditSpec {
            handles: vec![Entry {
                region: Region::Sphere {
                    center: Vect::<3>::zeros(),
                    radius: 1.0,
                },
                value: motion,
                line: 0,
            }],
            ..EditSpec::default()
        }
    }

    #[test]
    fn a_spec_made_in_code_is_refused_as_a_written_one() {
        let z = Vect::<3>::z();
        let turn = HandleMotion::turning(z, 30.0, 1.0, None, Vect::<3>::zeros()).unwrap();
        spec_with(turn).validate().unwrap();
        // A rotation of 3·I.
        let tripled = HandleMotion {
            rotation: Mat::<3>::identity() * 3.0,
            ..turn
        };
        let e = spec_with(tripled).validate().unwrap_err().to_string();
        assert!(
            e.contains("handle #1: the rotation is not a rotation"),
            "{e}"
        );
        assert!(!e.contains("line 0"), "{e}");
        // A turn that is not its rotation.
        let unturned = HandleMotion {
            rotation: Mat::<3>::identity(),
            ..turn
        };
        let e = spec_with(unturned).validate().unwrap_err().to_string();
        assert!(e.contains("is not the rotation"), "{e}");
        // A NaN translation, from the constructor and in the spec.
        let nan = Vect::<3>::new(f64::NAN, 0.0, 0.0);
        assert!(HandleMotion::turning(z, 30.0, 1.0, None, nan).is_err());
        let e = spec_with(HandleMotion {
            translate: nan,
            ..turn
        })
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("translate must be 3 finite numbers"), "{e}");
        // A sphere of radius −1.
        let mut spec = spec_with(turn);
        spec.handles[0].region = Region::Sphere {
            center: Vect::<3>::zeros(),
            radius: -1.0,
        };
        let e = spec.validate().unwrap_err().to_string();
        assert!(
            e.contains("<edit spec>: handle #1: sphere.radius -1 must be ≥ 0"),
            "{e}"
        );
        // Regions are not bounded: a sphere as far as the parser takes one.
        spec.handles[0].region = Region::Sphere {
            center: Vect::<3>::new(1e300, 0.0, 0.0),
            radius: 1e300,
        };
        spec.validate().unwrap();
        // A matrix that mirrors.
        let mirror = Mat::<3>::from_diagonal(&Vect::<3>::new(1.0, 1.0, -1.0));
        assert!(HandleMotion::affine(mirror, Vect::<3>::zeros()).is_err());
    }

    /// The constructors make what the parser makes from the same words.
    #[test]
    fn the_constructors_are_the_parsers_motions() {
        let text = "[[handle]]\nsphere = { center = [0, 0, 0], radius = 1 }\n\
                    rotate = { axis = [0, 0, 1], degrees = 400 }\nscale = 2\n\
                    pivot = [1, 2, 3]\ntranslate = [4, 5, 6]\n\
                    [[handle]]\nsphere = { center = [5, 0, 0], radius = 1 }\n\
                    matrix = [[0, -2, 0, 1], [2, 0, 0, 2], [0, 0, 2, 3], [0, 0, 0, 1]]\n";
        let spec = crate::spec::parse_spec::<3>(text, ".".as_ref(), "t.toml".as_ref()).unwrap();
        spec.validate().unwrap();
        let v = |x: f64, y: f64, z: f64| Vect::<3>::new(x, y, z);
        let turning = HandleMotion::turning(
            v(0.0, 0.0, 1.0),
            400.0,
            2.0,
            Some(v(1.0, 2.0, 3.0)),
            v(4.0, 5.0, 6.0),
        );
        assert_eq!(spec.handles[0].value, turning.unwrap());
        let linear = Mat::<3>::new(0.0, -2.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 2.0);
        let affine = HandleMotion::affine(linear, v(1.0, 2.0, 3.0)).unwrap();
        assert_eq!(spec.handles[1].value, affine);
        // A matrix the parser takes, however nearly singular, is one map.
        let thin = Mat::<3>::new(1.0, 1.0 - 1e-15, 0.0, 1.0, 1.0, 0.0, 0.3, 0.1, 1e-9);
        assert!(<Dim<3> as Rigid<3>>::determinant(&thin) > 0.0);
        HandleMotion::affine(thin, v(0.0, 0.0, 0.0))
            .unwrap()
            .check()
            .unwrap();
    }
}
