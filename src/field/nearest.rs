//! Exact nearest cell centers for the blend, through tiles.
//!
//! A generic kd-tree k-nearest query measured only 1.1–1.4 million queries/s on 2 cores here
//! (issue 5), which made the blend, not the file I/O, the bottleneck of streaming. The cells lie
//! on an octree, so space is cut into a regular grid of **tiles** (edge: the smallest cell's,
//! doubled until the grid has at most [`MAX_TILES`] tiles), and each tile gets, once, the short
//! list of the only centers that can be among the [`NEAR`] nearest of any point inside it. A
//! query is then a scan of that list, in cache, with no allocation.
//!
//! **Why the list is exact.** For a tile box `B` let `D = max_j dmax(c_j, B)` over the `NEAR`
//! centers nearest to the tile's middle, with `dmax(c, B)` the distance from `c` to the farthest
//! corner of `B`. Every point `x ∈ B` has those `NEAR` centers within `D`, so a center among its
//! `NEAR` nearest is within `D` of `x`, hence `dmin(c, B) ≤ D` and `|c − mid| ≤ D + r` (`r` the
//! half diagonal). The list holds exactly the centers found by that radius query that pass the
//! `dmin` test (with a relative slack of `1e-9` against rounding).
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
            return Err(Error::Solver("the field has no cells".into()));
        }
        let centers: Vec<[f64; D]> = centers.iter().map(|c| (*c).into()).collect();
        let tree = ImmutableKdTree::new_from_slice(&centers)
            .map_err(|e| Error::Solver(format!("kd-tree over cell centers: {e:?}")))?;
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
        Ok(Self {
            centers,
            tree,
            lower,
            size,
            dims,
            tiles,
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
    fn list(&self, t: usize) -> &TileList<D> {
        self.tiles[t].get_or_init(|| self.fill(t))
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
        let far = |c: &[f64; D]| -> f64 {
            (0..D)
                .map(|a| {
                    let d = (c[a] - lo[a]).abs().max((c[a] - hi[a]).abs());
                    d * d
                })
                .sum::<f64>()
                .sqrt()
        };
        let near = |c: &[f64; D]| -> f64 {
            (0..D)
                .map(|a| {
                    let d = (lo[a] - c[a]).max(c[a] - hi[a]).max(0.0);
                    d * d
                })
                .sum::<f64>()
                .sqrt()
        };
        let k = NonZero::new(NEAR.min(self.centers.len())).expect("centers are not empty");
        let bound = self
            .tree
            .query(&mid)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .iter()
            .map(|r| far(&self.centers[r.item as usize]))
            .fold(0.0, f64::max)
            * (1.0 + 1e-9);
        let reach = (bound + half_diagonal) * (1.0 + 1e-9);
        let cells: Vec<u32> = self
            .tree
            .query(&mid)
            .within::<SquaredEuclidean<f64>>(reach * reach)
            .unsorted()
            .execute()
            .iter()
            .map(|r| r.item)
            .filter(|&i| near(&self.centers[i as usize]) <= bound)
            .collect();
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
