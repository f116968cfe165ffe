//! The regions of an edit spec and the samples they select: boxes, spheres, half-spaces,
//! polygons (prisms over x, y, or lassos on a screen), indices and LAS classes, combined and
//! inverted. A region of space answers for any point; a selection by index, class or
//! visibility answers only for samples.

use std::collections::HashSet;
use std::path::PathBuf;

use crate::crs::Crs;

use crate::rigid::Vect;

/// A region of the edit spec: it selects samples.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
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
    /// Samples by index (0-based).
    Indices {
        /// The indices.
        samples: HashSet<u64>,
        /// The line of the spec that lists them (1-based), for messages.
        line: usize,
    },
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
    /// The GeoJSON file the rings came from (`polygon_file`), for messages.
    pub file: Option<PathBuf>,
    /// The coordinate system that GeoJSON's `crs` member names, checked against the scan's
    /// where the spec meets it ([`super::EditSpec::check_geojson_crs`]).
    pub crs: Option<Crs>,
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
        Self {
            rings,
            z,
            file: None,
            crs: None,
            lo,
            hi,
        }
    }

    /// The same polygon, read from the GeoJSON `file` whose `crs` member names `crs`.
    pub fn from_file(self, file: PathBuf, crs: Option<Crs>) -> Self {
        Self {
            file: Some(file),
            crs,
            ..self
        }
    }

    /// The rings' bounding box in x, y: the lowest and the highest corner.
    pub fn extent(&self) -> ([f64; 2], [f64; 2]) {
        (self.lo, self.hi)
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
            Self::Indices { .. } | Self::Classification(_) => false,
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

    /// The largest index this region lists (alone or among the parts of an entry), with the
    /// line that lists it; `None` when it selects no sample by index.
    pub fn largest_index(&self) -> Option<(u64, usize)> {
        match self {
            Self::Indices { samples, line } => samples.iter().max().map(|&i| (i, *line)),
            Self::All(parts) => parts.iter().filter_map(Self::largest_index).max(),
            Self::Not(r) => r.largest_index(),
            _ => None,
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
            Self::Indices { .. } | Self::Classification(_) => false,
        }
    }

    /// Whether the region selects sample `index` at `x` with LAS class `class`.
    pub fn selects(&self, index: u64, x: &Vect<D>, class: Option<u8>) -> bool {
        match self {
            Self::Indices { samples, .. } => samples.contains(&index),
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
