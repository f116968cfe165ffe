//! The edit spec (DESIGN §8): which samples are fixed, which are handles and where they go,
//! pins, soft targets and stiffness regions, in TOML, in the input's own coordinates.
//!
//! ```toml
//! [[fixed]]
//! box = { min = [0.0, 0.0, 0.0], max = [0.5, 1.0, 1.0] }
//!
//! [[handle]]
//! sphere = { center = [9.75, 0.5, 0.5], radius = 0.5 }  # or box, or plane = {point, normal}
//! translate = [0.0, 0.0, 4.0]
//! rotate = { axis = [0.0, 1.0, 0.0], degrees = -90.0 }  # about `pivot` (default: the centroid)
//! # scale = 1.0, pivot = [..], or matrix = [[..],[..],[..],[..]] instead of the parts
//!
//! [[pin]]
//! point = [5.0, 0.5, 1.0]
//! to = [5.0, 0.5, 1.5]
//!
//! [[target]]
//! from = [1.0, 0.5, 1.0]
//! to = [1.0, 0.5, 1.2]
//! weight = 1.0          # or file = "gcp.csv" with rows x,y,z,x2,y2,z2[,weight]
//!
//! [[stiffness]]
//! box = { min = [4.0, 0.0, 0.0], max = [6.0, 1.0, 1.0] }
//! scale = 0.2
//! ```
//!
//! A region is one of `box`, `sphere`, `plane` (the half-space behind `normal`, i.e. the points
//! `x` with `(x − point)·normal ≤ 0`), `indices = "file.txt"` (sample indices, whitespace or
//! comma separated, 0-based) or `classification = [..]` (LAS classes). A handle's transform is
//! `A(x) = S·R·(x − pivot) + pivot + translate`, or a general affine `matrix` (row-major 4×4 in
//! 3D, 3×3 in 2D, last row `0 … 0 1`). Unknown keys are errors, so typos do not pass silently;
//! every error names the line.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::error::{Error, Result};
use crate::rigid::{Dim, Mat, Rigid, Vect};

/// A region of the edit spec: it selects samples.
#[derive(Debug, Clone, PartialEq)]
pub enum Region<const D: usize> {
    /// The closed axis-aligned box `[min, max]`.
    Box {
        /// Lower corner.
        min: Vect<D>,
        /// Upper corner.
        max: Vect<D>,
    },
    /// The closed ball.
    Sphere {
        /// Center.
        center: Vect<D>,
        /// Radius.
        radius: f64,
    },
    /// The half-space `(x − point)·normal ≤ 0`.
    Plane {
        /// A point on the plane.
        point: Vect<D>,
        /// The outward normal of the half-space.
        normal: Vect<D>,
    },
    /// Samples by index.
    Indices(HashSet<u64>),
    /// Samples by LAS classification.
    Classification(HashSet<u8>),
}

impl<const D: usize> Region<D> {
    /// Whether the region is a region of space (a box, sphere or half-space), as opposed to a
    /// selection of samples by index or attribute.
    pub fn is_geometric(&self) -> bool {
        matches!(
            self,
            Self::Box { .. } | Self::Sphere { .. } | Self::Plane { .. }
        )
    }

    /// Whether the point `x` (input coordinates) lies in a geometric region (always false for a
    /// selection by index or attribute).
    pub fn contains_point(&self, x: &Vect<D>) -> bool {
        match self {
            Self::Box { min, max } => (0..D).all(|a| x[a] >= min[a] && x[a] <= max[a]),
            Self::Sphere { center, radius } => (x - center).norm_squared() <= radius * radius,
            Self::Plane { point, normal } => (x - point).dot(normal) <= 0.0,
            Self::Indices(_) | Self::Classification(_) => false,
        }
    }

    /// Whether the region selects sample `index` at `x` with LAS class `class`.
    pub fn selects(&self, index: u64, x: &Vect<D>, class: Option<u8>) -> bool {
        match self {
            Self::Indices(set) => set.contains(&index),
            Self::Classification(set) => class.is_some_and(|c| set.contains(&c)),
            _ => self.contains_point(x),
        }
    }
}

/// How a handle moves: `A(x) = R·P·(x − pivot) + pivot + translate`, with `R` a rotation and `P`
/// a stretch (`S·I` for a uniform scale). A general affine matrix is stored in this form by polar
/// decomposition, so that load steps can interpolate it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandleMotion<const D: usize> {
    /// The center of rotation and scaling (input coordinates); `None`: the centroid of the
    /// handle's selected samples.
    pub pivot: Option<Vect<D>>,
    /// The rotation `R`.
    pub rotation: Mat<D>,
    /// The rotation as written: its axis (unused in 2D) and signed angle in radians, of any
    /// size (720° is two whole turns). Load steps interpolate this angle, so a whole turn is
    /// not the identity. For a `matrix` it is the angle of `R` in `[0, π]`: a matrix cannot
    /// say how many turns it makes.
    pub turn: (Vect<D>, f64),
    /// The stretch `P`.
    pub stretch: Mat<D>,
    /// The translation.
    pub translate: Vect<D>,
    /// Whether the motion came from a `matrix`: then it is `A(x) = R·P·x + translate` exactly,
    /// whatever the pivot, and the pivot only centers the load-step interpolation.
    pub from_matrix: bool,
}

impl<const D: usize> HandleMotion<D> {
    /// The affine map at load fraction `f ∈ [0, 1]` about the pivot `pivot` (used when the
    /// motion has none of its own): rotation angle, stretch and translation grow linearly from
    /// the identity, so `f = 1` gives the full motion.
    pub fn at(&self, f: f64, pivot: &Vect<D>) -> crate::rigid::Affine<D>
    where
        Dim<D>: Rigid<D>,
    {
        let c = if self.from_matrix {
            *pivot
        } else {
            self.pivot.unwrap_or(*pivot)
        };
        let linear_full = self.rotation * self.stretch;
        // The translation that makes the motion about `c` equal to the specified map.
        let t_full = if self.from_matrix {
            linear_full * c + self.translate - c
        } else {
            self.translate
        };
        let (axis, angle) = self.turn;
        let rot = if f == 1.0 {
            self.rotation
        } else {
            <Dim<D> as Rigid<D>>::axis_angle(&axis, f * angle)
        };
        let stretch = Mat::<D>::identity() + (self.stretch - Mat::<D>::identity()) * f;
        let linear = rot * stretch;
        crate::rigid::Affine {
            linear,
            translation: c - linear * c + t_full * f,
        }
    }
}

/// One `[[fixed]]` or `[[stiffness]]` entry, or the region of a handle.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry<const D: usize, T> {
    /// The region.
    pub region: Region<D>,
    /// What the entry does.
    pub value: T,
    /// The line of the entry in the spec (1-based).
    pub line: usize,
}

/// A pin: the point `point` goes to `to`; its cell may rotate about it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pin<const D: usize> {
    /// The point (input coordinates).
    pub point: Vect<D>,
    /// Where it goes.
    pub to: Vect<D>,
    /// The line of the entry (1-based).
    pub line: usize,
}

/// A soft target: the point `from` should land on `to`, with weight `weight`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target<const D: usize> {
    /// The point (input coordinates).
    pub from: Vect<D>,
    /// Where it should go.
    pub to: Vect<D>,
    /// Weight, relative to the glue between two finest cells.
    pub weight: f64,
    /// The line of the entry (1-based).
    pub line: usize,
}

/// A parsed and validated edit spec.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EditSpec<const D: usize> {
    /// Fixed regions.
    pub fixed: Vec<Entry<D, ()>>,
    /// Handles.
    pub handles: Vec<Entry<D, HandleMotion<D>>>,
    /// Pins.
    pub pins: Vec<Pin<D>>,
    /// Soft targets.
    pub targets: Vec<Target<D>>,
    /// Stiffness regions with their scale.
    pub stiffness: Vec<Entry<D, f64>>,
}

impl<const D: usize> EditSpec<D> {
    /// Whether the spec constrains anything (stiffness regions alone do not).
    pub fn has_constraints(&self) -> bool {
        !(self.fixed.is_empty()
            && self.handles.is_empty()
            && self.pins.is_empty()
            && self.targets.is_empty())
    }
}

#[derive(Deserialize)]
struct RawSpec {
    #[serde(default)]
    fixed: Vec<Spanned<toml::Table>>,
    #[serde(default)]
    handle: Vec<Spanned<toml::Table>>,
    #[serde(default)]
    pin: Vec<Spanned<toml::Table>>,
    #[serde(default)]
    target: Vec<Spanned<toml::Table>>,
    #[serde(default)]
    stiffness: Vec<Spanned<toml::Table>>,
}

#[derive(Deserialize)]
struct RawBox {
    min: Vec<f64>,
    max: Vec<f64>,
}
#[derive(Deserialize)]
struct RawSphere {
    center: Vec<f64>,
    radius: f64,
}
#[derive(Deserialize)]
struct RawPlane {
    point: Vec<f64>,
    normal: Vec<f64>,
}
#[derive(Deserialize)]
struct RawRotate {
    #[serde(default)]
    axis: Option<Vec<f64>>,
    degrees: f64,
}

/// The largest magnitude of a motion's numbers (translations, pivots, pins, targets, scales,
/// matrix entries): f64 keeps 15–16 significant digits, so a shape moved to 1e15 keeps none
/// below the unit, and past about 1e50 the solver's squared residuals overflow (a fuzzed
/// `translate = [1e308, …]` ended in an indefinite Gauss-Newton system, exit 1). Regions are
/// not bounded: a box to ±1e308 is a way of saying "everything".
pub const LARGEST: f64 = 1e15;

const REGION_KEYS: [&str; 5] = ["box", "sphere", "plane", "indices", "classification"];

/// Reads and validates the edit spec in `path`.
pub fn read_spec<const D: usize>(path: &Path) -> Result<EditSpec<D>>
where
    Dim<D>: Rigid<D>,
{
    let text = std::fs::read_to_string(path).map_err(|e| Error::spec_file(path, e))?;
    parse_spec(&text, path.parent().unwrap_or(Path::new(".")), path)
}

/// Parses an edit spec. `base` is the folder that relative file names (`indices`, `file`) are
/// resolved against; `name` names the spec in errors.
pub fn parse_spec<const D: usize>(text: &str, base: &Path, name: &Path) -> Result<EditSpec<D>>
where
    Dim<D>: Rigid<D>,
{
    let ctx = Ctx { text, base, name };
    let raw: RawSpec = toml::from_str(text).map_err(|e| ctx.error(None, e.to_string()))?;
    let top: toml::Table = toml::from_str(text).map_err(|e| ctx.error(None, e.to_string()))?;
    if let Some(k) = top
        .keys()
        .find(|k| !["fixed", "handle", "pin", "target", "stiffness"].contains(&k.as_str()))
    {
        return Err(ctx.error(
            None,
            format!("unknown section `{k}` (expected fixed, handle, pin, target or stiffness)"),
        ));
    }
    let mut spec = EditSpec::default();
    for t in &raw.fixed {
        let line = ctx.line(t);
        ctx.allow(t.get_ref(), &[], line)?;
        spec.fixed.push(Entry {
            region: ctx.region(t.get_ref(), line)?,
            value: (),
            line,
        });
    }
    for t in &raw.handle {
        let line = ctx.line(t);
        ctx.allow(
            t.get_ref(),
            &["translate", "rotate", "scale", "pivot", "matrix"],
            line,
        )?;
        spec.handles.push(Entry {
            region: ctx.region(t.get_ref(), line)?,
            value: ctx.handle_motion(t.get_ref(), line)?,
            line,
        });
    }
    for t in &raw.pin {
        let line = ctx.line(t);
        ctx.allow_only(t.get_ref(), &["point", "to"], line)?;
        spec.pins.push(Pin {
            point: ctx.motion_vector(t.get_ref(), "point", line)?,
            to: ctx.motion_vector(t.get_ref(), "to", line)?,
            line,
        });
    }
    for t in &raw.target {
        let line = ctx.line(t);
        ctx.allow_only(t.get_ref(), &["from", "to", "weight", "file"], line)?;
        spec.targets.extend(ctx.targets(t.get_ref(), line)?);
    }
    for t in &raw.stiffness {
        let line = ctx.line(t);
        ctx.allow(t.get_ref(), &["scale"], line)?;
        let scale: f64 = ctx.field(t.get_ref(), "scale", line)?;
        if !(scale.is_finite() && scale > 0.0) {
            return Err(ctx.error(
                Some(line),
                format!("stiffness scale {scale} must be positive"),
            ));
        }
        spec.stiffness.push(Entry {
            region: ctx.region(t.get_ref(), line)?,
            value: scale,
            line,
        });
    }
    if !spec.has_constraints() {
        return Err(Error::NoConstraints);
    }
    Ok(spec)
}

struct Ctx<'a> {
    text: &'a str,
    base: &'a Path,
    name: &'a Path,
}

impl Ctx<'_> {
    fn error(&self, line: Option<usize>, message: String) -> Error {
        let message = match line {
            Some(l) => format!("line {l}: {message}"),
            None => message,
        };
        Error::Spec {
            path: self.name.to_path_buf(),
            message,
        }
    }

    fn line<T>(&self, s: &Spanned<T>) -> usize {
        let start = s.span().start.min(self.text.len());
        self.text[..start].matches('\n').count() + 1
    }

    fn allow(&self, t: &toml::Table, extra: &[&str], line: usize) -> Result<()> {
        let keys: Vec<&str> = REGION_KEYS.iter().chain(extra).copied().collect();
        self.allow_only(t, &keys, line)
    }

    fn allow_only(&self, t: &toml::Table, keys: &[&str], line: usize) -> Result<()> {
        match t.keys().find(|k| !keys.contains(&k.as_str())) {
            Some(k) => Err(self.error(
                Some(line),
                format!("unknown key `{k}` (expected one of {})", keys.join(", ")),
            )),
            None => Ok(()),
        }
    }

    fn field<T: serde::de::DeserializeOwned>(
        &self,
        t: &toml::Table,
        key: &str,
        line: usize,
    ) -> Result<T> {
        let v = t
            .get(key)
            .ok_or_else(|| self.error(Some(line), format!("missing `{key}`")))?;
        v.clone()
            .try_into()
            .map_err(|e| self.error(Some(line), format!("`{key}`: {e}")))
    }

    fn vector<const D: usize>(&self, t: &toml::Table, key: &str, line: usize) -> Result<Vect<D>> {
        let v: Vec<f64> = self.field(t, key, line)?;
        self.to_vect(&v, key, line)
    }

    /// A vector that places or moves samples (a translation, a pivot, a pin, a target): finite
    /// and at most [`LARGEST`] in magnitude.
    fn motion_vector<const D: usize>(
        &self,
        t: &toml::Table,
        key: &str,
        line: usize,
    ) -> Result<Vect<D>> {
        let v: Vect<D> = self.vector(t, key, line)?;
        self.within_range(v.amax(), key, line)?;
        Ok(v)
    }

    fn within_range(&self, magnitude: f64, key: &str, line: usize) -> Result<()> {
        if magnitude <= LARGEST {
            Ok(())
        } else {
            Err(self.error(
                Some(line),
                format!(
                    "`{key}` reaches {magnitude:e}, beyond {LARGEST:e}: a shape moved or \
                     scaled that far keeps no detail in 64-bit floats, and the solve fails"
                ),
            ))
        }
    }

    fn to_vect<const D: usize>(&self, v: &[f64], key: &str, line: usize) -> Result<Vect<D>> {
        if v.len() != D || !v.iter().all(|x| x.is_finite()) {
            return Err(self.error(
                Some(line),
                format!("`{key}` must be {D} finite numbers, got {v:?}"),
            ));
        }
        Ok(Vect::<D>::from_column_slice(v))
    }

    fn region<const D: usize>(&self, t: &toml::Table, line: usize) -> Result<Region<D>> {
        let present: Vec<&str> = REGION_KEYS
            .iter()
            .copied()
            .filter(|k| t.contains_key(*k))
            .collect();
        let [key] = present[..] else {
            return Err(self.error(
                Some(line),
                format!(
                    "an entry needs exactly one region ({}), found {}",
                    REGION_KEYS.join(", "),
                    if present.is_empty() {
                        "none".to_string()
                    } else {
                        present.join(" and ")
                    }
                ),
            ));
        };
        Ok(match key {
            "box" => {
                let b: RawBox = self.field(t, key, line)?;
                let (min, max) = (
                    self.to_vect(&b.min, "box.min", line)?,
                    self.to_vect(&b.max, "box.max", line)?,
                );
                if (0..D).any(|a| min[a] > max[a]) {
                    return Err(self.error(Some(line), "box.min exceeds box.max".into()));
                }
                Region::Box { min, max }
            }
            "sphere" => {
                let s: RawSphere = self.field(t, key, line)?;
                if !(s.radius.is_finite() && s.radius >= 0.0) {
                    return Err(self.error(Some(line), "sphere.radius must be ≥ 0".into()));
                }
                Region::Sphere {
                    center: self.to_vect(&s.center, "sphere.center", line)?,
                    radius: s.radius,
                }
            }
            "plane" => {
                let p: RawPlane = self.field(t, key, line)?;
                let normal: Vect<D> = self.to_vect(&p.normal, "plane.normal", line)?;
                if normal.norm() == 0.0 {
                    return Err(self.error(Some(line), "plane.normal is zero".into()));
                }
                Region::Plane {
                    point: self.to_vect(&p.point, "plane.point", line)?,
                    normal,
                }
            }
            "indices" => {
                let file: String = self.field(t, key, line)?;
                Region::Indices(self.read_indices(&file, line)?)
            }
            _ => {
                let classes: Vec<u8> = self.field(t, key, line)?;
                Region::Classification(classes.into_iter().collect())
            }
        })
    }

    fn resolve(&self, file: &str) -> PathBuf {
        self.base.join(file)
    }

    fn read_indices(&self, file: &str, line: usize) -> Result<HashSet<u64>> {
        let path = self.resolve(file);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::spec_file(&path, e))?;
        text.split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<u64>().map_err(|_| {
                    self.error(
                        Some(line),
                        format!("{}: `{s}` is not a sample index", path.display()),
                    )
                })
            })
            .collect()
    }

    fn handle_motion<const D: usize>(&self, t: &toml::Table, line: usize) -> Result<HandleMotion<D>>
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
            let m: Vec<Vec<f64>> = self.field(t, "matrix", line)?;
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
            return Err(self.error(Some(line), format!("scale {scale} must be positive")));
        }
        self.within_range(scale, "scale", line)?;
        let (rotation, turn) = match t.get("rotate") {
            Some(_) => {
                let r: RawRotate = self.field(t, "rotate", line)?;
                let axis = match (&r.axis, D) {
                    (Some(a), _) => self.to_vect::<D>(a, "rotate.axis", line)?,
                    (None, 2) => Vect::<D>::zeros(),
                    (None, _) => {
                        return Err(self.error(Some(line), "rotate needs an `axis` in 3D".into()));
                    }
                };
                if D == 3 && axis.norm() == 0.0 {
                    return Err(self.error(Some(line), "rotate.axis is zero".into()));
                }
                if !r.degrees.is_finite() {
                    return Err(self.error(Some(line), "rotate.degrees must be finite".into()));
                }
                let radians = r.degrees.to_radians();
                (
                    <Dim<D> as Rigid<D>>::axis_angle(&axis, radians),
                    (axis, radians),
                )
            }
            None => (Mat::<D>::identity(), (Vect::<D>::zeros(), 0.0)),
        };
        Ok(HandleMotion {
            pivot,
            rotation,
            turn,
            stretch: Mat::<D>::identity() * scale,
            translate,
            from_matrix: false,
        })
    }

    /// `A(x) = L x + t` with `L = R·P` split by polar decomposition, so that load steps can
    /// interpolate the rotation by angle.
    fn matrix_motion<const D: usize>(&self, m: &[Vec<f64>], line: usize) -> Result<HandleMotion<D>>
    where
        Dim<D>: Rigid<D>,
    {
        let n = D + 1;
        if m.len() != n || m.iter().any(|r| r.len() != n) {
            return Err(self.error(
                Some(line),
                format!("`matrix` must be {n} rows of {n} numbers"),
            ));
        }
        if m.iter().flatten().any(|v| !v.is_finite())
            || (0..D).any(|c| m[D][c] != 0.0)
            || m[D][D] != 1.0
        {
            return Err(self.error(
                Some(line),
                format!(
                    "`matrix` must be finite with last row [0 … 0 1], got {:?}",
                    m[D]
                ),
            ));
        }
        let largest = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
        self.within_range(largest, "matrix", line)?;
        let linear = Mat::<D>::from_fn(|r, c| m[r][c]);
        if <Dim<D> as Rigid<D>>::determinant(&linear) <= 0.0 {
            return Err(self.error(
                Some(line),
                "`matrix` must keep orientation (positive determinant)".into(),
            ));
        }
        let rotation = <Dim<D> as Rigid<D>>::nearest_rotation(&linear);
        Ok(HandleMotion {
            pivot: None,
            rotation,
            turn: <Dim<D> as Rigid<D>>::axis_angle_of(&rotation),
            stretch: rotation.transpose() * linear,
            translate: Vect::<D>::from_fn(|r, _| m[r][D]),
            from_matrix: true,
        })
    }

    fn targets<const D: usize>(&self, t: &toml::Table, line: usize) -> Result<Vec<Target<D>>> {
        let weight: f64 = match t.get("weight") {
            Some(_) => self.field(t, "weight", line)?,
            None => 1.0,
        };
        if !(weight.is_finite() && weight > 0.0) {
            return Err(self.error(Some(line), format!("weight {weight} must be positive")));
        }
        if let Some(file) = t.get("file") {
            if t.contains_key("from") || t.contains_key("to") {
                return Err(self.error(
                    Some(line),
                    "`file` and `from`/`to` exclude each other".into(),
                ));
            }
            let file: String = file
                .clone()
                .try_into()
                .map_err(|e| self.error(Some(line), format!("`file`: {e}")))?;
            return self.read_targets(&file, weight, line);
        }
        Ok(vec![Target {
            from: self.motion_vector(t, "from", line)?,
            to: self.motion_vector(t, "to", line)?,
            weight,
            line,
        }])
    }

    fn read_targets<const D: usize>(
        &self,
        file: &str,
        weight: f64,
        line: usize,
    ) -> Result<Vec<Target<D>>> {
        let path = self.resolve(file);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::spec_file(&path, e))?;
        let mut out = Vec::new();
        for (k, row) in text.lines().enumerate() {
            let row = row.trim();
            if row.is_empty() || row.starts_with('#') {
                continue;
            }
            let vals: std::result::Result<Vec<f64>, _> = row
                .split(|c: char| c == ',' || c.is_whitespace())
                .filter(|s| !s.is_empty())
                .map(str::parse::<f64>)
                .collect();
            // A malformed file the spec names is a problem of the spec (exit 4).
            let bad = || Error::Spec {
                path: path.clone(),
                message: format!(
                    "line {}: expected {} or {} numbers",
                    k + 1,
                    2 * D,
                    2 * D + 1
                ),
            };
            let vals = match vals {
                Ok(v) => v,
                // A header row of column names is allowed as the first row.
                Err(_) if out.is_empty() && k == 0 => continue,
                Err(_) => return Err(bad()),
            };
            if (vals.len() != 2 * D && vals.len() != 2 * D + 1)
                || vals.iter().any(|v| !v.is_finite())
            {
                return Err(bad());
            }
            let w = if vals.len() > 2 * D {
                vals[2 * D]
            } else {
                weight
            };
            out.push(Target {
                from: Vect::<D>::from_column_slice(&vals[..D]),
                to: Vect::<D>::from_column_slice(&vals[D..2 * D]),
                weight: w,
                line,
            });
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<EditSpec<3>> {
        parse_spec(text, Path::new("."), Path::new("edit.toml"))
    }

    #[test]
    fn parses_the_design_example() {
        let spec = parse(
            r#"
[[fixed]]
box = { min = [0.0, 0.0, 0.0], max = [1.0, 10.0, 10.0] }

[[handle]]
sphere = { center = [9.0, 5.0, 5.0], radius = 1.0 }
translate = [0.0, 0.0, 4.0]
rotate = { axis = [0.0, 1.0, 0.0], degrees = 90.0 }

[[pin]]
point = [5.0, 5.0, 9.0]
to = [5.0, 5.0, 11.0]

[[target]]
from = [1.0, 2.0, 3.0]
to = [1.1, 2.0, 3.2]
weight = 1.0

[[stiffness]]
plane = { point = [5.0, 0.0, 0.0], normal = [1.0, 0.0, 0.0] }
scale = 0.2
"#,
        )
        .unwrap();
        assert_eq!(spec.fixed.len(), 1);
        assert_eq!(spec.handles[0].line, 5);
        let h = spec.handles[0].value;
        let x = h.rotation * Vect::<3>::new(1.0, 0.0, 0.0);
        assert!((x - Vect::<3>::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        assert_eq!(spec.pins.len(), 1);
        assert_eq!(spec.targets[0].weight, 1.0);
        assert!(
            spec.stiffness[0]
                .region
                .contains_point(&Vect::<3>::new(4.0, 9.0, 9.0))
        );
    }

    #[test]
    fn errors_name_the_line() {
        let e = parse("[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n\n[[handle]]\nsphere = { center = [0.0, 0.0], radius = 1.0 }\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 4") && e.contains("3 finite numbers"),
            "{e}"
        );
        let e = parse(
            "[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nradius = 3\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("line 1") && e.contains("unknown key `radius`"),
            "{e}"
        );
        let e = parse("[[fixed]\n").unwrap_err().to_string();
        assert!(e.contains("line 1"), "{e}");
        let e = parse("[[handle]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nmatrix = [[1.0,0.0,0.0,0.0],[0.0,1.0,0.0,0.0],[0.0,0.0,1.0,0.0],[0.0,0.0,0.0,1.0]]\nscale = 2.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot be combined"), "{e}");
    }

    #[test]
    fn no_constraint_is_an_error() {
        assert!(matches!(parse(""), Err(Error::NoConstraints)));
        assert!(matches!(
            parse(
                "[[stiffness]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nscale = 2.0\n"
            ),
            Err(Error::NoConstraints)
        ));
    }

    #[test]
    fn matrix_is_split_into_rotation_and_stretch() {
        let spec = parse("[[handle]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nmatrix = [[0.0,-2.0,0.0,1.0],[2.0,0.0,0.0,0.0],[0.0,0.0,2.0,0.0],[0.0,0.0,0.0,1.0]]\n").unwrap();
        let h = spec.handles[0].value;
        let l = h.rotation * h.stretch;
        assert!((l - Mat::<3>::new(0.0, -2.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 2.0)).norm() < 1e-12);
        assert_eq!(h.translate, Vect::<3>::new(1.0, 0.0, 0.0));
    }
}
