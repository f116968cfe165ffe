//! Rasterization of the shape into the adaptive complex (paper §5).
//!
//! 1. The grid: finest cells of the user's size `S`; `max_level` levels above them (level-0 cells
//!    of size `S·2^max_level`); the grid is centered on the input's bounding box with at least one
//!    empty finest cell of margin on every side, so the exterior is connected around the shape.
//! 2. Occupancy at the finest level: the cell of every sample point, and every cell a triangle
//!    overlaps (exact test, so large triangles crossing many cells leave no gaps). Each
//!    triangle visits only the closed cells touching its bounding box, in parallel; a BVH over
//!    the triangles (issue 4 suggested `obvhs`) would find the same candidate cells and adds
//!    nothing here: one cell for a small triangle, and a large one must test its box anyway.
//! 3. Inside/outside of the empty finest cells: for meshes and soups by the generalized winding
//!    number of the triangles ([`super::winding`]; one evaluation per coarsest all-empty cell),
//!    which holes and unwelded or non-manifold surfaces do not fool; for point clouds with
//!    normals by its point variant (a dipole per occupied finest cell: the mean position, the
//!    mean normal times `c²/max|n_a|`, the area of a surface crossing one column of cells along
//!    the normal's dominant axis); for point clouds without normals by the exterior flood fill
//!    of [`classify_inside`], which leaks through gaps wider than a cell.
//! 4. A pyramid of states from the finest level up; leaves are emitted top-down: a cell that is
//!    all inside is an interior leaf at the coarsest level where that holds, a cell with occupied
//!    descendants is split down to `max_level`, a cell all outside is dropped.
//!
//! The finest level is held as a dense byte grid; that bounds the extent/cell-size ratio (about
//! 2·10⁹ finest cells), which [`build`] checks up front. Streaming occupancy for inputs larger
//! than memory is a later stage's job; this one takes the samples in memory.

use std::time::Instant;

use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};

use super::winding::Winding;
use super::{CellComplex, CellKey, CellKind, Grid, triangle_box_overlap};
use crate::error::{Error, Result};
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

/// Parameters of [`build`].
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
    /// The memory budget in bytes ([`crate::memory`]; `None`: the default share of the
    /// machine's memory).
    pub memory_limit: Option<u64>,
}

impl Default for BuildParams {
    fn default() -> Self {
        Self {
            cell_size: None,
            max_level: None,
            inside: Inside::Auto,
            target_cells: None,
            memory_limit: None,
        }
    }
}

/// What [`build`] did.
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
    /// Winding-number evaluations (one per empty cell of the coarsest level that has no
    /// occupied descendant).
    pub winding_queries: usize,
    /// Finest cells holding vertices of two or more parts of a mesh that are not connected
    /// (sharing no vertex position): such parts are glued there, up to the finest cell size.
    pub glued_cells: usize,
    /// Seconds spent.
    pub seconds: f64,
}

const OUT: u8 = 0;
const IN: u8 = 1;
const OCCUPIED: u8 = 2;
/// Largest finest grid [`build`] allocates (one byte per cell).
const MAX_FINEST_CELLS: u128 = 1 << 31;

/// Builds the cell complex of a shape given by `points` (world coordinates) and, in 3D,
/// `triangles` (indices into `points`; pass `&[]` for a point cloud).
pub fn build<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    params: &BuildParams,
) -> Result<(CellComplex<D>, BuildInfo)> {
    let (lo, hi) = bounds(points)?;
    let sized;
    let params = match params.target_cells {
        Some(n) => {
            sized = BuildParams {
                cell_size: Some(cell_size_for(points, triangles, params, n)?),
                target_cells: None,
                ..*params
            };
            &sized
        }
        None => params,
    };
    let mut occupancy = Occupancy::new(&lo, &hi, params)?;
    occupancy.add_points(points);
    occupancy.add_triangles(points, triangles)?;
    Ok(occupancy.finish())
}

/// The finest cell size for which the complex of `points` (and `triangles`) has about `target`
/// cells (within 2 %, where the counts allow), between 1/4096 and 1/2 of the longest extent.
/// Streaming callers pass a decimated proxy of the samples.
///
/// Each try is a whole build, so few are made: the count of a surface's cells goes about as
/// `size⁻²`, so the search steps by the secant of `log count` against `log size` through the
/// last two tries, kept inside the bracket of sizes known to give too many and too few cells
/// (and halving it in log space where the secant would leave it). On the dragon this takes 4–6
/// builds where the former bisection took 20.
pub fn cell_size_for<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    params: &BuildParams,
    target: usize,
) -> Result<f64> {
    let (lo, hi) = bounds(points)?;
    let longest = (hi - lo).max().max(f64::MIN_POSITIVE);
    // `small` gives too many cells (or fails), `large` at most `target`.
    let (mut small, mut large) = (longest / 4096.0, longest / 2.0);
    let count = |size: f64| -> Result<Option<usize>> {
        let at = BuildParams {
            cell_size: Some(size),
            target_cells: None,
            ..*params
        };
        match build(points, triangles, &at) {
            Ok((complex, _)) => Ok(Some(complex.len())),
            Err(Error::GridTooLarge { .. } | Error::Memory { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    };
    let goal = (target.max(1) as f64).ln();
    let mut last: Option<(f64, f64)> = None; // (ln size, ln count) of the previous try
    let mut size = longest / 32.0;
    for _ in 0..24 {
        if large / small < 1.002 {
            break;
        }
        let got = count(size)?;
        let ok = got.is_some_and(|c| c <= target);
        if ok {
            large = size
        } else {
            small = size
        }
        if let Some(c) = got
            && (c as f64 / target as f64 - 1.0).abs() <= 0.02
        {
            return Ok(size);
        }
        let now = got.map(|c| (size.ln(), (c.max(1) as f64).ln()));
        let slope = match (last, now) {
            (Some((s0, c0)), Some((s1, c1))) if (s1 - s0).abs() > 1e-12 && c1 != c0 => {
                ((c1 - c0) / (s1 - s0)).min(-0.5)
            }
            _ => -2.0,
        };
        let next = match now {
            Some((s1, c1)) => (s1 + (goal - c1) / slope).exp(),
            None => (small * large).sqrt(),
        };
        size = if next > small && next < large {
            next
        } else {
            (small * large).sqrt()
        };
        if now.is_some() {
            last = now;
        }
    }
    Ok(large)
}

/// The bounding box of `points`; an error for no points or a coordinate that is not finite.
pub fn bounds<const D: usize>(points: &[Vect<D>]) -> Result<(Vect<D>, Vect<D>)> {
    if points.is_empty() {
        return Err(Error::Input("the input has no points".into()));
    }
    if let Some(i) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(Error::Input(format!(
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

/// The finest-level occupancy of a shape, filled a batch of samples at a time: the first pass
/// of the streaming pipeline, which never holds all samples. [`Occupancy::finish`] classifies
/// the empty cells and emits the adaptive complex.
#[derive(Debug, Clone)]
pub struct Occupancy<const D: usize> {
    grid: Grid<D>,
    dims: [i64; D],
    state: Vec<u8>,
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
    /// An empty grid over the box `lo..hi` (world coordinates) under `params`.
    pub fn new(lo: &Vect<D>, hi: &Vect<D>, params: &BuildParams) -> Result<Self> {
        let grid = frame(lo, hi, params)?;
        let dims = grid.dims(grid.max_level);
        Ok(Self {
            grid,
            dims,
            state: vec![OUT; dims.iter().product::<i64>() as usize],
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

    /// The linear index of the finest cell holding the world point `p`, if inside the grid.
    #[inline]
    pub fn finest_index(&self, p: &Vect<D>) -> Option<usize> {
        self.grid
            .locate(&(p - self.grid.origin), self.grid.max_level)
            .map(|k| linear(&k.coord, &self.dims))
    }

    /// Marks the cells of world-coordinate samples. Returns how many fell outside the grid.
    pub fn add_points(&mut self, points: &[Vect<D>]) -> usize {
        let mut outside = 0;
        for p in points {
            match self.finest_index(p) {
                Some(i) => self.state[i] = OCCUPIED,
                None => outside += 1,
            }
        }
        outside
    }

    /// Marks the cells of world-coordinate samples with unit `normals` and, unless the
    /// classification is flood fill or none, gathers them for the point variant of winding
    /// numbers (used when there are no triangles): one dipole per voxel of a quarter finest
    /// cell. Returns how many fell outside the grid.
    pub fn add_oriented_points(&mut self, points: &[Vect<D>], normals: &[Vect<D>]) -> usize {
        let outside = self.add_points(points);
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
        outside
    }

    /// Marks every finest cell a triangle over `points` overlaps (3D; ignored in 2D), and keeps
    /// the triangles for winding numbers unless the classification is flood fill or none. Call
    /// it once, with all triangles.
    pub fn add_triangles(&mut self, points: &[Vect<D>], triangles: &[[u32; 3]]) -> Result<()> {
        if D == 3 && !triangles.is_empty() {
            for idx in triangle_cells(&self.grid, points, triangles)? {
                self.state[idx] = OCCUPIED;
            }
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
    pub fn finish(self) -> (CellComplex<D>, BuildInfo) {
        let Self {
            grid,
            dims,
            mut state,
            inside,
            winding,
            oriented,
            glued,
            start,
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
        let occupied = state.iter().filter(|&&s| s == OCCUPIED).count();
        let (inside, winding_queries) = match (inside, winding) {
            (Inside::Auto | Inside::Winding, Some(w)) => {
                (Inside::Winding, classify_winding(&grid, &mut state, &w))
            }
            (Inside::Auto | Inside::Winding, None) => {
                classify_inside(&dims, &mut state, Inside::Flood);
                (Inside::Flood, 0)
            }
            (mode, _) => {
                classify_inside(&dims, &mut state, mode);
                (mode, 0)
            }
        };
        let pyramid = pyramid(&grid, state);
        let mut leaves = Vec::new();
        let mut stack: Vec<CellKey<D>> = Vec::new();
        for_each_coord(&grid.dims0, |coord| stack.push(CellKey { level: 0, coord }));
        while let Some(key) = stack.pop() {
            let s = pyramid[key.level as usize][linear(&key.coord, &grid.dims(key.level))];
            match s {
                IN => leaves.push((key, CellKind::Interior)),
                OCCUPIED if key.level == grid.max_level => leaves.push((key, CellKind::Boundary)),
                OCCUPIED => stack.extend(key.children()),
                _ => {}
            }
        }
        leaves.sort_unstable_by_key(|(k, _)| *k);
        let boundary_cells = leaves
            .iter()
            .filter(|(_, k)| *k == CellKind::Boundary)
            .count();
        let interior_cells = leaves.len() - boundary_cells;
        let complex = CellComplex::from_keys(grid, leaves);
        let info = BuildInfo {
            finest_dims: dims.to_vec(),
            occupied,
            boundary_cells,
            interior_cells,
            inside,
            winding_queries,
            glued_cells: glued,
            seconds: start.elapsed().as_secs_f64(),
        };
        (complex, info)
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
    let size = match params.cell_size {
        Some(s) if s.is_finite() && s > 0.0 => s,
        Some(s) => return Err(Error::Param(format!("cell size {s} must be positive"))),
        None if longest > 0.0 => longest / 32.0,
        None => 1.0,
    };
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
    let mut finest = 1u128;
    for a in 0..D {
        let needed = (extent[a] / size).ceil() + 2.0;
        dims0[a] = (needed / block).ceil().max(1.0) as i64;
        finest = finest.saturating_mul((dims0[a] as u128) << levels);
    }
    if finest > MAX_FINEST_CELLS {
        return Err(Error::GridTooLarge {
            cell_size: size,
            cells: finest,
        });
    }
    crate::memory::check(
        &format!("the finest grid of {finest} cells of size {size}"),
        crate::memory::grid_bytes(finest as f64, params.inside != Inside::None),
        crate::memory::limit(params.memory_limit),
        "use a larger --cell-size (or fewer --cells)",
    )?;
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

/// Indices of the finest cells overlapped by `triangles`.
fn triangle_cells<const D: usize>(
    grid: &Grid<D>,
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
) -> Result<Vec<usize>> {
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
    let cells: Vec<usize> = triangles
        .par_iter()
        .fold(Vec::new, |mut out, t| {
            let tri: [[f64; 3]; 3] = t.map(|v| {
                let p = points[v as usize] - grid.origin;
                std::array::from_fn(|a| if a < D { p[a] } else { 0.0 })
            });
            let mut lo = [0i64; 3];
            let mut hi = [0i64; 3];
            for a in 0..D {
                let (mn, mx) = tri
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(l, h), p| (l.min(p[a]), h.max(p[a])));
                // Closed cells touching the triangle's box, i·s ≤ mx and (i + 1)·s ≥ mn, with
                // a margin against rounding (the exact test below decides).
                lo[a] = (((mn - grid.lower[a]) / size - 1e-9).ceil() as i64 - 1).max(0);
                hi[a] = (((mx - grid.lower[a]) / size + 1e-9).floor() as i64).min(dims[a] - 1);
            }
            if lo == hi {
                // The triangle's box lies in this one cell (a small triangle).
                let coord: [i64; D] = std::array::from_fn(|a| lo[a]);
                out.push(linear(&coord, &dims));
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
                            out.push(linear(&coord, &dims));
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

/// Classifies the empty cells of a dense finest grid in place: `state` holds `2` for occupied
/// cells and `0` elsewhere on entry; on return every empty cell is `0` (outside) or `1`
/// (inside). This is the one place where inside/outside is decided; other classifiers (winding
/// numbers for meshes) replace it here.
pub fn classify_inside<const D: usize>(dims: &[i64; D], state: &mut [u8], mode: Inside) {
    if mode == Inside::None || mode == Inside::Winding {
        return;
    }
    // Everything empty starts inside; the flood from the border marks the outside.
    for s in state.iter_mut() {
        if *s == OUT {
            *s = IN;
        }
    }
    // The stack holds linear indices (the grid has at most 2³¹ cells): 4 bytes a cell at worst.
    let strides: [usize; D] = std::array::from_fn(|a| dims[..a].iter().product::<i64>() as usize);
    let mut stack: Vec<u32> = Vec::new();
    for_each_coord(dims, |c| {
        if (0..D).any(|a| c[a] == 0 || c[a] == dims[a] - 1) {
            let i = linear(&c, dims);
            if state[i] == IN {
                state[i] = OUT;
                stack.push(i as u32);
            }
        }
    });
    while let Some(i) = stack.pop() {
        let i = i as usize;
        for a in 0..D {
            let c = (i / strides[a]) as i64 % dims[a];
            for (ok, n) in [
                (c > 0, i.wrapping_sub(strides[a])),
                (c + 1 < dims[a], i + strides[a]),
            ] {
                if ok && state[n] == IN {
                    state[n] = OUT;
                    stack.push(n as u32);
                }
            }
        }
    }
}

/// Classifies the empty finest cells by the winding number of `winding`: the surface lies in
/// occupied cells only, so the winding number cannot cross ½ inside a cell with no occupied
/// descendant, and one evaluation at the center of the coarsest such cell classifies all its
/// finest cells. Returns the number of evaluations.
fn classify_winding<const D: usize>(grid: &Grid<D>, state: &mut [u8], winding: &Winding) -> usize {
    let levels = pyramid(grid, state.to_vec());
    let mut empty = Vec::new();
    let mut stack = Vec::new();
    for_each_coord(&grid.dims0, |coord| stack.push(CellKey { level: 0, coord }));
    while let Some(key) = stack.pop() {
        match levels[key.level as usize][linear(&key.coord, &grid.dims(key.level))] {
            OUT => empty.push(key),
            _ if key.level < grid.max_level => stack.extend(key.children()),
            _ => {}
        }
    }
    let inside: Vec<bool> = empty
        .par_iter()
        .map(|key| {
            let c = grid.center(key);
            winding
                .at(&Vect::<3>::from_fn(|a, _| if a < D { c[a] } else { 0.0 }))
                .abs()
                >= 0.5
        })
        .collect();
    let dims = grid.dims(grid.max_level);
    for (key, _) in empty.iter().zip(&inside).filter(|(_, i)| **i) {
        let shift = grid.max_level - key.level;
        let span: [i64; D] = [1i64 << shift; D];
        for_each_coord(&span, |d| {
            let fine: [i64; D] = std::array::from_fn(|a| (key.coord[a] << shift) + d[a]);
            state[linear(&fine, &dims)] = IN;
        });
    }
    empty.len()
}

/// States of all levels, coarsest first: a cell is `IN`/`OUT` when all its finest descendants
/// are, `OCCUPIED` otherwise (it must be split).
fn pyramid<const D: usize>(grid: &Grid<D>, finest: Vec<u8>) -> Vec<Vec<u8>> {
    let mut levels = vec![finest];
    for level in (0..grid.max_level).rev() {
        let dims = grid.dims(level);
        let fine_dims = grid.dims(level + 1);
        let fine = levels.last().expect("finest level present");
        let mut coarse = vec![OUT; dims.iter().product::<i64>() as usize];
        for_each_coord(&dims, |coord| {
            let key = CellKey { level, coord };
            let mut all = None;
            let mut mixed = false;
            for child in key.children() {
                let s = fine[linear(&child.coord, &fine_dims)];
                mixed |= s == OCCUPIED || all.is_some_and(|a| a != s);
                all = Some(s);
            }
            coarse[linear(&coord, &dims)] = if mixed { OCCUPIED } else { all.unwrap_or(OUT) };
        });
        levels.push(coarse);
    }
    levels.reverse();
    levels
}

#[inline]
fn linear<const D: usize>(c: &[i64; D], dims: &[i64; D]) -> usize {
    let mut i = 0i64;
    for a in (0..D).rev() {
        i = i * dims[a] + c[a];
    }
    i as usize
}

fn for_each_coord<const D: usize>(dims: &[i64; D], mut f: impl FnMut([i64; D])) {
    if dims.iter().any(|&n| n <= 0) {
        return;
    }
    let mut c = [0i64; D];
    loop {
        f(c);
        let mut a = 0;
        loop {
            c[a] += 1;
            if c[a] < dims[a] {
                break;
            }
            c[a] = 0;
            a += 1;
            if a == D {
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let (complex, info) = build(&pts, &[], &params).unwrap();
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
        let (_, info) = build(&pts, &[], &params).unwrap();
        assert_eq!(info.interior_cells, 0);
    }

    #[test]
    fn rejects_bad_input() {
        assert!(build::<3>(&[], &[], &BuildParams::default()).is_err());
        let nan = [Vect::<3>::new(f64::NAN, 0.0, 0.0)];
        assert!(build(&nan, &[], &BuildParams::default()).is_err());
        let tiny = BuildParams {
            cell_size: Some(1e-9),
            ..Default::default()
        };
        let pts = [Vect::<3>::zeros(), Vect::<3>::new(1.0, 1.0, 1.0)];
        assert!(matches!(
            build(&pts, &[], &tiny),
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
        let (complex, _) = build(&pts, &[], &params).unwrap();
        assert_eq!(complex.components().1, 2);
    }
}
