//! The cell complex: an adaptive octree (quadtree in 2D) of rigid cells embedding the shape
//! (paper §5; docs/ARCHITECTURE.md, its code map).
//!
//! - A cell is a [`CellKey`] `(level, integer coordinates)` on a [`Grid`]: level 0 is a coarse
//!   regular grid of cells of size `cell_size · 2^max_level`; level `max_level` cells have the
//!   finest size `cell_size` chosen by the user. Refinement during the solve may go deeper.
//! - Cells holding samples of the shape (points, or triangles overlapping the box) are refined to
//!   `max_level` ([`build()`]); the empty space is tiled by maximal empty cells of the tree, each
//!   classified inside/outside (winding numbers, or an exterior flood fill over them); interior
//!   cells stay as coarse as the tree allows, exterior cells are dropped. Nothing is sized by
//!   the bounding box's volume ([`Occupancy`]).
//! - Two leaves are neighbors when their boxes share a (partial) face; the shared area is
//!   `min(2h_i, 2h_j)^(D−1)` because octree faces nest (T-junctions need no special handling).
//!
//! All geometry is in the **local frame** of the [`Grid`]: world coordinates minus
//! [`Grid::origin`] (the center of the input's bounding box), so georeferenced coordinates keep
//! their precision.

mod adjacency;
mod blocks;
mod build;
mod decimate;
mod export;
mod morton;
mod raster;
pub(crate) use morton::morton as morton_code;
mod size;
#[cfg(test)]
pub(crate) use export::BOX_QUADS;
mod tri_box;
mod winding;

pub(crate) use build::max_level_refused;
pub use build::{Forecast, MAX_LEVEL, Occupancy};
pub(crate) use decimate::Decimation;
pub use export::{Pose, write_cells_ply};
pub use size::{DEFAULT_DIVISIONS, cell_size_for};
pub(crate) use size::{Sized, check_size, shortfall, sized};
pub use tri_box::triangle_box_overlap;
pub use winding::Winding;

use rustc_hash::FxHashMap;

use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::rigid::Vect;

/// How empty cells are classified.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Inside {
    /// [`Inside::Winding`] for meshes, soups and point clouds with normals, [`Inside::Flood`]
    /// for point clouds without.
    #[default]
    Auto,
    /// Generalized winding number, `|w| ≥ ½` (see `cells::winding`): of the triangles, or of
    /// the oriented samples (one dipole per occupied finest cell); robust to holes, soups,
    /// non-manifold edges and self-intersections. Without triangles or normals it falls back
    /// to the flood fill.
    Winding,
    /// Exterior flood fill on the finest grid: an empty cell is inside when no path of empty
    /// face-adjacent cells leads from it to the grid's border.
    Flood,
    /// Keep occupied cells only (a shell; paper Fig. 10 right).
    None,
}

/// Parameters of [`build()`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BuildParams {
    /// Edge length of the finest cells, in input units. Default (`None`): the longest extent of
    /// the input's bounding box / 32.
    pub cell_size: Option<f64>,
    /// Levels of the tree above the finest cells. Default (`None`): enough for a level-0 cell
    /// to span the shortest extent (no interior cell can be larger), at least one.
    pub max_level: Option<u8>,
    /// Inside classification of empty cells. Default: winding numbers for meshes, flood fill
    /// for point clouds.
    pub inside: Inside,
    /// About this many cells: the finest cell size is searched for ([`cell_size_for`]),
    /// overriding `cell_size`.
    pub target_cells: Option<usize>,
}

impl Default for BuildParams {
    fn default() -> Self {
        Self {
            cell_size: None,
            max_level: None,
            inside: Inside::Auto,
            target_cells: None,
        }
    }
}

/// What [`build()`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BuildInfo {
    /// Finest cells along each axis.
    pub finest_dims: Vec<i64>,
    /// Occupied finest cells.
    pub occupied: usize,
    /// Boundary leaves.
    pub boundary_cells: usize,
    /// Interior leaves (at any level).
    pub interior_cells: usize,
    /// The classification used ([`Inside::Auto`] resolved).
    pub inside: Inside,
    /// Winding-number evaluations (one per empty block: see [`Occupancy::finish`]).
    pub winding_queries: usize,
    /// Finest cells holding vertices of two or more parts of a mesh that are not connected
    /// (sharing no vertex position): such parts are glued there, up to the finest cell size.
    pub glued_cells: usize,
    /// Seconds spent.
    pub seconds: f64,
}

/// Builds the cell complex of a shape given by `points` (world coordinates) and, in 3D,
/// `triangles` (indices into `points`; pass `&[]` for a point cloud), within the memory
/// `budget`.
pub fn build<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    params: &BuildParams,
    budget: Budget,
) -> Result<(CellComplex<D>, BuildInfo)> {
    build_checked(points, triangles, params, budget, &|_| Ok(()))
}

/// [`build()`], handing `check` the [`Forecast`] of the cells before the empty space is
/// classified or any leaf is made ([`Occupancy::finish_checked`]): what a run that will solve
/// the cells calls, so that one which cannot is refused before the build's time and memory are
/// spent. (A `--cells N` search's trial builds are not checked: only the size it settles on.)
pub fn build_checked<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    params: &BuildParams,
    budget: Budget,
    check: &dyn Fn(&Forecast) -> Result<()>,
) -> Result<(CellComplex<D>, BuildInfo)> {
    let (lo, hi) = bounds(points)?;
    // A point cloud is sized on the decimated samples a file of the same points is sized on
    // (`Decimation`); a mesh on all its vertices, which its triangles need.
    let mut every_point = true;
    let sized = sized(params, budget, || {
        if !triangles.is_empty() {
            return Ok((points.into(), triangles));
        }
        let mut proxy = Decimation::new(&lo, &hi);
        proxy.add(points, false);
        every_point = proxy.kept.len() == points.len();
        Ok((proxy.kept.into(), triangles))
    })?;
    // The search's last complex is this one when the search saw every point.
    if let Some(built) = sized.built.filter(|_| every_point) {
        return Ok(built);
    }
    let params = sized.params;
    let mut occupancy = Occupancy::new(&lo, &hi, &params, budget)?;
    occupancy.add_points(points)?;
    occupancy.add_triangles(points, triangles)?;
    occupancy.finish_checked(check)
}

/// The bounding box of `points`; an error for no points or a coordinate that is not finite.
pub fn bounds<const D: usize>(points: &[Vect<D>]) -> Result<(Vect<D>, Vect<D>)> {
    if points.is_empty() {
        return Err(Error::input("the input has no points"));
    }
    if let Some(i) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(Error::input(format!(
            "point {i} has a coordinate that is not a finite number"
        )));
    }
    let mut lo = points[0];
    let mut hi = points[0];
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    Ok((lo, hi))
}

/// The key of a cell: its level and its integer coordinates at that level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct CellKey<const D: usize> {
    /// Level: 0 is the coarse grid, each level halves the cell size.
    pub level: u8,
    /// Integer coordinates of the cell among the cells of its level (non-negative).
    pub coord: [i64; D],
}

impl<const D: usize> CellKey<D> {
    /// The key of the parent cell (`None` at level 0).
    pub fn parent(&self) -> Option<Self> {
        (self.level > 0).then(|| Self {
            level: self.level - 1,
            coord: self.coord.map(|c| c >> 1),
        })
    }

    /// The `2^D` children of the cell, in bit order of the axes.
    pub fn children(&self) -> impl Iterator<Item = Self> + '_ {
        (0..1usize << D).map(move |bits| Self {
            level: self.level + 1,
            coord: std::array::from_fn(|a| 2 * self.coord[a] + ((bits >> a) & 1) as i64),
        })
    }
}

/// The regular frame all cells live on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid<const D: usize> {
    /// World position of the local frame's origin (the input's bounding-box center).
    pub origin: Vect<D>,
    /// Local position of the grid's lower corner.
    pub lower: Vect<D>,
    /// Size of a level-0 cell.
    pub size0: f64,
    /// Number of level-0 cells along each axis.
    pub dims0: [i64; D],
    /// The finest level of the static discretization (cells of the user's cell size).
    pub max_level: u8,
}

impl<const D: usize> Grid<D> {
    /// Edge length of a cell of `level`.
    #[inline]
    pub fn cell_size(&self, level: u8) -> f64 {
        self.size0 / (1u64 << level) as f64
    }

    /// Edge length of the finest static cells.
    pub fn finest_size(&self) -> f64 {
        self.cell_size(self.max_level)
    }

    /// Local center of the cell `key`.
    pub fn center(&self, key: &CellKey<D>) -> Vect<D> {
        let s = self.cell_size(key.level);
        Vect::<D>::from_fn(|a, _| self.lower[a] + (key.coord[a] as f64 + 0.5) * s)
    }

    /// Number of cells along each axis at `level`.
    pub fn dims(&self, level: u8) -> [i64; D] {
        self.dims0.map(|n| n << level)
    }

    /// The key of the cell of `level` containing the local point `x`, if inside the grid.
    pub fn locate(&self, x: &Vect<D>, level: u8) -> Option<CellKey<D>> {
        let s = self.cell_size(level);
        let dims = self.dims(level);
        let mut coord = [0i64; D];
        for a in 0..D {
            // Truncation is the floor for t >= 0, and t < dims iff its floor is (dims is an
            // integer); `f64::floor` is a libm call on baseline x86-64 (a tenth of pass 1).
            let t = (x[a] - self.lower[a]) / s;
            if !(t >= 0.0 && t < dims[a] as f64) {
                return None;
            }
            coord[a] = t as i64;
        }
        Some(CellKey { level, coord })
    }
}

/// What a cell holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellKind {
    /// The cell holds samples of the shape (it intersects the surface).
    Boundary,
    /// The cell is empty and inside the shape.
    Interior,
}

/// One leaf of the complex.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell<const D: usize> {
    /// Its key on the grid.
    pub key: CellKey<D>,
    /// Rest center (local frame).
    pub center: Vect<D>,
    /// Half the edge length, `h`.
    pub half: f64,
    /// Boundary or interior.
    pub kind: CellKind,
}

impl<const D: usize> Cell<D> {
    /// Volume `(2h)^D`.
    pub fn volume(&self) -> f64 {
        (2.0 * self.half).powi(D as i32)
    }
}

/// A pair of face neighbors `i < j` with the weight `w_ij = A_ij / (h_i + h_j)` of paper eq. (2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FacePair {
    /// First cell (the smaller index).
    pub i: u32,
    /// Second cell.
    pub j: u32,
    /// `A_ij / (h_i + h_j)` with `A_ij = min(2h_i, 2h_j)^(D−1)`.
    pub weight: f64,
}

/// The leaves of the adaptive tree and their face adjacency.
#[derive(Debug, Clone)]
pub struct CellComplex<const D: usize> {
    /// The frame.
    pub grid: Grid<D>,
    /// The leaves.
    pub cells: Vec<Cell<D>>,
    /// Face-neighbor pairs, each once.
    pub pairs: Vec<FacePair>,
    index: FxHashMap<CellKey<D>, u32>,
    deepest: u8,
}

impl<const D: usize> CellComplex<D> {
    /// A complex of the given leaves; computes the key index and the face adjacency.
    pub fn from_keys(grid: Grid<D>, leaves: Vec<(CellKey<D>, CellKind)>) -> Self {
        let cells: Vec<Cell<D>> = leaves
            .into_iter()
            .map(|(key, kind)| Cell {
                key,
                center: grid.center(&key),
                half: 0.5 * grid.cell_size(key.level),
                kind,
            })
            .collect();
        let index = cells
            .iter()
            .enumerate()
            .map(|(i, c)| (c.key, i as u32))
            .collect();
        let deepest = cells.iter().map(|c| c.key.level).max().unwrap_or(0);
        let mut complex = Self {
            grid,
            cells,
            pairs: Vec::new(),
            index,
            deepest,
        };
        complex.pairs = adjacency::face_pairs(&complex);
        complex
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether the complex has no cells.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The index of the leaf with this key.
    pub fn find(&self, key: &CellKey<D>) -> Option<usize> {
        self.index.get(key).map(|&i| i as usize)
    }

    /// The deepest level of any leaf.
    pub fn deepest_level(&self) -> u8 {
        self.deepest
    }

    /// The leaf holding the finest grid cell `coord` (the cell itself or an ancestor): where a
    /// sample of that grid cell takes its constraints.
    pub fn finest_cell(&self, coord: &[i64; D]) -> Option<usize> {
        let key = CellKey {
            level: self.grid.max_level,
            coord: *coord,
        };
        self.locate(&self.grid.center(&key))
    }

    /// The index of the leaf containing the local point `x`, if any. A point on a face between
    /// cells belongs to the cell on its upper side.
    pub fn locate(&self, x: &Vect<D>) -> Option<usize> {
        let key = self.grid.locate(x, self.deepest)?;
        std::iter::successors(Some(key), |k| k.parent()).find_map(|k| self.find(&k))
    }

    /// Connected components of the face adjacency: a component id per cell, and the count.
    pub fn components(&self) -> (Vec<u32>, usize) {
        let mut parent: Vec<u32> = (0..self.cells.len() as u32).collect();
        fn root(parent: &mut [u32], mut i: u32) -> u32 {
            while parent[i as usize] != i {
                parent[i as usize] = parent[parent[i as usize] as usize];
                i = parent[i as usize];
            }
            i
        }
        for p in &self.pairs {
            let (a, b) = (root(&mut parent, p.i), root(&mut parent, p.j));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
        // Components numbered in the order of their first cells; `label` by root.
        let mut ids = vec![u32::MAX; self.cells.len()];
        let mut label = vec![u32::MAX; self.cells.len()];
        let mut count = 0usize;
        for i in 0..self.cells.len() {
            let r = root(&mut parent, i as u32) as usize;
            if label[r] == u32::MAX {
                label[r] = count as u32;
                count += 1;
            }
            ids[i] = label[r];
        }
        (ids, count)
    }

    /// Replaces each cell in `split` by its `2^D` children (same kind). Returns the new complex
    /// and, for every new cell, the index of the old cell it came from.
    pub fn split(&self, split: &[bool]) -> (Self, Vec<u32>) {
        let mut leaves = Vec::with_capacity(self.cells.len());
        let mut origin = Vec::with_capacity(self.cells.len());
        for (i, cell) in self.cells.iter().enumerate() {
            if split[i] {
                for child in cell.key.children() {
                    leaves.push((child, cell.kind));
                    origin.push(i as u32);
                }
            } else {
                leaves.push((cell.key, cell.kind));
                origin.push(i as u32);
            }
        }
        (Self::from_keys(self.grid, leaves), origin)
    }

    /// Checks the invariants of the complex: leaves do not nest, every pair is a pair of
    /// distinct cells whose boxes share a face of the stated area, and no pair is listed twice.
    pub fn validate(&self) -> Result<(), String> {
        for (i, c) in self.cells.iter().enumerate() {
            if let Some(a) = std::iter::successors(c.key.parent(), |k| k.parent())
                .find(|k| self.index.contains_key(k))
            {
                return Err(format!("cell {i} ({:?}) lies inside leaf {a:?}", c.key));
            }
        }
        let mut seen = std::collections::HashSet::new();
        for p in &self.pairs {
            if p.i >= p.j || !seen.insert((p.i, p.j)) {
                return Err(format!("pair ({}, {}) is not ordered or repeats", p.i, p.j));
            }
            let (a, b) = (&self.cells[p.i as usize], &self.cells[p.j as usize]);
            let d = b.center - a.center;
            let reach = a.half + b.half;
            let tol = 1e-9 * reach;
            let touching = (0..D)
                .filter(|&k| (d[k].abs() - reach).abs() <= tol)
                .count();
            let overlapping = (0..D)
                .filter(|&k| d[k].abs() < (a.half.max(b.half) - a.half.min(b.half)) + tol)
                .count();
            if touching != 1 || overlapping != D - 1 {
                return Err(format!("cells {} and {} do not share a face", p.i, p.j));
            }
            let area = (2.0 * a.half.min(b.half)).powi(D as i32 - 1);
            if (p.weight - area / reach).abs() > 1e-12 * p.weight {
                return Err(format!("pair ({}, {}) has a wrong weight", p.i, p.j));
            }
        }
        Ok(())
    }
}

/// `t` rounded down, as an integer (saturating): `f64::floor` is a libm call on baseline x86-64,
/// and this runs per sample (the cells' and the field's lookups).
#[inline]
pub(crate) fn floor(t: f64) -> i64 {
    let i = t as i64;
    if (i as f64) > t { i - 1 } else { i }
}

#[cfg(test)]
mod tests {
    #[test]
    fn floor_rounds_down() {
        for t in [-2.5, -2.0, -0.0, 0.0, 0.3, 1.0, 7.9, -1e-300, 3e18] {
            assert_eq!(super::floor(t), t.floor() as i64, "{t}");
        }
    }
}
