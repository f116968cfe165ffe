//! Rasterization of the shape into the adaptive complex (paper §5).
//!
//! 1. The grid: finest cells of the user's size `S`; `max_level` levels above them (level-0 cells
//!    of size `S·2^max_level`); the grid is centered on the input's bounding box with at least one
//!    empty finest cell of margin on every side, so the exterior is connected around the shape.
//! 2. Occupancy at the finest level: the cell of every sample point, and every cell a triangle
//!    overlaps (exact test, so large triangles crossing many cells leave no gaps). Each
//!    triangle visits only the closed cells touching its bounding box, in parallel; a BVH over
//!    the triangles would find the same candidate cells and adds
//!    nothing here: one cell for a small triangle, and a large one must test its box anyway.
//! 3. Inside/outside of the empty space, tiled by the maximal empty cells of the tree ("blocks":
//!    every unoccupied cell of level 0, and every unoccupied child of an occupied cell): the
//!    surface lies in occupied cells, so each block is wholly inside or outside. For meshes and
//!    soups by the generalized winding number of the triangles ([`super::winding`]; one
//!    evaluation per block), which holes and unwelded or non-manifold surfaces do not fool; for
//!    point clouds with normals by its point variant (a dipole per occupied finest cell: the
//!    mean position, the mean normal times `c²/max|n_a|`, the area of a surface crossing one
//!    column of cells along the normal's dominant axis); for point clouds without normals by an
//!    exterior flood fill over the blocks (`classify_flood`, a union-find of face-adjacent
//!    blocks), which leaks through gaps wider than a cell.
//! 4. Leaves: every occupied finest cell is a boundary leaf, every inside block an interior
//!    leaf at its own level (the coarsest where it is all inside); outside blocks are dropped.
//!
//! With the default levels nothing is sized by the bounding box's volume or extent: occupied
//! finest cells are sorted Morton codes, the coarser levels their shifted codes, the blocks at
//! most `2^D − 1` per occupied cell plus, at the coarsest level, the empty cells beside occupied
//! ones (the others are outside: see `empty_blocks`). Four samples 21 × 42 km apart at 0.3 m
//! cells make four cells and a few hundred blocks. A `max_level` below the default makes the
//! level-0 cells smaller than the box's shortest extent: the inside then reaches level-0 cells
//! beside no occupied one, and every level-0 cell is a block (`root_blocks`), as many as the
//! box holds: a 4 × 1 × 1 bar at 1 mm cells with one level has 5·10⁸. Memory is checked against
//! the budget before the grid is filled (those level-0 cells), as the codes grow
//! ([`BYTES_PER_OCCUPIED`]), and for the triangles' candidate cells before they are enumerated;
//! the cells are forecast ([`Forecast`]) before the blocks are classified, so that a run that
//! cannot solve them stops before the build's longest part.
//! A dense byte grid of the finest level would need 1024³ bytes (3.4 GB at the peak) for a
//! 257-point diagonal line 256 units long at 0.5 cells, of which 257 are occupied. The 64-bit
//! codes bound the finest cells along an axis to 2²¹ in 3D (2³¹ in 2D), which
//! [`crate::cells::build`] checks up front ([`Error::GridTooLarge`]); the complex's 32-bit cell
//! indices bound its cells to [`MAX_CELLS`].

use std::time::Instant;

use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};

use super::blocks::{classify_flood, classify_winding, empty_blocks, pyramid, root_blocks};
use super::morton::{coords, morton};
use super::raster::{smaller_cells, triangle_cells};
use super::size::finest;
use super::winding::Winding;
use super::{BuildInfo, BuildParams, Inside};
use super::{CellComplex, CellKey, CellKind, Grid};
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::rigid::Vect;
use crate::said::{Opt, Said};

/// Finest cells along an axis at most: the coordinates' bits of a 64-bit Morton code (21 in 3D,
/// 31 in 2D).
const fn max_axis(d: usize) -> i64 {
    if d == 3 { 1 << 21 } else { 1 << 31 }
}
/// Bytes per occupied finest cell while the complex is built and used: the code, its share of
/// the coarser levels, of the empty blocks (up to `2^D − 1` per occupied parent, with the flood
/// fill's maps), of the leaves, and of the complex's cells and face adjacency that follow.
/// Measured peaks (release, `rigidcells cells`): 914 B per occupied cell on a 0.5 m soup at
/// 1 mm cells (2.56M occupied, 4.2M cells, 2.3 GB), 580 B on a 1M-point terrain at 2 m (input
/// included). It was 160 B, counting the build's codes only: a `--min-cell-size` of 1 mm
/// passed a 1.5 GB budget and peaked at 2.3 GB.
pub(crate) const BYTES_PER_OCCUPIED: u64 = 1 << 10;

/// Blocks whose winding numbers forecast the inside of a build with many blocks (the inside
/// fraction of an even sample: within about 1.5 % of the blocks, two standard deviations).
const FORECAST_SAMPLES: usize = 4096;

/// The cells a build will make, forecast once its occupied cells are known and the empty
/// space is tiled by blocks, before the blocks are classified (most of a large build's time: a
/// winding number each) or any leaf is made: what [`Occupancy::finish_checked`] hands its
/// check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Forecast {
    /// Occupied finest cells: the boundary leaves.
    pub occupied: usize,
    /// Blocks of the empty space, each inside or outside.
    pub blocks: usize,
    /// Interior leaves: counted where the blocks are classified already (the flood fill, a
    /// few thousand blocks), else the inside fraction of an even sample of
    /// `FORECAST_SAMPLES` blocks times their count.
    pub interior: usize,
    /// The finest cell size.
    pub cell_size: f64,
}

impl Forecast {
    /// The leaves of the complex.
    pub fn cells(&self) -> usize {
        self.occupied + self.interior
    }
}

/// The most cells a complex holds: its cells are numbered in 32 bits, and the transfer keeps
/// the two highest numbers for "none".
pub(crate) const MAX_CELLS: u64 = u32::MAX as u64 - 2;

/// The finest-level occupancy of a shape, filled a batch of samples at a time: the first pass
/// of the streaming pipeline, which never holds all samples. [`Occupancy::finish`] classifies
/// the empty cells and emits the adaptive complex.
///
/// Occupied finest cells are held as sorted Morton codes (a parent's code is its child's
/// shifted right by `D` bits), appended per batch and sorted and deduplicated whenever they
/// have doubled: memory goes with the occupied cells, not with the bounding box's volume.
#[derive(Debug, Clone)]
pub struct Occupancy<const D: usize> {
    grid: Grid<D>,
    dims: [i64; D],
    /// Morton codes of occupied finest cells: sorted and unique up to `sorted`.
    occupied: Vec<u64>,
    sorted: usize,
    /// Level-0 cells that are blocks of the empty space whether or not an occupied cell is
    /// beside them (0 with the default levels: see `root_blocks`).
    roots: u64,
    limit: u64,
    inside: Inside,
    /// The triangles seen so far (local frame), for winding numbers.
    winding: Option<Winding>,
    /// Oriented samples (point clouds with normals) gathered per voxel of a quarter finest
    /// cell: summed local position, summed unit normal, count.
    oriented: FxHashMap<[i64; D], (Vect<D>, Vect<D>, u32)>,
    glued: usize,
    start: Instant,
}

impl<const D: usize> Occupancy<D> {
    /// An empty grid over the box `lo..hi` (world coordinates) under `params`, within the
    /// memory `budget`.
    pub fn new(lo: &Vect<D>, hi: &Vect<D>, params: &BuildParams, budget: Budget) -> Result<Self> {
        let grid = frame(lo, hi, params)?;
        let dims = grid.dims(grid.max_level);
        let occupancy = Self {
            roots: root_blocks(&grid, &(hi - lo), params.inside),
            grid,
            dims,
            occupied: Vec::new(),
            sorted: 0,
            limit: budget.limit(),
            inside: params.inside,
            winding: None,
            oriented: FxHashMap::default(),
            glued: 0,
            start: Instant::now(),
        };
        // The level-0 cells enumerated whole are known before any sample.
        occupancy.check_cells()?;
        Ok(occupancy)
    }

    /// The grid (its origin is the local frame's).
    pub fn grid(&self) -> &Grid<D> {
        &self.grid
    }

    /// The Morton code of the finest cell holding the world point `p`, if inside the grid.
    #[inline]
    pub fn finest_index(&self, p: &Vect<D>) -> Option<u64> {
        self.grid
            .locate(&(p - self.grid.origin), self.grid.max_level)
            .map(|k| morton(&k.coord))
    }

    /// Marks the cells of world-coordinate samples. Returns how many fell outside the grid, or
    /// the budget's error when the occupied cells outgrow it.
    pub fn add_points(&mut self, points: &[Vect<D>]) -> Result<usize> {
        let mut outside = 0;
        for p in points {
            match self.finest_index(p) {
                Some(code) => {
                    // Runs of samples in one cell (scan order) are stored once.
                    if self.occupied.last() != Some(&code) {
                        self.occupied.push(code)
                    }
                }
                None => outside += 1,
            }
        }
        if self.occupied.len() > 2 * self.sorted + (1 << 20) {
            self.compact()?;
        }
        Ok(outside)
    }

    /// The occupied finest cells so far (sorted and deduplicated first).
    pub(crate) fn occupied_len(&mut self) -> Result<usize> {
        self.compact()?;
        Ok(self.occupied.len())
    }

    /// Sorts and deduplicates the occupied codes, and checks what the build will need for them
    /// against the budget.
    fn compact(&mut self) -> Result<()> {
        self.occupied.par_sort_unstable();
        self.occupied.dedup();
        self.sorted = self.occupied.len();
        self.check_cells()
    }

    /// Checks the cells the build will make of the occupied cells so far and of the level-0
    /// cells enumerated whole against the budget and [`MAX_CELLS`].
    fn check_cells(&self) -> Result<()> {
        let size = |s: f64| crate::human::length(s, s);
        let occupied = format!(
            "{} occupied finest cells of size {}",
            crate::human::count(self.sorted as u64),
            size(self.grid.finest_size())
        );
        let (what, advice) = match self.roots {
            0 => (
                Said::from(format!("the cells of {occupied}")),
                smaller_cells(),
            ),
            roots => (
                Said::from(format!(
                    "{}{} cells of size {} that tile the box at ",
                    match self.sorted {
                        0 => String::new(),
                        _ => format!("{occupied} and the "),
                    },
                    crate::human::count(roots),
                    size(self.grid.size0),
                ))
                .set(Opt::MaxLevel, self.grid.max_level),
                Said::from("use a larger ")
                    .aside(Said::new().opt(Opt::MaxLevel).text(
                        " (or leave it out: by default the largest cells are as large as \
                             the shape's thinnest extent), or a larger ",
                    ))
                    .opt(Opt::CellSize),
            ),
        };
        let cells = self.sorted as f64 + self.roots as f64;
        crate::memory::check(
            &what,
            cells * BYTES_PER_OCCUPIED as f64,
            self.limit,
            &advice,
        )?;
        if cells > MAX_CELLS as f64 {
            return Err(Error::param(
                what.text(format!(
                    " are more than the {MAX_CELLS} cells a complex numbers: "
                ))
                .then(advice),
            ));
        }
        Ok(())
    }

    /// Marks the cells of world-coordinate samples with unit `normals` and, unless the
    /// classification is flood fill or none, gathers them for the point variant of winding
    /// numbers (used when there are no triangles): one dipole per voxel of a quarter finest
    /// cell. Returns how many fell outside the grid.
    pub fn add_oriented_points(
        &mut self,
        points: &[Vect<D>],
        normals: &[Vect<D>],
    ) -> Result<usize> {
        let outside = self.add_points(points)?;
        if D == 3 && matches!(self.inside, Inside::Auto | Inside::Winding) {
            let voxel = self.grid.finest_size();
            for (p, n) in points.iter().zip(normals) {
                let local = p - self.grid.origin;
                let key: [i64; D] = std::array::from_fn(|a| (local[a] / voxel).floor() as i64);
                let e =
                    self.oriented
                        .entry(key)
                        .or_insert((Vect::<D>::zeros(), Vect::<D>::zeros(), 0));
                e.0 += local;
                e.1 += n;
                e.2 += 1;
            }
        }
        Ok(outside)
    }

    /// Marks every finest cell a triangle over `points` overlaps (3D; ignored in 2D), and keeps
    /// the triangles for winding numbers unless the classification is flood fill or none. Call
    /// it once, with all triangles.
    pub fn add_triangles(&mut self, points: &[Vect<D>], triangles: &[[u32; 3]]) -> Result<()> {
        if D == 3 && !triangles.is_empty() {
            let cells = triangle_cells(&self.grid, points, triangles, self.limit)?;
            self.occupied.extend(cells);
            self.compact()?;
            self.glued = self.glued_cells(points, triangles);
            if matches!(self.inside, Inside::Auto | Inside::Winding) {
                let local: Vec<Vect<3>> = points
                    .iter()
                    .map(|p| Vect::<3>::from_fn(|a, _| p[a] - self.grid.origin[a]))
                    .collect();
                let cluster = 0.5 * self.grid.finest_size();
                self.winding = Some(Winding::decimated(&local, triangles, cluster));
            }
        }
        Ok(())
    }

    /// Finest cells holding vertices of parts of the mesh that are not connected. Parts are the
    /// connected components of triangles over vertex positions (an unwelded soup of a closed
    /// surface is one part); vertices in no triangle are parts of their own.
    fn glued_cells(&self, points: &[Vect<D>], triangles: &[[u32; 3]]) -> usize {
        let mut parent: Vec<u32> = (0..points.len() as u32).collect();
        fn root(parent: &mut [u32], mut i: u32) -> u32 {
            while parent[i as usize] != i {
                parent[i as usize] = parent[parent[i as usize] as usize];
                i = parent[i as usize];
            }
            i
        }
        let union = |parent: &mut Vec<u32>, a: u32, b: u32| {
            let (ra, rb) = (root(parent, a), root(parent, b));
            parent[ra.max(rb) as usize] = ra.min(rb);
        };
        for t in triangles {
            union(&mut parent, t[0], t[1]);
            union(&mut parent, t[1], t[2]);
        }
        // A connected mesh (the common case) has nothing to glue.
        if (0..points.len() as u32).all(|i| root(&mut parent, i) == 0) {
            return 0;
        }
        let mut first_at = FxHashMap::default();
        for (i, p) in points.iter().enumerate() {
            let key: [u64; D] = std::array::from_fn(|a| p[a].to_bits());
            let j = *first_at.entry(key).or_insert(i as u32);
            union(&mut parent, i as u32, j);
        }
        let mut part_of_cell = FxHashMap::default();
        let mut glued = FxHashSet::default();
        for (i, p) in points.iter().enumerate() {
            let Some(cell) = self.finest_index(p) else {
                continue;
            };
            let part = root(&mut parent, i as u32);
            if *part_of_cell.entry(cell).or_insert(part) != part {
                glued.insert(cell);
            }
        }
        glued.len()
    }

    /// Classifies the empty cells and emits the leaves of the adaptive complex.
    pub fn finish(self) -> Result<(CellComplex<D>, BuildInfo)> {
        self.finish_checked(&|_| Ok(()))
    }

    /// [`Occupancy::finish`], handing `check` the [`Forecast`] of the cells once the empty
    /// space is tiled and before it is classified or any leaf is made: an error there ends the
    /// build (a run that cannot solve that many cells is refused before it spends the build's
    /// time and memory on them).
    pub fn finish_checked(
        mut self,
        check: &dyn Fn(&Forecast) -> Result<()>,
    ) -> Result<(CellComplex<D>, BuildInfo)> {
        self.compact()?;
        let Self {
            grid,
            dims,
            occupied,
            inside,
            winding,
            oriented,
            glued,
            start,
            roots,
            ..
        } = self;
        let winding = winding.or_else(|| {
            // The point variant: each voxel's mean position, its mean normal times the area of
            // a surface crossing a voxel column along the normal's dominant axis, c²/max|n_a|.
            let c = grid.finest_size();
            let (points, normals): (Vec<Vect<3>>, Vec<Vect<3>>) = oriented
                .values()
                .filter_map(|(p, n, k)| {
                    let p = Vect::<3>::from_fn(|a, _| if a < D { p[a] / *k as f64 } else { 0.0 });
                    let n = Vect::<3>::from_fn(|a, _| if a < D { n[a] } else { 0.0 });
                    let unit = n.try_normalize(1e-9)?;
                    Some((p, unit * (c * c / unit.amax())))
                })
                .unzip();
            (!points.is_empty()).then(|| Winding::from_dipoles(&points, &normals))
        });
        let occupied_count = occupied.len();
        let levels = pyramid::<D>(&grid, occupied);
        let blocks = empty_blocks(&grid, &levels, roots > 0);
        // The blocks are classified here when that is cheap (the flood fill, few blocks), else
        // a sample of them forecasts the inside, and the rest waits for the check.
        let (inside, classified, interior) = match (inside, &winding) {
            (Inside::Auto | Inside::Winding, Some(w)) if blocks.len() > 4 * FORECAST_SAMPLES => {
                let sample: Vec<(u8, u64)> = (0..FORECAST_SAMPLES)
                    .map(|k| blocks[k * blocks.len() / FORECAST_SAMPLES])
                    .collect();
                let inside = classify_winding(&grid, &sample, w);
                let fraction = inside.iter().filter(|&&b| b).count() as f64 / sample.len() as f64;
                let interior = (fraction * blocks.len() as f64).round() as usize;
                (Inside::Winding, None, interior)
            }
            (Inside::Auto | Inside::Winding, Some(w)) => (
                Inside::Winding,
                Some(classify_winding(&grid, &blocks, w)),
                0,
            ),
            (Inside::None, _) => (Inside::None, Some(vec![false; blocks.len()]), 0),
            (Inside::Flood, _) | (Inside::Auto | Inside::Winding, None) => (
                Inside::Flood,
                Some(classify_flood(&grid, &levels, &blocks)),
                0,
            ),
        };
        let interior = match &classified {
            Some(is_inside) => is_inside.iter().filter(|&&b| b).count(),
            None => interior,
        };
        check(&Forecast {
            occupied: occupied_count,
            blocks: blocks.len(),
            interior,
            cell_size: grid.finest_size(),
        })?;
        let winding_queries = match inside {
            Inside::Winding => blocks.len(),
            _ => 0,
        };
        let is_inside = match (classified, &winding) {
            (Some(is_inside), _) => is_inside,
            (None, Some(w)) => classify_winding(&grid, &blocks, w),
            (None, None) => unreachable!("blocks are sampled by winding numbers only"),
        };
        let finest = grid.max_level;
        let mut leaves: Vec<(CellKey<D>, CellKind)> = levels[finest as usize]
            .iter()
            .map(|&code| {
                let key = CellKey {
                    level: finest,
                    coord: coords(code),
                };
                (key, CellKind::Boundary)
            })
            .collect();
        let boundary_cells = leaves.len();
        leaves.extend(
            blocks
                .iter()
                .zip(&is_inside)
                .filter(|(_, inside)| **inside)
                .map(|(&(level, code), _)| {
                    let key = CellKey {
                        level,
                        coord: coords(code),
                    };
                    (key, CellKind::Interior)
                }),
        );
        drop(levels);
        drop(blocks);
        leaves.par_sort_unstable_by_key(|(k, _)| *k);
        let interior_cells = leaves.len() - boundary_cells;
        let complex = CellComplex::from_keys(grid, leaves);
        let info = BuildInfo {
            finest_dims: dims.to_vec(),
            occupied: occupied_count,
            boundary_cells,
            interior_cells,
            inside,
            winding_queries,
            glued_cells: glued,
            seconds: start.elapsed().as_secs_f64(),
        };
        Ok((complex, info))
    }
}

/// The grid for the box `lo..hi` under `params`.
fn frame<const D: usize>(lo: &Vect<D>, hi: &Vect<D>, params: &BuildParams) -> Result<Grid<D>> {
    if !(lo.iter().chain(hi.iter()).all(|v| v.is_finite())) || (0..D).any(|a| lo[a] > hi[a]) {
        return Err(Error::input(format!(
            "the bounding box {:?}..{:?} is not finite",
            lo.as_slice(),
            hi.as_slice()
        )));
    }
    let (lo, hi) = (*lo, *hi);
    let extent = hi - lo;
    let longest = extent.max();
    let shortest = extent.min();
    let size = finest(params.cell_size, longest)?;
    let levels = match params.max_level {
        Some(l) if l <= MAX_LEVEL => l,
        Some(l) => return Err(Error::param(max_level_refused(l))),
        // An interior cell lies inside the shape, so no leaf is larger than the box's shortest
        // extent: coarser levels would only make the finest grid a cube over the longest
        // extent (a 2 km terrain 110 m high at 2.5 m cells: 1024³ finest cells instead of
        // 832 × 832 × 64).
        // At least one level, so the finest grid has an even number of cells along each axis
        // and the box's center lies on cell faces, as it did with the cubic grid: a scan
        // thinner than a cell then keeps two layers of cells rather than one plane of centers,
        // on which the dense RBF's linear part is undetermined.
        None => (shortest / size).max(2.0).log2().ceil().min(20.0) as u8,
    };
    let block = (1i64 << levels) as f64;
    let mut dims0 = [0i64; D];
    for a in 0..D {
        let needed = (extent[a] / size).ceil() + 2.0;
        let along = (needed / block).ceil().max(1.0);
        // Finest coordinates must fit the Morton codes' bits.
        if along * block > max_axis(D) as f64 {
            return Err(Error::GridTooLarge {
                cell_size: size,
                // A count past u128 (a size of 1e-300) saturates; the message says its power.
                cells: (along * block).min(u128::MAX as f64) as u128,
                max: max_axis(D) as u128,
            });
        }
        dims0[a] = along as i64;
    }
    let size0 = size * block;
    let origin = (lo + hi) * 0.5;
    let lower = Vect::<D>::from_fn(|a, _| -0.5 * dims0[a] as f64 * size0);
    Ok(Grid {
        origin,
        lower,
        size0,
        dims0,
        max_level: levels,
    })
}

/// The most octree levels above the finest cells (`--max-level`): a root cell 2²⁰ finest cells
/// wide.
pub const MAX_LEVEL: u8 = 20;

/// The refusal of `--max-level l` past [`MAX_LEVEL`], in every face's words.
pub(crate) fn max_level_refused(l: u8) -> Said {
    Said::new().set(Opt::MaxLevel, l).text(format!(
        ": at most {MAX_LEVEL} levels above the finest cells"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::build;

    /// The flood fill over maximal empty blocks classifies every finest cell as a flood over a
    /// dense grid would: random walls with holes and enclosed pockets, in 2D and 3D.
    #[test]
    fn block_flood_matches_a_dense_flood() {
        fn check<const D: usize>(seed: u64, side: i64) {
            let mut state = seed;
            let mut rand = move || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state
            };
            // Hollow boxes (some with a hole) and scattered cells, on a grid of unit cells.
            let mut occupied = std::collections::BTreeSet::new();
            for _ in 0..4 {
                let lo: [i64; D] = std::array::from_fn(|_| 1 + (rand() % (side as u64 - 8)) as i64);
                let len: [i64; D] = std::array::from_fn(|_| 3 + (rand() % 5) as i64);
                let hole = rand() % 2 == 0;
                let n: i64 = len.iter().product();
                for k in 0..n {
                    let mut r = k;
                    let c: [i64; D] = std::array::from_fn(|a| {
                        let v = r % len[a];
                        r /= len[a];
                        v
                    });
                    let wall = (0..D).any(|a| c[a] == 0 || c[a] == len[a] - 1);
                    let at_hole = hole && c[0] == 0 && (1..D).all(|a| c[a] == len[a] / 2);
                    if wall && !at_hole {
                        occupied.insert(std::array::from_fn::<i64, D, _>(|a| lo[a] + c[a]));
                    }
                }
            }
            for _ in 0..20 {
                occupied.insert(std::array::from_fn::<i64, D, _>(|_| {
                    (rand() % side as u64) as i64
                }));
            }
            let points: Vec<Vect<D>> = occupied
                .iter()
                .map(|c| Vect::<D>::from_fn(|a, _| c[a] as f64 + 0.5))
                .chain([Vect::<D>::zeros(), Vect::<D>::repeat(side as f64)])
                .collect();
            let params = BuildParams {
                cell_size: Some(1.0),
                inside: Inside::Flood,
                ..Default::default()
            };
            let (complex, info) = build(&points, &[], &params, Budget::default()).unwrap();
            complex.validate().unwrap();
            // The dense reference on the same finest grid.
            let g = complex.grid;
            let dims = g.dims(g.max_level);
            let total: i64 = dims.iter().product();
            let index = |c: &[i64; D]| (0..D).rev().fold(0i64, |i, a| i * dims[a] + c[a]) as usize;
            let coord = |mut i: i64| -> [i64; D] {
                std::array::from_fn(|a| {
                    let v = i % dims[a];
                    i /= dims[a];
                    v
                })
            };
            let mut busy = vec![false; total as usize];
            for p in &points {
                let k = g.locate(&(p - g.origin), g.max_level).unwrap();
                busy[index(&k.coord)] = true;
            }
            let mut outside = vec![false; total as usize];
            let mut stack: Vec<i64> = (0..total)
                .filter(|&i| {
                    let c = coord(i);
                    !busy[i as usize] && (0..D).any(|a| c[a] == 0 || c[a] == dims[a] - 1)
                })
                .collect();
            for &i in &stack {
                outside[i as usize] = true;
            }
            while let Some(i) = stack.pop() {
                let c = coord(i);
                for a in 0..D {
                    for step in [-1, 1] {
                        let mut n = c;
                        n[a] += step;
                        if n[a] < 0 || n[a] >= dims[a] {
                            continue;
                        }
                        let j = index(&n);
                        if !busy[j] && !outside[j] {
                            outside[j] = true;
                            stack.push(j as i64);
                        }
                    }
                }
            }
            let mut inside = 0;
            for i in 0..total {
                let c = coord(i);
                let center = g.center(&CellKey {
                    level: g.max_level,
                    coord: c,
                });
                let got = complex.locate(&center).map(|k| complex.cells[k].kind);
                let want = if busy[i as usize] {
                    Some(CellKind::Boundary)
                } else if outside[i as usize] {
                    None
                } else {
                    inside += 1;
                    Some(CellKind::Interior)
                };
                assert_eq!(got, want, "{D}D seed {seed}: finest cell {c:?}");
            }
            assert!(inside > 0 && info.interior_cells > 0, "{D}D seed {seed}");
        }
        for seed in 1..6 {
            check::<3>(seed * 7919, 24);
            check::<2>(seed * 104_729, 40);
        }
    }

    fn box_surface_points(n: usize, size: [f64; 3]) -> Vec<Vect<3>> {
        // Dense samples on the six faces of an axis-aligned box at the origin.
        let mut pts = Vec::new();
        for a in 0..3 {
            for side in [0.0, 1.0] {
                for i in 0..=n {
                    for j in 0..=n {
                        let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                        let mut p = [0.0; 3];
                        p[a] = side * size[a];
                        p[(a + 1) % 3] = u * size[(a + 1) % 3];
                        p[(a + 2) % 3] = v * size[(a + 2) % 3];
                        pts.push(Vect::<3>::from(p));
                    }
                }
            }
        }
        pts
    }

    #[test]
    fn closed_box_gets_interior_cells_and_validates() {
        let pts = box_surface_points(60, [4.0, 4.0, 4.0]);
        let params = BuildParams {
            cell_size: Some(0.25),
            ..Default::default()
        };
        let (complex, info) = build(&pts, &[], &params, Budget::default()).unwrap();
        complex.validate().unwrap();
        assert!(info.interior_cells > 0);
        // Interior cells are coarse: fewer than the finest interior count.
        let coarse = complex
            .cells
            .iter()
            .filter(|c| c.kind == CellKind::Interior && c.key.level < complex.grid.max_level)
            .count();
        assert!(coarse > 0);
        // Every sample lies in a cell and the complex is one component.
        assert!(
            pts.iter()
                .all(|p| complex.locate(&(p - complex.grid.origin)).is_some())
        );
        assert_eq!(complex.components().1, 1);
        // The cells cover the box volume (boundary cells overhang by up to one layer).
        let vol: f64 = complex.cells.iter().map(|c| c.volume()).sum();
        assert!(vol > 64.0 && vol < 4.6f64.powi(3), "volume {vol}");
    }

    /// Fewer levels than the default (`max_level` given) make level-0 cells smaller than the
    /// box: the inside away from the surface is filled all the same, the same finest cells as
    /// with the default levels, by the flood fill and by winding numbers.
    #[test]
    fn few_levels_fill_the_same_inside() {
        let pts = box_surface_points(60, [2.0, 1.0, 1.0]);
        let normals: Vec<Vect<3>> = pts
            .iter()
            .map(|p| {
                let d = Vect::<3>::from_fn(|a, _| {
                    let s = [2.0, 1.0, 1.0][a];
                    if p[a] == 0.0 {
                        -1.0
                    } else if p[a] == s {
                        1.0
                    } else {
                        0.0
                    }
                });
                d.normalize()
            })
            .collect();
        for oriented in [false, true] {
            let volume = |max_level: Option<u8>| {
                let params = BuildParams {
                    cell_size: Some(0.07),
                    max_level,
                    ..Default::default()
                };
                let (lo, hi) = crate::cells::bounds(&pts).unwrap();
                let mut occupancy = Occupancy::new(&lo, &hi, &params, Budget::default()).unwrap();
                match oriented {
                    true => occupancy.add_oriented_points(&pts, &normals).unwrap(),
                    false => occupancy.add_points(&pts).unwrap(),
                };
                let (complex, info) = occupancy.finish().unwrap();
                complex.validate().unwrap();
                let want = if oriented {
                    Inside::Winding
                } else {
                    Inside::Flood
                };
                assert_eq!(info.inside, want);
                complex.cells.iter().map(|c| c.volume()).sum::<f64>()
            };
            let whole = volume(None);
            assert!(whole > 2.0, "{whole}");
            // One level or more keeps the finest grid's alignment (an even number of cells
            // along each axis, centered on the box), so the cells are the same.
            for levels in [1, 2] {
                let v = volume(Some(levels));
                assert!(
                    (v - whole).abs() <= 1e-9 * whole,
                    "{levels}: {v} against {whole}"
                );
            }
        }
    }

    /// The level-0 cells that fewer levels make are counted against the budget before any
    /// sample, with the advice to raise `--max-level`.
    #[test]
    fn few_levels_are_refused_past_the_budget() {
        let (lo, hi) = (Vect::<3>::zeros(), Vect::<3>::new(4.0, 1.0, 1.0));
        let params = BuildParams {
            cell_size: Some(1e-3),
            max_level: Some(1),
            ..Default::default()
        };
        let e = Occupancy::new(&lo, &hi, &params, Budget::bytes(1 << 30)).unwrap_err();
        assert!(matches!(e, Error::Memory { .. }), "{e}");
        assert!(e.to_string().contains("--max-level"), "{e}");
        // Without an inside to fill, nothing beside the shape is enumerated.
        let shell = BuildParams {
            inside: Inside::None,
            ..params
        };
        assert!(Occupancy::new(&lo, &hi, &shell, Budget::bytes(1 << 30)).is_ok());
    }

    #[test]
    fn shell_mode_has_no_interior() {
        let pts = box_surface_points(40, [2.0, 2.0, 2.0]);
        let params = BuildParams {
            cell_size: Some(0.25),
            inside: Inside::None,
            ..Default::default()
        };
        let (_, info) = build(&pts, &[], &params, Budget::default()).unwrap();
        assert_eq!(info.interior_cells, 0);
    }

    #[test]
    fn rejects_bad_input() {
        assert!(build::<3>(&[], &[], &BuildParams::default(), Budget::default()).is_err());
        let nan = [Vect::<3>::new(f64::NAN, 0.0, 0.0)];
        assert!(build(&nan, &[], &BuildParams::default(), Budget::default()).is_err());
        let tiny = BuildParams {
            cell_size: Some(1e-9),
            ..Default::default()
        };
        let pts = [Vect::<3>::zeros(), Vect::<3>::new(1.0, 1.0, 1.0)];
        assert!(matches!(
            build(&pts, &[], &tiny, Budget::default()),
            Err(Error::GridTooLarge { .. })
        ));
    }

    #[test]
    fn disjoint_parts_stay_separate_components() {
        let mut pts = box_surface_points(20, [1.0, 1.0, 1.0]);
        pts.extend(
            box_surface_points(20, [1.0, 1.0, 1.0])
                .into_iter()
                .map(|p| p + Vect::<3>::new(3.0, 0.0, 0.0)),
        );
        let params = BuildParams {
            cell_size: Some(0.2),
            ..Default::default()
        };
        let (complex, _) = build(&pts, &[], &params, Budget::default()).unwrap();
        assert_eq!(complex.components().1, 2);
    }
}
