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
//! Nothing is sized by the bounding box's volume or extent: occupied finest cells are sorted
//! Morton codes, the coarser levels their shifted codes, the blocks at most `2^D − 1` per
//! occupied cell plus, at the coarsest level, the empty cells beside occupied ones (the others
//! are outside: see `empty_blocks`). Four samples 21 × 42 km apart at 0.3 m cells make four
//! cells and a few hundred blocks. Memory is checked against the budget as the codes grow
//! ([`BYTES_PER_OCCUPIED`]), and the triangles' candidate cells before they are enumerated. A
//! dense byte grid of the finest level would need 1024³ bytes (3.4 GB at the peak) for a
//! 257-point diagonal line 256 units long at 0.5 cells, of which 257 are occupied. The 64-bit
//! codes bound the finest cells along an axis to 2²¹ in 3D (2³¹ in 2D), which
//! [`crate::cells::build`] checks up front ([`Error::GridTooLarge`]).

use std::time::Instant;

use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};

use super::morton::{coords, morton};
use super::size::finest;
use super::winding::Winding;
use super::{BuildInfo, BuildParams, Inside};
use super::{CellComplex, CellKey, CellKind, Grid, triangle_box_overlap};
use crate::error::{Error, Result};
use crate::field::floor;
use crate::memory::Budget;
use crate::rigid::Vect;

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
        Ok(Self {
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
        })
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

    /// Sorts and deduplicates the occupied codes, and checks what the build will need for them
    /// against the budget.
    fn compact(&mut self) -> Result<()> {
        self.occupied.par_sort_unstable();
        self.occupied.dedup();
        self.sorted = self.occupied.len();
        crate::memory::check(
            &format!(
                "the cells of {} occupied finest cells of size {}",
                self.sorted,
                crate::human::length(self.grid.finest_size(), self.grid.finest_size())
            ),
            self.sorted as f64 * BYTES_PER_OCCUPIED as f64,
            self.limit,
            "use a larger --cell-size or --min-cell-size (or fewer --cells)",
        )
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
    pub fn finish(mut self) -> Result<(CellComplex<D>, BuildInfo)> {
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
        let blocks = empty_blocks(&grid, &levels);
        let (inside, winding_queries, is_inside) = match (inside, winding) {
            (Inside::Auto | Inside::Winding, Some(w)) => {
                let is_inside = classify_winding(&grid, &blocks, &w);
                (Inside::Winding, blocks.len(), is_inside)
            }
            (Inside::None, _) => (Inside::None, 0, vec![false; blocks.len()]),
            (Inside::Flood, _) | (Inside::Auto | Inside::Winding, None) => {
                (Inside::Flood, 0, classify_flood(&grid, &levels, &blocks))
            }
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
        return Err(Error::Input(format!(
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
        Some(l) if l <= 20 => l,
        Some(l) => return Err(Error::Param(format!("max level {l} is above 20"))),
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

/// Morton codes of the finest cells overlapped by `triangles`. The cells of the triangles'
/// boxes are counted first and checked against the budget `limit`.
fn triangle_cells<const D: usize>(
    grid: &Grid<D>,
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    limit: u64,
) -> Result<Vec<u64>> {
    let dims = grid.dims(grid.max_level);
    let size = grid.finest_size();
    let n = points.len();
    if let Some(t) = triangles
        .iter()
        .find(|t| t.iter().any(|&v| v as usize >= n))
    {
        return Err(Error::Input(format!(
            "a face refers to vertex {} but there are {n} vertices",
            t.iter().max().unwrap_or(&0)
        )));
    }
    let local = |t: &[u32; 3]| -> [[f64; 3]; 3] {
        t.map(|v| {
            let p = points[v as usize] - grid.origin;
            std::array::from_fn(|a| if a < D { p[a] } else { 0.0 })
        })
    };
    // The closed cells touching a triangle's box, i·s ≤ max and (i + 1)·s ≥ min, with a margin
    // against rounding (the exact test decides).
    let range = |tri: &[[f64; 3]; 3]| -> ([i64; 3], [i64; 3]) {
        let mut lo = [0i64; 3];
        let mut hi = [0i64; 3];
        for a in 0..D {
            let (mn, mx) = tri
                .iter()
                .fold((f64::MAX, f64::MIN), |(l, h), p| (l.min(p[a]), h.max(p[a])));
            // ⌈t⌉ − 1 = −⌊−t⌋ − 1 (libm's floor and ceil are calls on baseline x86-64).
            lo[a] = (-floor(-((mn - grid.lower[a]) / size - 1e-9)) - 1).max(0);
            hi[a] = floor((mx - grid.lower[a]) / size + 1e-9).min(dims[a] - 1);
        }
        (lo, hi)
    };
    let candidates: f64 = triangles
        .par_iter()
        .map(|t| {
            let (lo, hi) = range(&local(t));
            (0..3)
                .map(|a| (hi[a] - lo[a] + 1).max(1) as f64)
                .product::<f64>()
        })
        .sum();
    crate::memory::check(
        &format!(
            "rasterizing {} triangles into cells of size {size}",
            triangles.len()
        ),
        candidates * 8.0,
        limit,
        "use a larger --cell-size or --min-cell-size (or fewer --cells)",
    )?;
    let cells: Vec<u64> = triangles
        .par_iter()
        .fold(Vec::new, |mut out, t| {
            let tri = local(t);
            let (lo, hi) = range(&tri);
            if lo == hi {
                // The triangle's box lies in this one cell (a small triangle); runs of
                // triangles in one cell (a mesh's order) are stored once.
                let coord: [i64; D] = std::array::from_fn(|a| lo[a]);
                let code = morton(&coord);
                if out.last() != Some(&code) {
                    out.push(code);
                }
                return out;
            }
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        let c3 = [x, y, z];
                        let coord: [i64; D] = std::array::from_fn(|a| c3[a]);
                        let center = grid.center(&CellKey {
                            level: grid.max_level,
                            coord,
                        });
                        let c: [f64; 3] = std::array::from_fn(|a| center[a]);
                        if triangle_box_overlap(&tri, c, 0.5 * size) {
                            out.push(morton(&coord));
                        }
                    }
                }
            }
            out
        })
        .reduce(Vec::new, |mut a, b| {
            a.extend(b);
            a
        });
    Ok(cells)
}

/// The occupied cells of every level, coarsest first, as sorted Morton codes: a cell is
/// occupied when one of its finest descendants is.
fn pyramid<const D: usize>(grid: &Grid<D>, finest: Vec<u64>) -> Vec<Vec<u64>> {
    let mut levels = vec![finest];
    for _ in 0..grid.max_level {
        let fine = levels.last().expect("finest level present");
        // A parent's code is its child's shifted right: the order is kept.
        let mut coarse: Vec<u64> = fine.iter().map(|c| c >> D).collect();
        coarse.dedup();
        levels.push(coarse);
    }
    levels.reverse();
    levels
}

/// The maximal empty cells near the shape: every cell of level 0 that is not occupied but
/// touches an occupied one (edges and corners included), and every child that is not occupied
/// of an occupied cell above the finest level. With the level-0 cells far from the shape,
/// which are outside, they tile the grid's empty space, and each is wholly inside or wholly
/// outside the shape (the surface lies in occupied cells). Returned as `(level, code)`.
fn empty_blocks<const D: usize>(grid: &Grid<D>, levels: &[Vec<u64>]) -> Vec<(u8, u64)> {
    // Level 0: the empty cells among the 3^D around each occupied one. A level-0 cell is at
    // least as large as the box's shortest extent, so one with no occupied neighbor can hold
    // neither the surface nor any inside: it is outside, and is not enumerated (a grid of
    // 35,000 × 70,000 of them around four samples was 2.45e9 blocks).
    let mut near: Vec<u64> = levels[0]
        .iter()
        .flat_map(|&code| {
            let c = coords::<D>(code);
            (0..3usize.pow(D as u32)).filter_map(move |k| {
                let mut n = c;
                for (a, v) in n.iter_mut().enumerate() {
                    *v += (k / 3usize.pow(a as u32) % 3) as i64 - 1;
                    if *v < 0 || *v >= grid.dims0[a] {
                        return None;
                    }
                }
                Some(morton(&n))
            })
        })
        .filter(|code| levels[0].binary_search(code).is_err())
        .collect();
    near.sort_unstable();
    near.dedup();
    let mut blocks: Vec<(u8, u64)> = near.into_iter().map(|code| (0, code)).collect();
    for level in 1..levels.len() {
        let (parents, children) = (&levels[level - 1], &levels[level]);
        // Both are sorted and the children of a parent are the codes `p << D ..`: one merge.
        let mut j = 0;
        for &p in parents {
            for child in p << D..(p + 1) << D {
                while j < children.len() && children[j] < child {
                    j += 1;
                }
                if children.get(j) != Some(&child) {
                    blocks.push((level as u8, child));
                }
            }
        }
    }
    blocks
}

/// Classifies the empty blocks by the winding number of `winding`: the surface lies in
/// occupied cells only, so the winding number cannot cross ½ inside a block, and one
/// evaluation at its center classifies it.
fn classify_winding<const D: usize>(
    grid: &Grid<D>,
    blocks: &[(u8, u64)],
    winding: &Winding,
) -> Vec<bool> {
    blocks
        .par_iter()
        .map(|&(level, code)| {
            let c = grid.center(&CellKey {
                level,
                coord: coords(code),
            });
            winding
                .at(&Vect::<3>::from_fn(|a, _| if a < D { c[a] } else { 0.0 }))
                .abs()
                >= 0.5
        })
        .collect()
}

/// Classifies the empty blocks by the exterior flood fill: a block is outside when a path of
/// empty face-adjacent cells leads from it to the grid's border. The blocks are joined by a
/// union-find: each block looks across each face at the cell of its own level there; an empty
/// block there, or the coarser empty block that holds that cell, is joined to it, and an
/// occupied one is left to its own finer empty blocks, which find this block from their side.
/// So every pair of blocks sharing a face is joined once, as the finest cells of a dense grid
/// would be, and the work goes with the blocks.
fn classify_flood<const D: usize>(
    grid: &Grid<D>,
    levels: &[Vec<u64>],
    blocks: &[(u8, u64)],
) -> Vec<bool> {
    let mut index: Vec<FxHashMap<u64, u32>> = vec![FxHashMap::default(); levels.len()];
    for (k, &(level, code)) in blocks.iter().enumerate() {
        index[level as usize].insert(code, k as u32);
    }
    let outside = blocks.len() as u32;
    let mut parent: Vec<u32> = (0..=outside).collect();
    fn root(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    // The joins are found in parallel and applied in order, a bounded batch of blocks at a
    // time.
    const BATCH: usize = 1 << 18;
    for (b, batch) in blocks.chunks(BATCH).enumerate() {
        let joins: Vec<(u32, u32)> = batch
            .par_iter()
            .enumerate()
            .fold(Vec::new, |mut out, (i, &(level, code))| {
                let k = (b * BATCH + i) as u32;
                let dims = grid.dims(level);
                let c = coords::<D>(code);
                for a in 0..D {
                    for step in [-1i64, 1] {
                        let mut n = c;
                        n[a] += step;
                        if n[a] < 0 || n[a] >= dims[a] {
                            out.push((k, outside));
                            continue;
                        }
                        let (mut l, mut m) = (level as usize, morton(&n));
                        loop {
                            if let Some(&other) = index[l].get(&m) {
                                out.push((k, other));
                                break;
                            }
                            if levels[l].binary_search(&m).is_ok() {
                                break;
                            }
                            if l == 0 {
                                // An empty level-0 cell far from the shape: outside.
                                out.push((k, outside));
                                break;
                            }
                            l -= 1;
                            m >>= D;
                        }
                    }
                }
                out
            })
            .reduce(Vec::new, |mut a, b| {
                a.extend(b);
                a
            });
        for (a, b) in joins {
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            // The outside node stays a root, so a block is outside when its root is.
            if ra != rb {
                if ra == outside {
                    parent[rb as usize] = ra;
                } else {
                    parent[ra as usize] = rb;
                }
            }
        }
    }
    drop(index);
    (0..outside)
        .map(|k| root(&mut parent, k) != outside)
        .collect()
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
