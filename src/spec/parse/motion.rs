//! A handle's motion: its `translate`, `rotate` (axis and degrees), `scale` and `pivot`, or a
//! general affine `matrix`, split into rotation and stretch so that load steps can interpolate
//! it.

use serde::Deserialize;

use super::Ctx;
use crate::error::Result;
use crate::rigid::{Dim, Mat, Rigid, Vect};
use crate::spec::entries::HandleMotion;

/// The largest turn a handle may ask for, in degrees: ten whole turns. Load steps interpolate
/// the angle (at most 30° a step), so the solver's work grows with it.
pub const MAX_TURN_DEGREES: f64 = 3600.0;

#[derive(Deserialize)]
struct RawRotate {
    #[serde(default)]
    axis: Option<Vec<f64>>,
    degrees: f64,
}

impl Ctx<'_> {
    /// A handle's motion: `translate`, `rotate`, `scale` and `pivot`, or a `matrix`.
    pub(super) fn handle_motion<const D: usize>(
        &self,
        t: &toml::Table,
        line: usize,
    ) -> Result<HandleMotion<D>>
    where
        Dim<D>: Rigid<D>,
    {
        if t.contains_key("matrix") {
            if let Some(k) = ["translate", "rotate", "scale", "pivot"]
                .iter()
                .find(|k| t.contains_key(**k))
            {
                return Err(self.error(
                    Some(line),
                    format!("`matrix` and `{k}` cannot be combined; give one or the other"),
                ));
            }
            let m = self.square(t, "matrix", D + 1, line)?;
            return self.matrix_motion(&m, line);
        }
        let translate = match t.get("translate") {
            Some(_) => self.motion_vector(t, "translate", line)?,
            None => Vect::<D>::zeros(),
        };
        let pivot = match t.get("pivot") {
            Some(_) => Some(self.motion_vector(t, "pivot", line)?),
            None => None,
        };
        let scale: f64 = match t.get("scale") {
            Some(_) => self.field(t, "scale", line)?,
            None => 1.0,
        };
        if !(scale.is_finite() && scale > 0.0) {
            return Err(self.error(
                self.at(line, "scale"),
                format!("scale {scale} must be positive"),
            ));
        }
        self.within_range(scale, "scale", line)?;
        let (axis, degrees) = match t.get("rotate") {
            Some(_) => {
                let r: RawRotate = self.field(t, "rotate", line)?;
                let axis = match (&r.axis, D) {
                    (Some(a), _) => self.to_vect::<D>(a, "rotate.axis", line)?,
                    (None, 2) => Vect::<D>::zeros(),
                    (None, _) => {
                        return Err(self.error(
                            self.at(line, "rotate"),
                            "rotate needs an `axis` in 3D".into(),
                        ));
                    }
                };
                if D == 3 && axis.norm() == 0.0 {
                    return Err(self.error(self.at(line, "rotate"), "rotate.axis is zero".into()));
                }
                if !r.degrees.is_finite() {
                    return Err(self.error(
                        self.at(line, "rotate"),
                        "rotate.degrees must be finite".into(),
                    ));
                }
                if r.degrees.abs() > MAX_TURN_DEGREES {
                    return Err(self.error(
                        self.at(line, "rotate"),
                        format!(
                            "rotate.degrees = {} is more than ten whole turns (at most \
                             ±{MAX_TURN_DEGREES}); each whole turn costs the solver a dozen \
                             load steps",
                            r.degrees
                        ),
                    ));
                }
                (axis, r.degrees)
            }
            None => (Vect::<D>::zeros(), 0.0),
        };
        HandleMotion::turning(axis, degrees, scale, pivot, translate)
            .map_err(|m| self.error(Some(line), m))
    }

    /// `A(x) = L x + t` with `L = R·P` split by polar decomposition, so that load steps can
    /// interpolate the rotation by angle.
    fn matrix_motion<const D: usize>(&self, m: &[Vec<f64>], line: usize) -> Result<HandleMotion<D>>
    where
        Dim<D>: Rigid<D>,
    {
        if (0..D).any(|c| m[D][c] != 0.0) || m[D][D] != 1.0 {
            return Err(self.error(
                self.at_element(line, "matrix", &[D]),
                format!(
                    "`matrix` must be finite with last row [0 … 0 1], got {}",
                    crate::human::list(&m[D])
                ),
            ));
        }
        let cells = m
            .iter()
            .enumerate()
            .flat_map(|(r, row)| row.iter().enumerate().map(move |(c, v)| (r, c, v.abs())));
        let (r, c, largest) = cells.fold((0, 0, 0.0f64), |a, b| if b.2 > a.2 { b } else { a });
        if largest > super::LARGEST {
            // Named by the line of its row.
            let at = self.at_element(line, "matrix", &[r, c]);
            return Err(self.error(at, self.beyond_range(largest, "matrix")));
        }
        let linear = Mat::<D>::from_fn(|r, c| m[r][c]);
        HandleMotion::affine(linear, Vect::<D>::from_fn(|r, _| m[r][D]))
            .map_err(|e| self.error(self.at(line, "matrix"), e))
    }
}
