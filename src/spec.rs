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
//! weight = 1.0          # or file = "gcp.csv": control points ([`read_control_points`])
//! # snap = 5.0          # move `from` to the nearest sample within 5 units first
//!
//! [[stiffness]]
//! box = { min = [4.0, 0.0, 0.0], max = [6.0, 1.0, 1.0] }
//! scale = 0.2
//! ```
//!
//! A region is one or more of `box`, `sphere`, `plane` (the half-space behind `normal`, i.e.
//! the points `x` with `(x − point)·normal ≤ 0`), `polygon = [[x, y], ..]` or
//! `polygon_file = "area.geojson"` (a prism over x, y, with an optional height range
//! `z = [lo, hi]`; or, with `view = [[..] × 4]`, a lasso drawn on a screen: the polygon is in
//! the view's normalized device coordinates `[-1, 1]²` and the region is every point in front
//! of the camera that the 4×4 world-to-clip matrix projects into it, as the editor writes it;
//! with `visible = true` as well, only the samples whose cell the camera sees, the front
//! surface: [`crate::solve::Sight`] states the rule),
//! `indices = "file.txt"` (sample indices, whitespace or comma separated,
//! 0-based) or `classification = [..]` (LAS classes); several in one entry combine (a sample
//! must satisfy all), and `invert = true` takes the rest. A handle's transform is
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
    /// The prism over a polygon in the first two coordinates (x, y), between heights `z`
    /// (3D; all heights when `None`). Several rings combine by the even–odd rule: a ring inside
    /// another is a hole, and disjoint rings are a union.
    Polygon(Polygon),
    /// The points in front of a camera that project into a polygon on its screen: `view` is
    /// the row-major world-to-clip matrix, the polygon's rings are in normalized device
    /// coordinates (`x/w, y/w`), `w > 0` is in front (3D; the editor's box and lasso).
    Screen {
        /// The world-to-clip matrix.
        view: [[f64; 4]; 4],
        /// The polygon on the screen (no height range).
        polygon: Polygon,
        /// Only the samples whose cell the camera sees ([`crate::solve::Sight`]): a selection
        /// of samples then, not a region of space (no cell is taken for its center alone).
        visible: bool,
    },
    /// The samples every region selects (an entry with several region keys).
    All(Vec<Region<D>>),
    /// The samples the region does not select (`invert = true`).
    Not(Box<Region<D>>),
}

/// Rings of `[x, y]` vertices (closed implicitly), with their bounding box and height range.
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    /// The rings.
    pub rings: Vec<Vec<[f64; 2]>>,
    /// The heights between which the prism lies (`None`: all).
    pub z: Option<[f64; 2]>,
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Polygon {
    /// A polygon of `rings`, between heights `z`.
    pub fn new(rings: Vec<Vec<[f64; 2]>>, z: Option<[f64; 2]>) -> Self {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for v in rings.iter().flatten() {
            for a in 0..2 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        Self { rings, z, lo, hi }
    }

    /// Whether `(x, y)` lies inside (even–odd rule; points on an edge may go either way), at
    /// height `z` when the polygon has a height range.
    pub fn contains(&self, x: f64, y: f64, z: Option<f64>) -> bool {
        if let (Some([z0, z1]), Some(z)) = (self.z, z)
            && !(z >= z0 && z <= z1)
        {
            return false;
        }
        if !(x >= self.lo[0] && x <= self.hi[0] && y >= self.lo[1] && y <= self.hi[1]) {
            return false;
        }
        let mut inside = false;
        for ring in &self.rings {
            let mut j = ring.len() - 1;
            for i in 0..ring.len() {
                let ([xi, yi], [xj, yj]) = (ring[i], ring[j]);
                if (yi > y) != (yj > y) && x < xi + (y - yi) / (yj - yi) * (xj - xi) {
                    inside = !inside;
                }
                j = i;
            }
        }
        inside
    }
}

impl<const D: usize> Region<D> {
    /// Whether the region is a region of space (a box, sphere or half-space), as opposed to a
    /// selection of samples by index or attribute.
    pub fn is_geometric(&self) -> bool {
        match self {
            Self::Box { .. } | Self::Sphere { .. } | Self::Plane { .. } | Self::Polygon(_) => true,
            Self::Screen { visible, .. } => !visible,
            Self::Indices(_) | Self::Classification(_) => false,
            Self::All(parts) => parts.iter().all(Self::is_geometric),
            Self::Not(r) => r.is_geometric(),
        }
    }

    /// Whether the region selects by LAS classification anywhere.
    pub fn uses_classes(&self) -> bool {
        match self {
            Self::Classification(_) => true,
            Self::All(parts) => parts.iter().any(Self::uses_classes),
            Self::Not(r) => r.uses_classes(),
            _ => false,
        }
    }

    /// The view of the screen selection with `visible = true` in this region (alone or among
    /// the parts of an entry), whose cells must be seen ([`crate::solve::Sight`]).
    pub fn visible_from(&self) -> Option<&[[f64; 4]; 4]> {
        match self {
            Self::Screen {
                view,
                visible: true,
                ..
            } => Some(view),
            Self::All(parts) => parts.iter().find_map(Self::visible_from),
            _ => None,
        }
    }

    /// Whether the point `x` (input coordinates) lies in a geometric region (always false for a
    /// selection by index or attribute, or of the visible samples).
    pub fn contains_point(&self, x: &Vect<D>) -> bool {
        match self {
            Self::Box { min, max } => (0..D).all(|a| x[a] >= min[a] && x[a] <= max[a]),
            Self::Sphere { center, radius } => (x - center).norm_squared() <= radius * radius,
            Self::Plane { point, normal } => (x - point).dot(normal) <= 0.0,
            Self::Polygon(p) => p.contains(x[0], x[1], (D > 2).then(|| x[D - 1])),
            Self::Screen { visible: true, .. } => false,
            Self::Screen { view, polygon, .. } => on_screen(view, polygon, x),
            Self::All(parts) => parts.iter().all(|r| r.contains_point(x)),
            Self::Not(r) => r.is_geometric() && !r.contains_point(x),
            Self::Indices(_) | Self::Classification(_) => false,
        }
    }

    /// Whether the region selects sample `index` at `x` with LAS class `class`.
    pub fn selects(&self, index: u64, x: &Vect<D>, class: Option<u8>) -> bool {
        match self {
            Self::Indices(set) => set.contains(&index),
            Self::Classification(set) => class.is_some_and(|c| set.contains(&c)),
            Self::All(parts) => parts.iter().all(|r| r.selects(index, x, class)),
            Self::Not(r) => !r.selects(index, x, class),
            // The samples on the screen; [`crate::solve::Sight`] keeps those it sees.
            Self::Screen { view, polygon, .. } => on_screen(view, polygon, x),
            _ => self.contains_point(x),
        }
    }
}

/// Whether `x` lies in front of the camera `view` and projects into `polygon` on its screen.
fn on_screen<const D: usize>(view: &[[f64; 4]; 4], polygon: &Polygon, x: &Vect<D>) -> bool {
    let row = |r: &[f64; 4]| (0..D).map(|a| r[a] * x[a]).sum::<f64>() + r[3];
    let w = row(&view[3]);
    w > 0.0 && polygon.contains(row(&view[0]) / w, row(&view[1]) / w, None)
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

/// A soft target (a control point): the point `from` should land on `to`, with weight `weight`.
#[derive(Debug, Clone, PartialEq)]
pub struct Target<const D: usize> {
    /// The point (input coordinates). For a [`Target::horizontal`] point its height is not
    /// known until it is snapped to the samples.
    pub from: Vect<D>,
    /// Where it should go.
    pub to: Vect<D>,
    /// Weight, relative to the glue between two finest cells.
    pub weight: f64,
    /// The line of the `[[target]]` entry in the spec (1-based).
    pub line: usize,
    /// The point's name: the file's ID column, else `#k` (the k-th target of the spec).
    pub id: String,
    /// Where the point was given, for messages: `gcp.csv line 9` or `edit.toml line 12`.
    pub place: String,
    /// A 2D control point (3D inputs only): it pulls horizontally and leaves the height free;
    /// its height is the nearest sample's horizontally (within [`Target::snap`] or
    /// [`HORIZONTAL_SNAP`] finest cells).
    pub horizontal: bool,
    /// Move `from` to the nearest sample within this distance before solving (`None`: keep
    /// it where it was given).
    pub snap: Option<f64>,
}

/// The pull on a horizontal control point's height, relative to its horizontal pull
/// ([`Target::mask`]); its weight in the energy is the square, 1 %.
pub const HEIGHT_HOLD: f64 = 0.1;

/// How far, in finest cells, a 2D control point without `snap` looks for its height.
pub const HORIZONTAL_SNAP: f64 = 2.0;

impl<const D: usize> Target<D> {
    /// Per axis, how hard the target pulls: 1, except the height of a horizontal control
    /// point, [`HEIGHT_HOLD`]: the point prescribes no height, but its height is held lightly
    /// at the surface's. With a height entirely free, a scan pulled only sideways buckles —
    /// its cells tilt so that horizontal distances change cheaply (autzen_trim with three 2D
    /// points: heights off by 24 m at 1e-3; within 2 cm at 0.1, with the same horizontal
    /// residuals as at 1).
    pub fn mask(&self) -> Vect<D> {
        let mut m = Vect::<D>::repeat(1.0);
        if self.horizontal {
            m[D - 1] = HEIGHT_HOLD;
        }
        m
    }

    /// `x` along the axes the target constrains: all of them, or the horizontal ones.
    pub fn pulled(&self, mut x: Vect<D>) -> Vect<D> {
        if self.horizontal {
            x[D - 1] = 0.0;
        }
        x
    }
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
/// The largest turn a handle may ask for, in degrees: ten whole turns. Load steps interpolate
/// the angle (at most 30° a step), so the solver's work grows with it.
pub const MAX_TURN_DEGREES: f64 = 3600.0;

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

/// The keys that select: one or more in an entry, combined (all must hold).
const REGION_KEYS: [&str; 7] = [
    "box",
    "sphere",
    "plane",
    "indices",
    "classification",
    "polygon",
    "polygon_file",
];
/// Keys that qualify a selection.
const SELECTION_KEYS: [&str; 4] = ["z", "invert", "view", "visible"];

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
        ctx.allow_only(t.get_ref(), &["from", "to", "weight", "file", "snap"], line)?;
        let first = spec.targets.len();
        spec.targets.extend(ctx.targets(t.get_ref(), line, first)?);
    }
    for t in &raw.stiffness {
        let line = ctx.line(t);
        ctx.allow(t.get_ref(), &["scale"], line)?;
        let scale: f64 = ctx.field(t.get_ref(), "scale", line)?;
        if !(scale.is_finite() && scale > 0.0) {
            return Err(ctx.error(
                ctx.at(line, "scale"),
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

    /// The line of `key` (its first part, for `box.min`) in the entry that starts on line
    /// `entry`: where a value's error is reported. The entry's own line when the key is not
    /// written on a line of its own (a dotted key, a key of an inline table).
    fn at(&self, entry: usize, key: &str) -> Option<usize> {
        let root = key.split('.').next().unwrap_or(key);
        for (i, text) in self.text.lines().enumerate().skip(entry) {
            let t = text.trim_start();
            // The next table header ends the entry; a multi-line array's rows start with `[`
            // and a number or another `[`.
            let header = t.trim_start_matches('[').trim_start();
            if t.starts_with('[') && header.starts_with(|c: char| c.is_alphabetic() || c == '"') {
                break;
            }
            let unquoted = t
                .strip_prefix('"')
                .and_then(|r| r.strip_prefix(root)?.strip_prefix('"'))
                .or_else(|| t.strip_prefix(root));
            if let Some(rest) = unquoted.map(str::trim_start)
                && (rest.starts_with('=') || rest.starts_with('.'))
            {
                return Some(i + 1);
            }
        }
        Some(entry)
    }

    fn line<T>(&self, s: &Spanned<T>) -> usize {
        let start = s.span().start.min(self.text.len());
        self.text[..start].matches('\n').count() + 1
    }

    fn allow(&self, t: &toml::Table, extra: &[&str], line: usize) -> Result<()> {
        let keys: Vec<&str> = REGION_KEYS
            .iter()
            .chain(&SELECTION_KEYS)
            .chain(extra)
            .copied()
            .collect();
        self.allow_only(t, &keys, line)
    }

    fn allow_only(&self, t: &toml::Table, keys: &[&str], line: usize) -> Result<()> {
        match t.keys().find(|k| !keys.contains(&k.as_str())) {
            Some(k) => Err(self.error(
                self.at(line, k),
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
            .ok_or_else(|| self.error(self.at(line, key), format!("missing `{key}`")))?;
        v.clone()
            .try_into()
            .map_err(|e| self.error(self.at(line, key), format!("`{key}`: {e}")))
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
                self.at(line, key),
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
                self.at(line, key),
                format!("`{key}` must be {D} finite numbers, got {v:?}"),
            ));
        }
        Ok(Vect::<D>::from_column_slice(v))
    }

    /// The region of an entry: its region keys combined (a sample must satisfy all), then
    /// `invert`ed.
    fn region<const D: usize>(&self, t: &toml::Table, line: usize) -> Result<Region<D>> {
        let present: Vec<&str> = REGION_KEYS
            .iter()
            .copied()
            .filter(|k| t.contains_key(*k))
            .collect();
        if present.is_empty() {
            return Err(self.error(
                Some(line),
                format!(
                    "an entry needs a region ({}; several combine)",
                    REGION_KEYS.join(", ")
                ),
            ));
        }
        if present.contains(&"polygon") && present.contains(&"polygon_file") {
            return Err(self.error(
                Some(line),
                "`polygon` and `polygon_file` exclude each other".into(),
            ));
        }
        if t.contains_key("view") && !present.contains(&"polygon") {
            return Err(self.error(
                self.at(line, "view"),
                "`view` (a screen's world-to-clip matrix) goes with a `polygon`".into(),
            ));
        }
        if t.contains_key("visible") && !t.contains_key("view") {
            return Err(self.error(
                Some(line),
                "`visible` (only what a screen's camera sees) goes with a `view`".into(),
            ));
        }
        if t.contains_key("z") && !present.iter().any(|k| k.starts_with("polygon")) {
            return Err(self.error(
                self.at(line, "z"),
                "`z` (a height range) goes with a `polygon` or `polygon_file`".into(),
            ));
        }
        let mut parts = present
            .iter()
            .map(|k| self.region_part::<D>(t, k, line))
            .collect::<Result<Vec<_>>>()?;
        let region = match parts.len() {
            1 => parts.pop().unwrap(),
            _ => Region::All(parts),
        };
        let invert = match t.get("invert") {
            Some(_) => self.field::<bool>(t, "invert", line)?,
            None => false,
        };
        if invert && region.visible_from().is_some() {
            return Err(self.error(
                Some(line),
                "`visible = true` and `invert = true` exclude each other".into(),
            ));
        }
        Ok(if invert {
            Region::Not(Box::new(region))
        } else {
            region
        })
    }

    fn region_part<const D: usize>(
        &self,
        t: &toml::Table,
        key: &str,
        line: usize,
    ) -> Result<Region<D>> {
        Ok(match key {
            "box" => {
                let b: RawBox = self.field(t, key, line)?;
                let (min, max) = (
                    self.to_vect(&b.min, "box.min", line)?,
                    self.to_vect(&b.max, "box.max", line)?,
                );
                if (0..D).any(|a| min[a] > max[a]) {
                    return Err(self.error(self.at(line, "box"), "box.min exceeds box.max".into()));
                }
                Region::Box { min, max }
            }
            "sphere" => {
                let s: RawSphere = self.field(t, key, line)?;
                if !(s.radius.is_finite() && s.radius >= 0.0) {
                    return Err(
                        self.error(self.at(line, "sphere"), "sphere.radius must be ≥ 0".into())
                    );
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
                    return Err(self.error(self.at(line, "plane"), "plane.normal is zero".into()));
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
            "polygon" | "polygon_file" => {
                let rings = if key == "polygon" {
                    let ring: Vec<Vec<f64>> = self.field(t, key, line)?;
                    vec![self.ring(&ring, "polygon", line)?]
                } else {
                    let file: String = self.field(t, key, line)?;
                    self.read_geojson(&file)?
                };
                if t.contains_key("view") {
                    return self.screen::<D>(t, rings, line);
                }
                let z = match t.get("z") {
                    Some(_) if D == 2 => {
                        return Err(self.error(self.at(line, "z"), "`z` is for 3D inputs".into()));
                    }
                    Some(_) => {
                        let z: Vec<f64> = self.field(t, "z", line)?;
                        match z[..] {
                            [a, b] if a <= b => Some([a, b]),
                            _ => {
                                return Err(self.error(
                                    self.at(line, "z"),
                                    format!("`z` must be [lowest, highest], got {z:?}"),
                                ));
                            }
                        }
                    }
                    None => None,
                };
                Region::Polygon(Polygon::new(rings, z))
            }
            _ => {
                let classes: Vec<u8> = self.field(t, key, line)?;
                Region::Classification(classes.into_iter().collect())
            }
        })
    }

    /// A `polygon` on the screen of `view`.
    fn screen<const D: usize>(
        &self,
        t: &toml::Table,
        rings: Vec<Vec<[f64; 2]>>,
        line: usize,
    ) -> Result<Region<D>> {
        if D != 3 || t.contains_key("z") {
            return Err(self.error(
                self.at(line, "view"),
                "`view` is for 3D inputs, without `z`".into(),
            ));
        }
        let rows: Vec<Vec<f64>> = self.field(t, "view", line)?;
        let mut view = [[0.0; 4]; 4];
        if rows.len() != 4 || rows.iter().any(|r| r.len() != 4) {
            return Err(self.error(
                self.at(line, "view"),
                "`view` must be 4 rows of 4 numbers".into(),
            ));
        }
        for (out, row) in view.iter_mut().zip(&rows) {
            for (o, v) in out.iter_mut().zip(row) {
                if !v.is_finite() {
                    return Err(self.error(
                        self.at(line, "view"),
                        "`view` holds a number that is not finite".into(),
                    ));
                }
                *o = *v;
            }
        }
        let visible = match t.get("visible") {
            Some(_) => self.field::<bool>(t, "visible", line)?,
            None => false,
        };
        if visible && view[2][..3].iter().all(|&v| v == 0.0) {
            return Err(self.error(
                Some(line),
                "`visible` needs the view's depth: its third row is zero".into(),
            ));
        }
        Ok(Region::Screen {
            view,
            polygon: Polygon::new(rings, None),
            visible,
        })
    }

    /// A ring of `[x, y]` vertices: at least 3, finite.
    fn ring(&self, v: &[Vec<f64>], key: &str, line: usize) -> Result<Vec<[f64; 2]>> {
        if v.len() < 3
            || v.iter()
                .any(|p| p.len() != 2 || !p.iter().all(|x| x.is_finite()))
        {
            return Err(self.error(
                self.at(line, key),
                format!("`{key}` must be at least 3 points [x, y] of finite numbers"),
            ));
        }
        Ok(v.iter().map(|p| [p[0], p[1]]).collect())
    }

    /// The rings of every polygon in a GeoJSON file (a FeatureCollection, a Feature or a bare
    /// geometry; Polygon and MultiPolygon, holes included; heights ignored). The coordinates
    /// must be those of the input.
    fn read_geojson(&self, file: &str) -> Result<Vec<Vec<[f64; 2]>>> {
        let path = self.resolve(file);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::spec_file(&path, e))?;
        let bad = |message: String| Error::Spec {
            path: path.clone(),
            message,
        };
        let json: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| bad(format!("not GeoJSON: {e}")))?;
        let mut rings = Vec::new();
        collect_rings(&json, &mut rings).map_err(bad)?;
        if rings.is_empty() {
            return Err(bad("holds no Polygon or MultiPolygon".into()));
        }
        Ok(rings)
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
                        self.at(line, "indices"),
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
            return Err(self.error(
                self.at(line, "scale"),
                format!("scale {scale} must be positive"),
            ));
        }
        self.within_range(scale, "scale", line)?;
        let (rotation, turn) = match t.get("rotate") {
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
                self.at(line, "matrix"),
                format!("`matrix` must be {n} rows of {n} numbers"),
            ));
        }
        if m.iter().flatten().any(|v| !v.is_finite())
            || (0..D).any(|c| m[D][c] != 0.0)
            || m[D][D] != 1.0
        {
            return Err(self.error(
                self.at(line, "matrix"),
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
                self.at(line, "matrix"),
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

    fn targets<const D: usize>(
        &self,
        t: &toml::Table,
        line: usize,
        first: usize,
    ) -> Result<Vec<Target<D>>> {
        let weight: f64 = match t.get("weight") {
            Some(_) => self.field(t, "weight", line)?,
            None => 1.0,
        };
        if !(weight.is_finite() && weight > 0.0) {
            return Err(self.error(
                self.at(line, "weight"),
                format!("weight {weight} must be positive"),
            ));
        }
        let snap = match t.get("snap") {
            Some(_) => {
                let d: f64 = self.field(t, "snap", line)?;
                if !(d.is_finite() && d > 0.0) {
                    return Err(self.error(
                        self.at(line, "snap"),
                        format!("snap {d} must be a positive distance"),
                    ));
                }
                Some(d)
            }
            None => None,
        };
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
                .map_err(|e| self.error(self.at(line, "file"), format!("`file`: {e}")))?;
            let path = self.resolve(&file);
            let text = std::fs::read_to_string(&path).map_err(|e| Error::spec_file(&path, e))?;
            let rows = read_control_points::<D>(&text, &path)?;
            let mut out = Vec::with_capacity(rows.len());
            for (k, row) in rows.into_iter().enumerate() {
                let place = format!("{file} line {}", row.line);
                let key = |what: &str| format!("{place}: {what}");
                self.within_range(row.from.amax(), &key("from"), line)?;
                self.within_range(row.to.amax(), &key("to"), line)?;
                out.push(Target {
                    from: row.from,
                    to: row.to,
                    weight: row.weight.unwrap_or(weight),
                    line,
                    id: row.id.unwrap_or_else(|| format!("#{}", first + k + 1)),
                    place,
                    horizontal: row.horizontal,
                    snap,
                });
            }
            return Ok(out);
        }
        Ok(vec![Target {
            from: self.motion_vector(t, "from", line)?,
            to: self.motion_vector(t, "to", line)?,
            weight,
            line,
            id: format!("#{}", first + 1),
            place: format!("{} line {line}", file_name(self.name)),
            horizontal: false,
            snap,
        }])
    }
}

/// Adds the rings of the polygons in the GeoJSON value `v` to `out`.
fn collect_rings(
    v: &serde_json::Value,
    out: &mut Vec<Vec<[f64; 2]>>,
) -> std::result::Result<(), String> {
    let ring = |r: &serde_json::Value| -> std::result::Result<Vec<[f64; 2]>, String> {
        let points = r.as_array().ok_or("a ring is not an array")?;
        let ring = points
            .iter()
            .map(|p| {
                let c = p
                    .as_array()
                    .filter(|c| c.len() >= 2)
                    .ok_or("a position is not [x, y]")?;
                match (c[0].as_f64(), c[1].as_f64()) {
                    (Some(x), Some(y)) if x.is_finite() && y.is_finite() => Ok([x, y]),
                    _ => Err("a position is not two numbers"),
                }
            })
            .collect::<std::result::Result<Vec<_>, _>>()?;
        if ring.len() < 3 {
            return Err("a ring has fewer than 3 positions".into());
        }
        Ok(ring)
    };
    match v.get("type").and_then(|t| t.as_str()) {
        Some("FeatureCollection") => {
            for f in v
                .get("features")
                .and_then(|f| f.as_array())
                .ok_or("no `features`")?
            {
                collect_rings(f, out)?;
            }
        }
        Some("Feature") => {
            if let Some(g) = v.get("geometry").filter(|g| !g.is_null()) {
                collect_rings(g, out)?;
            }
        }
        Some("GeometryCollection") => {
            for g in v
                .get("geometries")
                .and_then(|g| g.as_array())
                .ok_or("no `geometries`")?
            {
                collect_rings(g, out)?;
            }
        }
        Some("Polygon") => {
            for r in v
                .get("coordinates")
                .and_then(|c| c.as_array())
                .ok_or("no `coordinates`")?
            {
                out.push(ring(r)?);
            }
        }
        Some("MultiPolygon") => {
            for p in v
                .get("coordinates")
                .and_then(|c| c.as_array())
                .ok_or("no `coordinates`")?
            {
                for r in p.as_array().ok_or("a polygon is not an array")? {
                    out.push(ring(r)?);
                }
            }
        }
        // Points and lines select nothing.
        Some(_) => {}
        None => return Err("an object without a `type`".into()),
    }
    Ok(())
}

/// The file name of `path` for messages.
fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

/// One row of a control-point file.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlRow<const D: usize> {
    /// The ID column, if the file has one.
    pub id: Option<String>,
    /// The point (for a horizontal point, its height is 0 until snapped).
    pub from: Vect<D>,
    /// Where it goes (for a horizontal point, its height is 0).
    pub to: Vect<D>,
    /// The weight column, if the file has one.
    pub weight: Option<f64>,
    /// Whether the file gives x and y only.
    pub horizontal: bool,
    /// The line in the file (1-based).
    pub line: usize,
}

/// What a column of a control-point file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Column {
    Id,
    From(usize),
    To(usize),
    Weight,
}

/// Reads a control-point file (`[[target]] file = …`), naming `path` in errors with the line
/// and column.
///
/// - Separators: `,`, `;`, tab or spaces, the first that the first data row holds, in that
///   order. With `;`, tab or spaces, a decimal comma (`12,5`) reads as `12.5`. Fields may be
///   quoted (`"P1"`); `#` starts a comment line; blank lines are skipped.
/// - Columns by count, without a header (3D): `x,y,z,X,Y,Z` (6), `id,x,y,z,X,Y,Z` (7),
///   `id,x,y,z,X,Y,Z,weight` (8); 2D control points, whose height is free: `x,y,X,Y` (4),
///   `id,x,y,X,Y` (5). A first field that is not a number is an ID whatever the count. In a
///   2D (image) spec: `x,y,X,Y`, `id,x,y,X,Y`, `id,x,y,X,Y,weight`.
/// - A header row (a first data row that is not numbers) names the columns, in any order:
///   `id` (or `name`, `point`, `label`), `x y z` (or `from_x …`) for the point, `X Y Z` (or
///   `to_x …`, `x2 …`) for where it goes, `weight` (or `w`). Unknown names are errors.
pub fn read_control_points<const D: usize>(text: &str, path: &Path) -> Result<Vec<ControlRow<D>>> {
    let fail = |line: usize, column: Option<usize>, message: String| Error::Spec {
        path: path.to_path_buf(),
        message: match column {
            Some(c) => format!("line {line}, column {c}: {message}"),
            None => format!("line {line}: {message}"),
        },
    };
    let mut rows = text
        .lines()
        .enumerate()
        .map(|(k, l)| (k + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((first_line, first)) = rows.next() else {
        return Ok(Vec::new());
    };
    let sep = [';', ',', '\t']
        .into_iter()
        .find(|c| first.contains(*c))
        .unwrap_or(' ');
    let split = |row: &str| -> Vec<String> {
        let fields: Vec<&str> = if sep == ' ' {
            row.split_whitespace().collect()
        } else {
            row.split(sep).collect()
        };
        fields
            .iter()
            .map(|f| f.trim().trim_matches('"').trim().to_string())
            .collect()
    };
    let number = |f: &str| -> Option<f64> {
        let v = match f.parse::<f64>() {
            Ok(v) => Some(v),
            Err(_) if sep != ',' && f.contains(',') && !f.contains('.') => {
                f.replace(',', ".").parse::<f64>().ok()
            }
            Err(_) => None,
        };
        v.filter(|v| v.is_finite())
    };
    let head = split(first);
    let all_numbers = head.iter().skip(1).all(|f| number(f).is_some());
    let (layout, mut pending) = if all_numbers {
        let id = number(&head[0]).is_none();
        (
            by_count::<D>(head.len(), id).ok_or_else(|| {
                fail(
                    first_line,
                    None,
                    format!(
                        "{} columns; expected {} (see the README's control points)",
                        head.len(),
                        expected_counts::<D>()
                    ),
                )
            })?,
            Some((first_line, first)),
        )
    } else {
        (
            by_header::<D>(&head).map_err(|(c, m)| fail(first_line, Some(c), m))?,
            None,
        )
    };
    let horizontal = D == 3 && !layout.contains(&Column::From(2));
    let mut out = Vec::new();
    let mut next = || pending.take().or_else(|| rows.next());
    while let Some((line, row)) = next() {
        let fields = split(row);
        if fields.len() != layout.len() {
            return Err(fail(
                line,
                None,
                format!(
                    "{} columns, the file's rows have {}",
                    fields.len(),
                    layout.len()
                ),
            ));
        }
        let mut r = ControlRow {
            id: None,
            from: Vect::<D>::zeros(),
            to: Vect::<D>::zeros(),
            weight: None,
            horizontal,
            line,
        };
        for (c, (field, col)) in fields.iter().zip(&layout).enumerate() {
            if *col == Column::Id {
                r.id = Some(field.clone());
                continue;
            }
            let v = number(field).ok_or_else(|| {
                fail(
                    line,
                    Some(c + 1),
                    format!("`{field}` is not a finite number"),
                )
            })?;
            match *col {
                Column::From(a) => r.from[a] = v,
                Column::To(a) => r.to[a] = v,
                Column::Weight if v > 0.0 => r.weight = Some(v),
                Column::Weight => {
                    return Err(fail(
                        line,
                        Some(c + 1),
                        format!("weight {v} must be positive"),
                    ));
                }
                Column::Id => {}
            }
        }
        out.push(r);
    }
    Ok(out)
}

fn expected_counts<const D: usize>() -> &'static str {
    if D == 3 {
        "6 (x,y,z,X,Y,Z), 7 (id,x,y,z,X,Y,Z), 8 (id,…,weight), 4 (x,y,X,Y) or 5 (id,x,y,X,Y)"
    } else {
        "4 (x,y,X,Y), 5 (id,x,y,X,Y) or 6 (id,x,y,X,Y,weight)"
    }
}

/// The columns of a file without a header, from their count and whether the first field is
/// an ID that is not a number.
fn by_count<const D: usize>(count: usize, text_id: bool) -> Option<Vec<Column>> {
    let points = |dims: usize, id: bool, weight: bool| {
        let mut c = Vec::new();
        if id {
            c.push(Column::Id);
        }
        c.extend((0..dims).map(Column::From));
        c.extend((0..dims).map(Column::To));
        if weight {
            c.push(Column::Weight);
        }
        c
    };
    let layout = match (D, count) {
        (3, 6) if !text_id => points(3, false, false),
        (3, 7) => points(3, true, false),
        (3, 8) => points(3, true, true),
        (3, 4) if !text_id => points(2, false, false),
        (3, 5) => points(2, true, false),
        (2, 4) if !text_id => points(2, false, false),
        (2, 5) => points(2, true, false),
        (2, 6) => points(2, true, true),
        _ => return None,
    };
    Some(layout)
}

/// The columns of a file from its header row; an error gives the column (1-based).
fn by_header<const D: usize>(
    names: &[String],
) -> std::result::Result<Vec<Column>, (usize, String)> {
    const AXES: [&str; 3] = ["x", "y", "z"];
    let mut layout = Vec::new();
    for (c, name) in names.iter().enumerate() {
        let lower = name.to_ascii_lowercase();
        let axis = |n: &str| AXES[..D].iter().position(|a| *a == n);
        let col = match name.as_str() {
            "X" | "Y" | "Z" => axis(&lower).map(Column::To),
            "x" | "y" | "z" => axis(name).map(Column::From),
            _ => match lower.as_str() {
                "id" | "name" | "point" | "label" | "gcp" => Some(Column::Id),
                "weight" | "w" => Some(Column::Weight),
                _ => {
                    let (prefix, a) = lower.split_at(lower.len().saturating_sub(1));
                    match prefix {
                        "from_" | "from" | "src_" => axis(a).map(Column::From),
                        "to_" | "to" | "dst_" => axis(a).map(Column::To),
                        _ => match lower.strip_suffix('2') {
                            Some(a) => axis(a).map(Column::To),
                            None => None,
                        },
                    }
                }
            },
        };
        let col = col.ok_or_else(|| {
            (
                c + 1,
                format!(
                    "unknown column `{name}` (expected id, x, y{z}, X, Y{Z}, weight)",
                    z = if D == 3 { ", z" } else { "" },
                    Z = if D == 3 { ", Z" } else { "" },
                ),
            )
        })?;
        if layout.contains(&col) {
            return Err((c + 1, format!("column `{name}` appears twice")));
        }
        layout.push(col);
    }
    let has = |c: Column| layout.contains(&c);
    let dims = if D == 3 && !has(Column::From(2)) && !has(Column::To(2)) {
        2
    } else {
        D
    };
    if let Some(a) = (0..dims).find(|&a| !has(Column::From(a)) || !has(Column::To(a))) {
        return Err((
            1,
            format!(
                "the header names no column for {} or {}",
                AXES[a],
                AXES[a].to_ascii_uppercase()
            ),
        ));
    }
    Ok(layout)
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

    /// An error in a value names the value's line, not its entry's; an error of the entry as
    /// a whole names the entry's line.
    #[test]
    fn errors_name_the_line_of_the_bad_value() {
        let line_of = |text: &str| {
            let e = parse(text).unwrap_err().to_string();
            let n = e
                .split("line ")
                .nth(1)
                .expect("a line")
                .split(':')
                .next()
                .unwrap();
            (n.parse::<usize>().unwrap(), e)
        };
        let fixed = "[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n";
        let (n, e) = line_of(&format!(
            "{fixed}[[handle]]\nsphere = {{ center = [5.0, 0.0, 0.0], radius = 1.0 }}\n\
             translate = [0, 0, \"a\"]\n"
        ));
        assert_eq!(n, 5, "{e}");
        let (n, e) = line_of(&format!(
            "{fixed}[[handle]]\n# a turn\nsphere = {{ center = [5.0, 0.0, 0.0], radius = 1.0 }}\n\
             rotate = {{ axis = [1, 0, 0], degrees = 5000 }}\n"
        ));
        assert_eq!(n, 6, "{e}");
        let (n, e) =
            line_of("[[fixed]]\n\nbox = { min = [2.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n");
        assert_eq!(n, 3, "{e}");
        let (n, e) = line_of(&format!(
            "{fixed}[[handle]]\npolygon = [\n  [0.0, 0.0],\n  [1.0, 0.0],\n  [0.0, 1.0],\n]\n\
             z = [2.0, 1.0]\ntranslate = [0, 0, 1]\n"
        ));
        assert_eq!(n, 9, "{e}");
        // The next entry's keys are not this one's: a missing `to` names the pin's line.
        let (n, e) = line_of(&format!(
            "{fixed}[[pin]]\npoint = [0, 0, 0]\n[[pin]]\nto = [1, 1, 1]\n"
        ));
        assert_eq!(n, 3, "{e}");
    }

    #[test]
    fn errors_name_the_line() {
        let e = parse("[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n\n[[handle]]\nsphere = { center = [0.0, 0.0], radius = 1.0 }\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 5") && e.contains("3 finite numbers"),
            "{e}"
        );
        let e = parse(
            "[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nradius = 3\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("line 3") && e.contains("unknown key `radius`"),
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
    fn regions_combine_invert_and_polygons_have_holes() {
        let spec = parse(
            "[[fixed]]\nclassification = [2, 6]\npolygon = [[0, 0], [10, 0], [10, 10], [0, 10]]\n\
             z = [0, 5]\n[[stiffness]]\nsphere = { center = [0, 0, 0], radius = 1 }\n\
             invert = true\nscale = 2\n",
        )
        .unwrap();
        let r = &spec.fixed[0].region;
        let p = Vect::<3>::new(5.0, 5.0, 1.0);
        assert!(r.selects(0, &p, Some(2)) && !r.selects(0, &p, Some(3)));
        assert!(!r.selects(0, &Vect::<3>::new(5.0, 5.0, 6.0), Some(2)));
        assert!(!r.selects(0, &Vect::<3>::new(11.0, 5.0, 1.0), Some(6)));
        assert!(!r.is_geometric() && r.uses_classes());
        let s = &spec.stiffness[0].region;
        assert!(s.is_geometric() && !s.contains_point(&Vect::<3>::zeros()));
        assert!(s.contains_point(&Vect::<3>::new(2.0, 0.0, 0.0)));
        // Even–odd: a ring inside another is a hole.
        let square = |a: f64, b: f64| vec![[a, a], [b, a], [b, b], [a, b]];
        let holed = Polygon::new(vec![square(0.0, 10.0), square(4.0, 6.0)], None);
        assert!(holed.contains(1.0, 1.0, None) && !holed.contains(5.0, 5.0, None));
        assert!(!holed.contains(11.0, 5.0, None));
    }

    #[test]
    fn control_point_files_by_count_and_by_header() {
        let read = |text: &str| read_control_points::<3>(text, Path::new("gcp.csv"));
        // By count: 6, 7 (an ID), 8 (an ID and a weight), 4 and 5 (2D).
        let r = read("1 2 3 4 5 6\n").unwrap();
        assert_eq!(
            (r[0].id.clone(), r[0].to[2], r[0].horizontal),
            (None, 6.0, false)
        );
        let r = read("7;1;2;3;4;5;6\n").unwrap();
        assert_eq!((r[0].id.as_deref(), r[0].from[0]), (Some("7"), 1.0));
        let r = read("A,1,2,3,4,5,6,2.5\n").unwrap();
        assert_eq!(r[0].weight, Some(2.5));
        let r = read("1\t2\t3\t4\n").unwrap();
        assert!(r[0].horizontal && r[0].to[1] == 4.0);
        let r = read("P9 1 2 3 4\n").unwrap();
        assert!(r[0].horizontal && r[0].id.as_deref() == Some("P9"));
        // A text ID needs its column: 6 fields with a name first is not 3D without one.
        assert!(read("P1,1,2,3,4,5\n").is_err());
        // By header, in any order; decimal commas with `;`.
        let r = read("# c\n\nZ;Y;X;z;y;x;name\n6;5;4;3;2;1,5;Q\n").unwrap();
        assert_eq!(r[0].from, Vect::<3>::new(1.5, 2.0, 3.0));
        assert_eq!(r[0].to, Vect::<3>::new(4.0, 5.0, 6.0));
        assert_eq!((r[0].id.as_deref(), r[0].line), (Some("Q"), 4));
        let r = read("point,from_x,from_y,to_x,to_y,w\nA,1,2,3,4,0.5\n").unwrap();
        assert!(r[0].horizontal && r[0].weight == Some(0.5));
        let e = read("id,x,y,X\n").unwrap_err().to_string();
        assert!(e.contains("no column for y or Y"), "{e}");
        let e = read("id,x,x,y,X,Y\n").unwrap_err().to_string();
        assert!(e.contains("column 3") && e.contains("twice"), "{e}");
        let e = read("1,2,3,4,5,6\n1,2,3,4,5,-6,7\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("7 columns"), "{e}");
        assert!(read("# nothing\n").unwrap().is_empty());
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
