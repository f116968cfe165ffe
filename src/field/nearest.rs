//! Exact nearest cell centers for the blend, through tiles.
//!
//! A generic kd-tree k-nearest query measured only 1.1–1.4 million queries/s on 2 cores here,
//! which would make the blend, not the file I/O, the bottleneck of streaming. The cells lie
//! on an octree, so space is cut into a regular grid of **tiles** (edge: the smallest cell's,
//! doubled until the grid has at most [`MAX_TILES`] tiles), and each tile gets, once, the short
//! list of the only centers that can be among the [`NEAR`] nearest of any point inside it. A
//! query is then a scan of that list, in cache, with no allocation.
//!
//! **Filling a tile** takes no kd-tree query where the field is small enough for a
//! [`LeafMap`]: a grid of voxels of the smallest cells' size, each holding the cell that covers
//! it. The cells of the voxels around the tile give the bound below, and the cells of the
//! voxels within the bound of the tile the list. Filling the 16.6k tiles that the 480k-vertex
//! dragon meets at 5.5k cells took about 2.6 µs of CPU per tile with two kd-tree queries (a
//! third of the blend's time) and about half of that from the map; the blend went from 0.058 to
//! 0.052 s (first pass, best of 10). Where the map would exceed [`MAX_VOXELS`], or a tile's
//! region [`MAX_VISITED`] voxels, the kd-tree fills the tile.
//!
//! **Why the list is exact.** For a tile box `B` let `D = max_j dmax(c_j, B)` over any `NEAR`
//! centers (the kd-tree's `NEAR` nearest to the tile's middle, or the `NEAR` of smallest `dmax`
//! among the map's cells around the tile), with `dmax(c, B)` the distance from `c` to the
//! farthest corner of `B`. Every point `x ∈ B` has those `NEAR` centers within `D`, so a center
//! among its `NEAR` nearest is within `D` of `x`, hence `dmin(c, B) ≤ D`: it lies within `D + r`
//! of the middle (`r` the half diagonal; the kd-tree's radius query) and in a voxel of `B` grown
//! by `D` (the map's). The list holds exactly the centers found that pass the `dmin` test (with
//! a relative slack of `1e-9` against rounding).
//!
//! **Order.** Neighbors are ordered by squared distance, ties by the lower cell index, whatever
//! order candidates are offered in; lists are sorted by distance from the tile's middle, so the
//! first candidates offered are mostly the ones kept and the rest are turned away by one
//! well-predicted comparison. The brute-force scan [`Nearest::brute_force`] uses the same rule
//! and arithmetic, so the two give identical neighbors (a test checks this). Tiles are filled lazily, each by a
//! deterministic function of its box, so any chunking and thread count gives the same bits.
//! Points outside the tiled box (only when a field is applied to other data) use the kd-tree.

use std::num::NonZero;
use std::sync::OnceLock;

use kiddo::{ImmutableKdTree, SquaredEuclidean};

use crate::error::{Error, Result};
use crate::rigid::Vect;

/// Nearest centers found per point: the blend uses 4 and the continuous blend's weights fall to
/// zero at the 5th.
pub const NEAR: usize = 5;

/// Upper bound on the number of tiles (each costs 24 bytes until it is filled).
const MAX_TILES: usize = 1 << 21;

/// The nearest centers of one point, nearest first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Neighbors {
    /// Cell indices.
    pub cells: [u32; NEAR],
    /// Squared distances.
    pub d2: [f64; NEAR],
    /// How many were found (`NEAR` unless the field has fewer cells).
    pub n: usize,
}

impl Neighbors {
    const EMPTY: Self = Self {
        cells: [0; NEAR],
        d2: [f64::INFINITY; NEAR],
        n: 0,
    };

    /// Keeps the center `cell` at squared distance `d2` if it is among the nearest so far, in
    /// the order of `(d2, cell)`: whatever order centers are offered in, the result is the same.
    #[inline(always)]
    fn offer(&mut self, d2: f64, cell: u32) {
        offer(&mut self.d2, &mut self.cells, &mut self.n, d2, cell);
    }
}

/// Keeps `(d2, cell)` among the `N` smallest so far of the sorted `d2s`/`cells` (`n` of them
/// filled), in the order of `(d2, cell)`.
#[inline(always)]
fn offer<const N: usize>(
    d2s: &mut [f64; N],
    cells: &mut [u32; N],
    n: &mut usize,
    d2: f64,
    cell: u32,
) {
    let before = |d2s: &[f64; N], cells: &[u32; N], j: usize| {
        d2 < d2s[j] || (d2 == d2s[j] && cell < cells[j])
    };
    if *n == N && !before(d2s, cells, N - 1) {
        return;
    }
    let mut j = (*n).min(N - 1);
    *n = (*n + 1).min(N);
    while j > 0 && before(d2s, cells, j - 1) {
        d2s[j] = d2s[j - 1];
        cells[j] = cells[j - 1];
        j -= 1;
    }
    d2s[j] = d2;
    cells[j] = cell;
}

/// What [`Nearest::find_reusing`] keeps from one call to the next: the last point searched in
/// full, its [`NEAR`] nearest centers, and the squared radius around it within which they stay
/// provably the nearest.
#[derive(Debug, Clone, Copy)]
pub struct Anchor<const D: usize> {
    at: [f64; D],
    cells: [u32; NEAR],
    reach2: f64,
}

impl<const D: usize> Anchor<D> {
    /// Whether [`Nearest::find_reusing`] would answer at the local point `x` from this anchor.
    pub fn covers(&self, x: &[f64; D]) -> bool {
        dist2(x, &self.at) < self.reach2
    }
}

impl<const D: usize> Default for Anchor<D> {
    fn default() -> Self {
        Self {
            at: [0.0; D],
            cells: [0; NEAR],
            reach2: -1.0,
        }
    }
}

/// One candidate center of a tile: its position and index.
#[derive(Debug, Clone, Copy)]
struct Candidate<const D: usize> {
    at: [f64; D],
    cell: u32,
}

/// The candidates of a tile and the bound they were chosen by: every center left out is
/// farther than `bound` from every point of the tile.
struct TileList<const D: usize> {
    candidates: Box<[Candidate<D>]>,
    bound: f64,
}

/// The nearest-center index over a field's rest centers.
pub struct Nearest<const D: usize> {
    centers: Vec<[f64; D]>,
    tree: ImmutableKdTree<f64, D>,
    lower: [f64; D],
    size: f64,
    dims: [usize; D],
    tiles: Vec<OnceLock<TileList<D>>>,
    /// The cells over a grid of the smallest cells, when it is small enough.
    leaves: Option<LeafMap<D>>,
}

/// Upper bound on the voxels of a [`LeafMap`] (4 bytes each).
const MAX_VOXELS: usize = 1 << 22;

/// Upper bound on the voxels a tile's fill visits before it asks the kd-tree instead.
const MAX_VISITED: usize = 4096;

/// The cell covering each voxel of a grid of the smallest cells' size over the cells' boxes
/// (`u32::MAX`: none). The cells are the leaves of an octree, aligned with this grid, so every
/// center within a box of space lies in a voxel of its cell inside that box.
struct LeafMap<const D: usize> {
    edge: f64,
    dims: [usize; D],
    cells: Vec<u32>,
    /// Whether a cell covers more than one voxel (and may be met more than once).
    coarse: Vec<bool>,
}

impl<const D: usize> LeafMap<D> {
    /// The map of the cells (`centers`, `halves`) over the box from `lower` to `upper`, or
    /// `None` when it would have more than [`MAX_VOXELS`] voxels or the cells are not aligned
    /// with it.
    fn new(centers: &[[f64; D]], halves: &[f64], lower: [f64; D], upper: [f64; D]) -> Option<Self> {
        let edge = 2.0 * halves.iter().cloned().fold(f64::MAX, f64::min);
        let dims: [usize; D] =
            std::array::from_fn(|a| (((upper[a] - lower[a]) / edge).round() as usize).max(1));
        if dims.iter().map(|&n| n as f64).product::<f64>() > MAX_VOXELS as f64 {
            return None;
        }
        let mut cells = vec![u32::MAX; dims.iter().product()];
        let coarse = halves.iter().map(|&h| 2.0 * h > 1.5 * edge).collect();
        for (i, (c, h)) in centers.iter().zip(halves).enumerate() {
            let mut from = [0usize; D];
            let mut to = [0usize; D];
            for a in 0..D {
                let f = (c[a] - h - lower[a]) / edge;
                let t = (c[a] + h - lower[a]) / edge;
                if (f - f.round()).abs() > 1e-6 || (t - t.round()).abs() > 1e-6 {
                    return None;
                }
                from[a] = f.round() as usize;
                to[a] = (t.round() as usize).min(dims[a]);
            }
            for_each_voxel(&dims, from, to, |v| cells[v] = i as u32);
        }
        Some(Self {
            edge,
            dims,
            cells,
            coarse,
        })
    }
}

/// The squared distance from `c` to the farthest corner of the box from `lo` to `hi`.
#[inline]
fn far2<const D: usize>(c: &[f64; D], lo: &[f64; D], hi: &[f64; D]) -> f64 {
    (0..D)
        .map(|a| {
            let d = (c[a] - lo[a]).abs().max((c[a] - hi[a]).abs());
            d * d
        })
        .sum()
}

/// The squared distance from `c` to the box from `lo` to `hi` (zero inside).
#[inline]
fn near2<const D: usize>(c: &[f64; D], lo: &[f64; D], hi: &[f64; D]) -> f64 {
    (0..D)
        .map(|a| {
            let d = (lo[a] - c[a]).max(c[a] - hi[a]).max(0.0);
            d * d
        })
        .sum()
}

/// Calls `f` with the index of every voxel from `from` to `to` (exclusive) of a grid of `dims`,
/// the first axis fastest.
#[inline]
fn for_each_voxel<const D: usize>(
    dims: &[usize; D],
    from: [usize; D],
    to: [usize; D],
    mut f: impl FnMut(usize),
) {
    if (0..D).any(|a| from[a] >= to[a]) {
        return;
    }
    let mut at = from;
    loop {
        let mut index = 0;
        for a in (1..D).rev() {
            index = (index + at[a]) * dims[a - 1];
        }
        for i in from[0]..to[0] {
            f(index + i);
        }
        let mut a = 1;
        loop {
            if a == D {
                return;
            }
            at[a] += 1;
            if at[a] < to[a] {
                break;
            }
            at[a] = from[a];
            a += 1;
        }
    }
}

#[inline(always)]
fn dist2<const D: usize>(x: &[f64; D], c: &[f64; D]) -> f64 {
    let mut s = 0.0;
    for a in 0..D {
        let d = x[a] - c[a];
        s += d * d;
    }
    s
}

impl<const D: usize> Nearest<D> {
    /// The index over `centers` of cells with half edges `halves`; tiles cover the union of the
    /// cells' boxes.
    pub fn new(centers: &[Vect<D>], halves: &[f64]) -> Result<Self> {
        if centers.is_empty() {
            return Err(Error::solver("the field has no cells"));
        }
        let centers: Vec<[f64; D]> = centers.iter().map(|c| (*c).into()).collect();
        let tree = ImmutableKdTree::new_from_slice(&centers)
            .map_err(|e| Error::solver(format!("kd-tree over cell centers: {e:?}")))?;
        let mut lower = [f64::MAX; D];
        let mut upper = [f64::MIN; D];
        for (c, h) in centers.iter().zip(halves) {
            for a in 0..D {
                lower[a] = lower[a].min(c[a] - h);
                upper[a] = upper[a].max(c[a] + h);
            }
        }
        let smallest = halves.iter().cloned().fold(f64::MAX, f64::min);
        let mut size = smallest;
        let count = |size: f64| -> [usize; D] {
            std::array::from_fn(|a| (((upper[a] - lower[a]) / size).ceil() as usize).max(1))
        };
        let mut dims = count(size);
        while dims.iter().map(|&n| n as f64).product::<f64>() > MAX_TILES as f64 {
            size *= 2.0;
            dims = count(size);
        }
        let tiles = (0..dims.iter().product())
            .map(|_| OnceLock::new())
            .collect();
        let leaves = LeafMap::new(&centers, halves, lower, upper);
        Ok(Self {
            centers,
            tree,
            lower,
            size,
            dims,
            tiles,
            leaves,
        })
    }

    /// The [`NEAR`] centers nearest to the local point `x` (fewer if the field has fewer);
    /// none for a point with a non-finite coordinate.
    #[inline]
    pub fn find(&self, x: &[f64; D]) -> Neighbors {
        let Some(t) = self.tile_of(x) else {
            return self.outside(x);
        };
        let (d2, cells, n) = self.scan::<NEAR>(x, self.list(t));
        Neighbors { cells, d2, n }
    }

    /// The filled candidate list of tile `t`.
    #[inline(always)]
    ///
    /// A thread that finds the tile empty fills it itself rather than wait for another thread
    /// that is filling it: the lists are the same, the first stored is kept, and no thread
    /// sleeps (waiting measured as a tenth of the first pass's time).
    fn list(&self, t: usize) -> &TileList<D> {
        let tile = &self.tiles[t];
        if let Some(list) = tile.get() {
            return list;
        }
        let _ = tile.set(self.fill(t));
        tile.get().expect("just set")
    }

    /// The `N` candidates of `list` nearest to `x`, in the order of `(d2, cell)`, and how many
    /// there are.
    #[inline(always)]
    fn scan<const N: usize>(
        &self,
        x: &[f64; D],
        list: &TileList<D>,
    ) -> ([f64; N], [u32; N], usize) {
        let (mut d2s, mut cells, mut n) = ([f64::INFINITY; N], [0u32; N], 0);
        for c in list.candidates.iter() {
            offer(&mut d2s, &mut cells, &mut n, dist2(x, &c.at), c.cell);
        }
        (d2s, cells, n)
    }

    /// [`Self::find`] for points that come in a coherent order (scans): when `x` is within
    /// `anchor`'s reach, its nearest centers are the anchor's, and only their distances are
    /// computed; otherwise `x` is searched in full and becomes the anchor. The result is
    /// [`Self::find`]'s, bit for bit.
    ///
    /// **Why.** Let `a` be the anchor, `d5` the distance of its 5th nearest center and `L` a
    /// lower bound on its distance to every other center: the 6th nearest of its tile's list, or
    /// the tile's bound for the centers left out of the list. For `x` with `δ = |x − a|`, every
    /// kept center is within `d5 + δ` of `x` and every other beyond `L − δ`, so while
    /// `δ < (L − d5) / 2` the kept centers are strictly the nearest (the reach is shortened by
    /// `1e-9 L` against rounding), and sorting them by `(d2, cell)` gives what the full scan
    /// gives.
    #[inline]
    pub fn find_reusing(&self, x: &[f64; D], anchor: &mut Anchor<D>) -> Neighbors {
        if anchor.covers(x) {
            let mut nb = Neighbors::EMPTY;
            for &c in &anchor.cells {
                nb.offer(dist2(x, &self.centers[c as usize]), c);
            }
            return nb;
        }
        anchor.reach2 = -1.0;
        let Some(t) = self.tile_of(x) else {
            return self.outside(x);
        };
        let list = self.list(t);
        let (d2s, cells, n) = self.scan::<{ NEAR + 1 }>(x, list);
        let mut nb = Neighbors::EMPTY;
        nb.n = n.min(NEAR);
        nb.d2.copy_from_slice(&d2s[..NEAR]);
        nb.cells.copy_from_slice(&cells[..NEAR]);
        if n >= NEAR {
            let d5 = d2s[NEAR - 1].sqrt();
            let beyond = d2s[NEAR].sqrt().min(list.bound);
            let reach = 0.5 * (beyond - d5) - 1e-9 * beyond;
            if reach > 0.0 {
                *anchor = Anchor {
                    at: *x,
                    cells: nb.cells,
                    reach2: reach * reach,
                };
            }
        }
        nb
    }

    /// The reference: every center scanned, with the arithmetic of [`Self::find`].
    pub fn brute_force(&self, x: &[f64; D]) -> Neighbors {
        let mut nb = Neighbors::EMPTY;
        for (i, c) in self.centers.iter().enumerate() {
            nb.offer(dist2(x, c), i as u32);
        }
        nb
    }

    /// Tiles in the grid and the tiles filled so far.
    pub fn tile_counts(&self) -> (usize, usize) {
        let filled = self.tiles.iter().filter(|t| t.get().is_some()).count();
        (self.tiles.len(), filled)
    }

    /// Mean candidate-list length over the filled tiles.
    pub fn mean_candidates(&self) -> f64 {
        let (sum, n) = self
            .tiles
            .iter()
            .filter_map(|t| t.get())
            .fold((0usize, 0usize), |(s, n), l| {
                (s + l.candidates.len(), n + 1)
            });
        sum as f64 / n.max(1) as f64
    }

    #[inline(always)]
    fn tile_of(&self, x: &[f64; D]) -> Option<usize> {
        let mut t = 0;
        for a in (0..D).rev() {
            let f = (x[a] - self.lower[a]) / self.size;
            // Also false for NaN.
            if !(f >= 0.0 && f < self.dims[a] as f64) {
                return None;
            }
            t = t * self.dims[a] + f as usize;
        }
        Some(t)
    }

    /// The lower and upper corners of tile `t`.
    fn tile_box(&self, mut t: usize) -> ([f64; D], [f64; D]) {
        let mut lo = [0.0; D];
        let mut hi = [0.0; D];
        for a in 0..D {
            let i = t % self.dims[a];
            t /= self.dims[a];
            lo[a] = self.lower[a] + i as f64 * self.size;
            hi[a] = self.lower[a] + (i + 1) as f64 * self.size;
        }
        (lo, hi)
    }

    /// The candidate list of tile `t` (see the module docs).
    fn fill(&self, t: usize) -> TileList<D> {
        let (lo, hi) = self.tile_box(t);
        let mid: [f64; D] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
        let half_diagonal = 0.5 * self.size * (D as f64).sqrt();
        let far = |c: &[f64; D]| -> f64 { far2(c, &lo, &hi).sqrt() };
        let near = |c: &[f64; D]| -> f64 { near2(c, &lo, &hi).sqrt() };
        let from_leaves = self
            .leaves
            .as_ref()
            .and_then(|map| self.gather_by_leaves(map, &lo, &hi));
        let (bound, cells) = match from_leaves {
            Some(found) => found,
            None => self.gather_by_tree(&mid, half_diagonal, &far, &near),
        };
        // Nearest to the middle first: the first few offered are then mostly the kept ones, and
        // later candidates are rejected by one predictable comparison.
        let mut cells: Vec<(f64, u32)> = cells
            .into_iter()
            .map(|i| (dist2(&mid, &self.centers[i as usize]), i))
            .collect();
        cells.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let candidates = cells
            .into_iter()
            .map(|(_, cell)| cell)
            .map(|cell| Candidate {
                at: self.centers[cell as usize],
                cell,
            })
            .collect();
        TileList { candidates, bound }
    }

    /// A tile's bound and candidates (see the module docs) from the kd-tree: its [`NEAR`]
    /// centers nearest to the middle give the bound, and a radius query the candidates.
    fn gather_by_tree(
        &self,
        mid: &[f64; D],
        half_diagonal: f64,
        far: &impl Fn(&[f64; D]) -> f64,
        near: &impl Fn(&[f64; D]) -> f64,
    ) -> (f64, Vec<u32>) {
        let k = NonZero::new(NEAR.min(self.centers.len())).expect("centers are not empty");
        let bound = self
            .tree
            .query(mid)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .iter()
            .map(|r| far(&self.centers[r.item as usize]))
            .fold(0.0, f64::max)
            * (1.0 + 1e-9);
        let reach = (bound + half_diagonal) * (1.0 + 1e-9);
        let cells = self
            .tree
            .query(mid)
            .within::<SquaredEuclidean<f64>>(reach * reach)
            .unsorted()
            .execute()
            .iter()
            .map(|r| r.item)
            .filter(|&i| near(&self.centers[i as usize]) <= bound)
            .collect();
        (bound, cells)
    }

    /// A tile's bound and candidates from the leaf map, or `None` where that
    /// would visit more than [`MAX_VISITED`] voxels. The cells of the voxels around the tile,
    /// grown a voxel at a time until they hold [`NEAR`] centers, give the bound (any `NEAR`
    /// centers bound every point's `NEAR`-th distance by their farthest corner distances);
    /// every center within the bound of the tile lies in a voxel of the tile's box grown by the
    /// bound (and a millionth of a voxel against rounding), so the cells of those voxels are the
    /// candidates.
    fn gather_by_leaves(
        &self,
        map: &LeafMap<D>,
        lo: &[f64; D],
        hi: &[f64; D],
    ) -> Option<(f64, Vec<u32>)> {
        let range = |grow: f64| -> Option<([usize; D], [usize; D])> {
            let mut from = [0usize; D];
            let mut to = [0usize; D];
            let mut count = 1.0;
            for a in 0..D {
                let f = ((lo[a] - grow - self.lower[a]) / map.edge - 1e-6).floor();
                let t = ((hi[a] + grow - self.lower[a]) / map.edge + 1e-6).floor() + 1.0;
                from[a] = f.clamp(0.0, map.dims[a] as f64) as usize;
                to[a] = t.clamp(0.0, map.dims[a] as f64) as usize;
                count *= (to[a] - from[a]) as f64;
            }
            (count <= MAX_VISITED as f64).then_some((from, to))
        };
        let mut found = Vec::with_capacity(512);
        // The cells of the voxels from `from` to `to`, each once: a cell of one voxel is met
        // once; the few coarser ones are checked against those already found.
        let mut seen_coarse: Vec<u32> = Vec::with_capacity(64);
        let mut gather = |from, to, found: &mut Vec<u32>| {
            found.clear();
            seen_coarse.clear();
            let mut last = u32::MAX;
            for_each_voxel(&map.dims, from, to, |v| {
                let cell = map.cells[v];
                if cell == last || cell == u32::MAX {
                    return;
                }
                last = cell;
                if map.coarse[cell as usize] {
                    if seen_coarse.contains(&cell) {
                        return;
                    }
                    seen_coarse.push(cell);
                }
                found.push(cell);
            });
        };
        // The tile's voxels, grown a voxel at a time until they hold NEAR cells.
        let mut grow = 0.0;
        let bound = loop {
            let (from, to) = range(grow)?;
            gather(from, to, &mut found);
            if found.len() >= NEAR {
                // The NEAR smallest farthest-corner distances.
                let mut smallest = [f64::INFINITY; NEAR];
                for &i in &found {
                    let d = far2(&self.centers[i as usize], lo, hi);
                    if d < smallest[NEAR - 1] {
                        let mut j = NEAR - 1;
                        while j > 0 && d < smallest[j - 1] {
                            smallest[j] = smallest[j - 1];
                            j -= 1;
                        }
                        smallest[j] = d;
                    }
                }
                break smallest[NEAR - 1].sqrt() * (1.0 + 1e-9);
            }
            if (0..D).all(|a| from[a] == 0 && to[a] == map.dims[a]) {
                // The whole field holds fewer than NEAR cells: every one is a candidate.
                return Some((f64::INFINITY, found));
            }
            grow += map.edge;
        };
        let (from, to) = range(bound)?;
        gather(from, to, &mut found);
        let bound2 = bound * bound;
        found.retain(|&i| near2(&self.centers[i as usize], lo, hi) <= bound2);
        Some((bound, found))
    }

    /// A point outside the tiles: the kd-tree's nearest, then every center as near as the
    /// farthest of them (so that ties are all seen), offered with the arithmetic of
    /// [`Self::find`].
    fn outside(&self, x: &[f64; D]) -> Neighbors {
        let mut nb = Neighbors::EMPTY;
        if x.iter().any(|v| !v.is_finite()) {
            return nb;
        }
        let k = NonZero::new(NEAR.min(self.centers.len())).expect("centers are not empty");
        let reach = self
            .tree
            .query(x)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .iter()
            .map(|r| dist2(x, &self.centers[r.item as usize]))
            .fold(0.0, f64::max);
        for r in self
            .tree
            .query(x)
            .within::<SquaredEuclidean<f64>>(reach * (1.0 + 1e-9))
            .execute()
        {
            let i = r.item;
            nb.offer(dist2(x, &self.centers[i as usize]), i);
        }
        nb
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kd-tree's fill, used where the leaf map is not (cells not on one grid, or too many
    /// voxels), finds the brute-force neighbors too; and the leaf map is built where the cells
    /// are aligned.
    #[test]
    fn tiles_filled_by_the_kd_tree_equal_brute_force() {
        let mut next = super::super::test_numbers(17);
        // A lattice of unit cells (aligned: the map is built) and the same lattice jittered.
        let lattice: Vec<Vect<3>> = (0..6 * 5 * 4)
            .map(|i| Vect::<3>::new((i % 6) as f64, (i / 6 % 5) as f64, (i / 30) as f64))
            .collect();
        let jittered: Vec<Vect<3>> = lattice
            .iter()
            .map(|c| c + Vect::<3>::new(next(), next(), next()) * 0.2)
            .collect();
        let halves = vec![0.5; lattice.len()];
        let aligned = Nearest::new(&lattice, &halves).unwrap();
        assert!(aligned.leaves.is_some());
        let mut forced = Nearest::new(&lattice, &halves).unwrap();
        forced.leaves = None;
        let unaligned = Nearest::new(&jittered, &halves).unwrap();
        assert!(unaligned.leaves.is_none());
        for nearest in [&aligned, &forced, &unaligned] {
            for _ in 0..5000 {
                let x = [3.0 + 3.5 * next(), 2.5 + 3.0 * next(), 2.0 + 2.5 * next()];
                assert_eq!(nearest.find(&x), nearest.brute_force(&x), "at {x:?}");
            }
            let (_, filled) = nearest.tile_counts();
            assert!(filled > 100, "{filled}");
        }
    }
}
