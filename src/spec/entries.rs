//! The entries of an edit spec once parsed and validated: fixed regions, handles with their
//! motion, pins, soft targets (control points) and stiffness regions, gathered in
//! [`EditSpec`].

use std::path::PathBuf;

use super::region::Region;
use crate::error::{Error, Result};
use crate::rigid::{Dim, Mat, Rigid, Vect};

/// How a handle moves: `A(x) = R·P·(x − pivot) + pivot + translate`, with `R` a rotation and `P`
/// a stretch (`S·I` for a uniform scale). A general affine matrix is stored in this form by polar
/// decomposition, so that load steps can interpolate it. Made by [`HandleMotion::turning`] or
/// [`HandleMotion::affine`] (outside the crate, only by them), which keep the rotation and the
/// turn one map.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct HandleMotion<const D: usize> {
    /// The center of rotation and scaling (input coordinates); `None`: the centroid of the
    /// handle's selected samples.
    pub pivot: Option<Vect<D>>,
    /// The rotation `R`.
    pub rotation: Mat<D>,
    /// The rotation as written: its axis (unused in 2D) and signed angle in radians, of any
    /// size (720° is two whole turns). Load steps interpolate this angle, so a whole turn is
    /// not the identity. For a `matrix` it is the angle of `R` in `[0, π]` (2D: `(−π, π]`): a
    /// matrix cannot say how many turns it makes, nor, at a half turn, which way round
    /// ([`HandleMotion::undirected`]).
    pub turn: (Vect<D>, f64),
    /// The stretch `P`.
    pub stretch: Mat<D>,
    /// The translation.
    pub translate: Vect<D>,
    /// Whether the motion came from a `matrix`: then it is `A(x) = R·P·x + translate` exactly,
    /// whatever the pivot, and the pivot only centers the load-step interpolation.
    pub from_matrix: bool,
}

/// A matrix whose rotation is within this many radians (0.06°) of a half turn does not say
/// which way round it turns ([`HandleMotion::undirected`]): its antisymmetric part, which would
/// tell, is `2 sin θ` there, of the order of its rounding (a half turn about z made in single
/// precision, as Blender's matrices are, has `sin θ` of 9e-8, of either sign).
pub(crate) const HALF_TURN_SLACK: f64 = 1e-3;

impl<const D: usize> HandleMotion<D> {
    /// Whether the motion is a `matrix` turning by a half turn, which reaches the same pose
    /// turned either way round: the solver turns it one way and, where the shape gives way,
    /// the other ([`HandleMotion::the_other_way`]).
    pub fn undirected(&self) -> bool {
        self.from_matrix && (std::f64::consts::PI - self.turn.1.abs()).abs() < HALF_TURN_SLACK
    }

    /// The same map, its turn taken the other way round about the same axis (an angle a
    /// whole turn less, or more for a negative one): 180° becomes −180°.
    pub fn the_other_way(&self) -> Self {
        let (axis, angle) = self.turn;
        Self {
            turn: (axis, angle - std::f64::consts::TAU.copysign(angle)),
            ..*self
        }
    }

    /// The turn in degrees as the user would write it: as typed in a spec, and a matrix's to a
    /// tenth of a degree (its rounding makes a half turn 179.99999°).
    pub fn asked_degrees(&self) -> f64 {
        let degrees = self.turn.1.to_degrees();
        let step = if self.from_matrix { 10.0 } else { 1e9 };
        (degrees * step).round() / step
    }

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
    /// The line of the entry in the spec (1-based; 0 for an entry made in code).
    pub line: usize,
}

/// A pin: the point `point` goes to `to`; its cell may rotate about it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pin<const D: usize> {
    /// The point (input coordinates).
    pub point: Vect<D>,
    /// Where it goes.
    pub to: Vect<D>,
    /// The line of the entry (1-based; 0 for a pin made in code).
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
    /// The line of the `[[target]]` entry in the spec (1-based; 0 for a target made in code).
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
    /// A checkpoint (a control-point file's `check` column): left out of the solve and the
    /// trend, and scored apart ([`crate::control`]).
    pub check: bool,
    /// An exact control point (`exact = true`): its cell is pinned, turning about the point,
    /// which goes where it is wanted to the output's precision, not merely as close as the
    /// solve pulls it. Still a control point: in the trend, the residuals and leave-one-out.
    pub exact: bool,
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

/// The global trend fitted to the control points before the cells carry the rest
/// (`trend = "…"` at the top of the spec; [`crate::solve::trend`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Trend {
    /// No trend: the cells carry all of the control points' motion.
    #[default]
    None,
    /// One shift, the weighted mean of the points' motions.
    Shift,
    /// A shift, a rotation and a uniform scale (a Helmert transformation; for 2D points, in
    /// the horizontal plane).
    Similarity,
    /// A general affine map (for 2D points, of x and y; heights as they are).
    Affine,
    /// A thin-plate spline over the horizontal plane with its affine part, through every
    /// point (each coordinate's displacement interpolated exactly).
    Spline,
}

impl Trend {
    /// The names the spec takes.
    pub const NAMES: [&'static str; 5] = ["none", "shift", "similarity", "affine", "spline"];

    /// The trend named `name` in a spec.
    pub fn named(name: &str) -> Option<Self> {
        match name {
            "none" => Some(Self::None),
            "shift" => Some(Self::Shift),
            "similarity" => Some(Self::Similarity),
            "affine" => Some(Self::Affine),
            "spline" => Some(Self::Spline),
            _ => None,
        }
    }
}

impl std::fmt::Display for Trend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(Self::NAMES[*self as usize])
    }
}

/// An edit spec: parsed from TOML ([`crate::spec::parse_spec`], which checks it line by line), or
/// made in code and checked by [`EditSpec::validate`] where a run starts.
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
    /// The trend fitted to the targets before the cells carry the rest: as the spec says, else
    /// [`Trend::Spline`] for control points read from a file and [`Trend::None`] for targets
    /// written in the spec.
    pub trend: Trend,
    /// The spec's name in messages (its file; empty for a spec made in code).
    pub name: PathBuf,
}

impl<const D: usize> EditSpec<D> {
    /// Whether the spec constrains anything (stiffness regions alone do not).
    pub fn has_constraints(&self) -> bool {
        !(self.fixed.is_empty()
            && self.handles.is_empty()
            && self.pins.is_empty()
            && self.targets.is_empty())
    }

    /// Refuses a region that lists a sample index past the input's `samples`, naming the
    /// spec's line: such an index selects nothing, and is a mistake (an index file of another
    /// input, a count from 1).
    pub fn check_indices(&self, samples: u64) -> Result<()> {
        let largest = self
            .fixed
            .iter()
            .map(|e| &e.region)
            .chain(self.handles.iter().map(|e| &e.region))
            .chain(self.stiffness.iter().map(|e| &e.region))
            .filter_map(Region::largest_index)
            .find(|&(index, _)| index >= samples);
        let Some((index, line)) = largest else {
            return Ok(());
        };
        let range = match samples {
            0 => String::new(),
            n => format!(", numbered 0 to {}", n - 1),
        };
        Err(Error::spec(
            self.name.clone(),
            Some(line),
            format!(
                "`indices` lists sample {index}, but the input has {samples} \
                 samples{range}"
            ),
        ))
    }
}
