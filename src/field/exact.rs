//! Exact constraints and the field's domain (docs/ARCHITECTURE.md, the invariants): the layer
//! every transfer is applied through.
//!
//! **Constraints are exact, and the map stays smooth.** The blend and the RBF interpolate the
//! cells' motions between their centers, so a sample inside a fixed region but near its border
//! (or anywhere inside it, with the RBF) moved a little, and a handle's samples missed its
//! transform. [`FieldMap`] adds, for every region `r` of cells that follow one prescribed map
//! `A_r` (the fixed cells and the cells kept at rest follow the identity; each handle its
//! transform; a pinned cell and the cells of a loose part carried along, their own rigid
//! motion), a weight `w_r` that is 1 on the region's cells and falls to 0 over a band of two of
//! the smallest cells around them:
//!
//! ```text
//! x' = F(x) + Σ_r w_r(x) (A_r(x) − F(x))          F: the transfer (blend or RBF)
//! w_r = 1 − σ(s⁻¹(v_r)),   v_r = 1 − (K * 1_{R_r ⊕ e})(x)
//! ```
//!
//! **Where the weight comes from.** `R_r ⊕ e` is the region grown by one voxel of the smallest
//! cells' edge `e`: its cells and the voxels around them. `K` is the kernel `Π_a s'(·)` of
//! half-width `e`, with `s(t) = 10t³ − 15t⁴ + 6t⁵`, so `K * 1_{R ⊕ e}` is C² (the kernel is C¹ and vanishes
//! at its ends), is 1 wherever the kernel's support lies in the grown region — on every cell of
//! the region — and 0 two voxels away. At a flat border it is `1 − s(d / 2e)` at a distance
//! `d`, and elsewhere (corners, steps of the cells' staircase) it rounds that off smoothly: the
//! region's cells and the voxels around them are disjoint boxes, so the convolution is a sum of
//! products of the kernel's one-dimensional masses over the `3^D` voxels around the sample's.
//! `Bands` keeps the voxels around each region; which of a sample's neighbors lie in a grown
//! region is found when a sample meets the voxel (and kept for the next samples of a run), so
//! the work grows with the samples near the regions, not with the regions' surface.
//!
//! **Why the profile `σ`.** Near a region the field leaves the region's map at the rate `c` it
//! keeps beyond (the cells turn steadily from the fixed ones on), and it leads the map already
//! where the region's cells end: the transfer interpolates between the cells' centers, and the
//! first free cell has moved one step `c·e` from the last prescribed one, so at the border the
//! transfer is half that step ahead. So `A − F ≈ c (d + d₀)` at a distance `d`, with
//! `d₀ ≈ e / 2`, and a weight `1 − σ(d / L)` gives the map the rate `c ((u + a) σ(u))'` with
//! `a = d₀ / L`. Its average over the band is `1 + a` (the band must catch the head start up);
//! the smoothstep `σ = s` peaks at 2.1 times the field's rate — a collar — while the `σ` used
//! here makes `((u + a) σ)'` rise as `s` to its least possible peak over the first tenth of the
//! band, hold it and ease back to 1 over the last: 1.33 for the band of two cells
//! (`a = 1/4`). `σ` is C² with `σ(0) = 0`, `σ(1) = 1` and zero slopes at both ends. A wider band
//! lowers the peak (1.19 for four cells, `a = 1/8`: on a bust with its neck fixed and its head
//! turned 30°, the largest edge strain 1.44 against 1.51) at the cost of `5^D` neighbors a
//! voxel and more space blended.
//! Measured on a tube twisted 30° between a fixed and a turned end (`tools/python/border_strain.py`;
//! BENCHMARKS.md): the largest edge strain 1.47 with the smoothstep over one cell (and the sum
//! of the cells' bumps capped at 1, which held the band exact for half its width), 1.29 with
//! this band, and 1.20 for the transfer alone (which is not exact).
//!
//! **Regions with a border.** A region of space of the spec (a box, sphere, half-space, polygon
//! or a combination of them: [`Shape`], [`Prescribed::shapes`]) is measured from itself, not
//! from its cells: its cells are those whose centers it holds (the cells that straddle its
//! border are free, so the field turns from where the region ends, not up to a cell past it),
//! a sample inside it takes `A_r(x)` whatever cell holds it, and outside
//! `w_r = 1 − σ(d_r(x) / L)` with `d_r` the shape's signed distance (1-Lipschitz, so a voxel
//! farther than its half-diagonal beyond the band is left alone, and one that far inside is
//! exact whole) over a band `L` of four of the smallest cells
//! ([`SHAPE_BAND`](super::band::SHAPE_BAND)): measured from the shape it needs no masks, so a
//! wide band costs nothing more. At the border the transfer leads the map by the motion over
//! the distance from the last prescribed center, between none and one cell; `σ` is made for a
//! whole cell's head start, so the map's rate peaks between 1.26 and 1.33 times the field's
//! (over two cells it would reach 1.61 where the border falls just short of a cell's center).
//! On a bust with its neck's lowest fifth fixed and everything above 0.55 of its height turned
//! 30°, the largest edge strain fell from 1.62 to 1.44, and the 99.9th percentile from 1.397
//! to 1.355 (BENCHMARKS.md). The selections of samples (indices, classes, what a camera sees),
//! pins and carried parts keep the cells' weight above: their cells are held whole.
//!
//! Inside a cell held whole the sample goes to its map `A_r(x)` itself, and inside a region with
//! a border (a cell held whole first) to the region's: a fixed sample keeps its coordinates bit
//! for bit, a handle sample follows the handle's transform to rounding. Where the bands of
//! regions meet, each region's weight counts as `w_r Π_{q≠r} (1 − w_q)` and the field's as
//! `Π_q (1 − w_q)`, over their sum: a region's map has the whole weight at its own border
//! whatever the others' bands (so the map is continuous there), and where one band alone
//! reaches its weight is as above. Regions that touch blend into each other only through the
//! field between them. Soft targets are points, not regions, and are left to the transfer.
//!
//! The band is where the transfer's misfit to a region's map is paid: where the transfer
//! compresses space and misses the map by a good part of a cell, the band can fold space over.
//! The fold-over check of `deform` reports them.
//!
//! **Heights a field does not move.** A field of 2D control points alone
//! ([`Field::heights_kept`]) gives every sample its own last coordinate back, bit for bit, and
//! its normals turn with the map's horizontal part (the Jacobian whose last row is the height's
//! own): the points say nothing of heights, and the cells' slight turns about horizontal axes
//! under a sideways pull would move them.
//!
//! **A field knows its domain.** A sample counts as inside when a cell holds it or it lies
//! within the margin of the cells: one voxel (of the size of the largest cell on the complex's
//! outer boundary, aligned with the cells) around each voxel that such a cell meets. So every
//! sample within that cell size of a cell (in each axis) is inside, and none farther than twice
//! that. What happens beyond is [`Outside`]: refused (the default of `apply`), kept unchanged,
//! or extended by the transfer as it is. Either way they are counted ([`FieldMap::outside`]).
//!
//! **Lookups.** The cells are the leaves of an octree, which is rebuilt from their centers and
//! sizes alone (the field file stores nothing more, and `deform` and `apply` then locate samples
//! with the same arithmetic). A sample's voxel of the smallest cells' size gives its leaf through
//! one hash lookup per level present, the list of the prescribed cells whose band meets the voxel
//! (only voxels outside prescribed cells have one), and its margin voxel; consecutive samples of
//! a scan mostly share a voxel, whose answer is kept.

use std::sync::Mutex;

use super::band::{
    Bands, GROW, Masks, NEIGHBORS, SHAPE_BAND, SIDE, bands, combine, fall, neighbor, profile,
    smooth,
};
use super::domain::Margin;
use super::leaves::Leaves;
use super::{Deformer, Field, Shape, Warp, normal_like};
use crate::error::{Error, Result};
use crate::rigid::{Affine, Dim, Mat, Rigid, Vect};
use crate::solve::trend::TrendMap;

/// A cell that follows no prescribed map ([`Prescribed::cells`]).
pub const UNPRESCRIBED: u32 = u32::MAX;

/// The maps that regions of cells follow exactly.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Prescribed<const D: usize> {
    /// For each cell, the index of its map in `maps`, or [`UNPRESCRIBED`]; empty when no cell has one.
    pub cells: Vec<u32>,
    /// The distinct maps, in the local frame.
    pub maps: Vec<Affine<D>>,
    /// The maps that hold a region of space to its own border ([`Shape`], input coordinates):
    /// the exact layer measures their band from the shape, and their cells (those whose
    /// centers lie in it) are not prescribed whole.
    pub shapes: Vec<(u32, Shape<D>)>,
}

impl<const D: usize> Prescribed<D> {
    /// The map of cell `c`, if it has one.
    pub fn of(&self, c: usize) -> Option<&Affine<D>> {
        match self.cells.get(c) {
            Some(&m) if m != UNPRESCRIBED => Some(&self.maps[m as usize]),
            _ => None,
        }
    }

    /// Gives cell `c` the map `map`, sharing the index of an equal map: equal to a billionth of
    /// its linear part's entries and of its translation. Parts carried along by one carrier
    /// have the same motion, solved to rounding; sharing one index makes them one region, whose
    /// band blends them as one whatever the last bits (and so whatever the order of the input's
    /// records).
    pub fn set(&mut self, c: usize, n: usize, map: Affine<D>) {
        if self.cells.is_empty() {
            self.cells = vec![UNPRESCRIBED; n];
        }
        let near = |m: &Affine<D>| {
            (m.linear - map.linear).amax() <= 1e-9
                && (m.translation - map.translation).amax() <= 1e-9 * (1.0 + map.translation.amax())
        };
        let shaped = |k: &usize| self.shapes.iter().any(|(m, _)| *m as usize == *k);
        let k = match (0..self.maps.len()).find(|&k| !shaped(&k) && near(&self.maps[k])) {
            Some(k) => k,
            None => {
                self.maps.push(map);
                self.maps.len() - 1
            }
        };
        self.cells[c] = k as u32;
    }

    /// A map of its own for the region `shape` ([`Prescribed::shapes`]), for
    /// [`Prescribed::put`].
    pub fn shaped(&mut self, map: Affine<D>, shape: Shape<D>) -> u32 {
        self.maps.push(map);
        let k = self.maps.len() as u32 - 1;
        self.shapes.push((k, shape));
        k
    }

    /// Gives cell `c` (of `n`) map `k`.
    pub fn put(&mut self, c: usize, n: usize, k: u32) {
        if self.cells.is_empty() {
            self.cells = vec![UNPRESCRIBED; n];
        }
        self.cells[c] = k;
    }

    /// Whether map `k` holds a shape.
    pub fn is_shaped(&self, k: u32) -> bool {
        self.shapes.iter().any(|(m, _)| *m == k)
    }
}

/// What happens to samples beyond the field's margin.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Outside {
    /// They are counted and the run fails ([`Error::Outside`]); nothing is written.
    #[default]
    Refuse,
    /// They keep their coordinates, bit for bit (the shape tears at the margin).
    Keep,
    /// The transfer is evaluated there as anywhere (the RBF's linear part grows with the
    /// distance; the blend follows the nearest cells' motions).
    Extend,
}

/// Samples found beyond the margin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutsideTally<const D: usize> {
    /// How many.
    pub count: u64,
    /// The largest distance of one from the cells' bounding box (0 for samples inside the box
    /// but away from every cell).
    pub farthest: f64,
    /// That sample (local frame).
    pub at: Vect<D>,
}

impl<const D: usize> Default for OutsideTally<D> {
    fn default() -> Self {
        Self {
            count: 0,
            farthest: 0.0,
            at: Vect::<D>::zeros(),
        }
    }
}

impl<const D: usize> OutsideTally<D> {
    fn add(&mut self, x: &Vect<D>, distance: f64) {
        if self.count == 0 || distance > self.farthest {
            self.farthest = distance;
            self.at = *x;
        }
        self.count += 1;
    }

    fn merge(&mut self, other: &Self) {
        if other.count > 0 {
            if self.count == 0 || other.farthest > self.farthest {
                self.farthest = other.farthest;
                self.at = other.at;
            }
            self.count += other.count;
        }
    }
}

/// What a voxel is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Class {
    /// Inside a cell that follows map `k` exactly.
    Exact(u32),
    /// Among the cells, beyond every band.
    Free,
    /// Among the cells or within the margin, within two voxels of a cell held whole or within a
    /// band of a region with a border.
    Band,
    /// Beyond the margin.
    Outside,
}

/// A field's map of space, what [`crate::SavedField::deformer`] gives: its transfer (`inner`),
/// exact in the regions the spec prescribes, within a guarded domain; see the module docs.
pub struct FieldMap<const D: usize> {
    inner: Deformer<D>,
    origin: Vect<D>,
    halves: Vec<f64>,
    prescribed: Prescribed<D>,
    /// The map each cell holds whole (the prescribed cells but those of a shape's map).
    whole_cells: Vec<u32>,
    /// The shapes, with their maps (world coordinates).
    shapes: Vec<(u32, Shape<D>)>,
    /// The inverse transposes of the maps' linear parts (normals).
    normal_maps: Vec<Mat<D>>,
    /// Which maps are the identity.
    identity: Vec<bool>,
    leaves: Leaves<D>,
    bands: Bands<D>,
    /// The voxels within the margin of the cells.
    margin: Margin<D>,
    /// The cells' bounding box (local).
    bounds: (Vect<D>, Vect<D>),
    outside: Outside,
    tally: Mutex<OutsideTally<D>>,
    /// For a window of a field's cells ([`FieldMap::in_window`]): the box (local) its
    /// samples must lie in, and how many did not.
    window: Option<(Vect<D>, Vect<D>)>,
    beyond_window: std::sync::atomic::AtomicUsize,
    /// Every sample keeps its last coordinate ([`Field::heights_kept`]).
    heights_kept: bool,
    /// The trend applied to the transfer's values ([`Field::trend`]; `None`: the identity).
    trend: Option<TrendMap<D>>,
}

/// What a window of a field's cells needs from the whole field to treat samples as the whole
/// field does ([`FieldMap::in_window`]; saved in field files).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame<const D: usize> {
    /// The voxel grid of the leaves: voxel 0's lower corner (local) and the voxels' edge.
    pub lower: Vect<D>,
    /// The smallest cells' edge.
    pub edge: f64,
    /// The margin voxels are `2^margin_shift` voxels.
    pub margin_shift: u32,
    /// The cells' bounding box (local).
    pub bounds: (Vect<D>, Vect<D>),
    /// The largest cell's half-size.
    pub largest_half: f64,
}

impl<const D: usize> Frame<D> {
    /// How far past a box of samples the cells a window needs may lie: a sample's leaf, its
    /// margin voxels and the bands around it are all within this distance (in each axis).
    pub fn reach(&self) -> f64 {
        3.0 * self.edge * f64::from(1u32 << self.margin_shift.min(31))
            + 2.0 * self.largest_half
            + (2 * GROW + 1) as f64 * self.edge
    }
}

impl<const D: usize> FieldMap<D>
where
    Dim<D>: Rigid<D>,
{
    /// The transfer inside, for keeping what it built (the RBF's factorized coefficients)
    /// once the exact layer is no longer needed.
    pub fn into_inner(self) -> Deformer<D> {
        self.inner
    }

    /// `inner` for `field`, with `field.prescribed` exact and samples beyond the margin
    /// handled by `outside`. Fails when the field's cells are not the leaves of an octree (a
    /// damaged field file).
    pub fn new(field: &Field<D>, inner: Deformer<D>, outside: Outside) -> Result<Self> {
        let leaves = Leaves::new(&field.centers, &field.halves).map_err(Error::solver)?;
        let mut lo = Vect::<D>::repeat(f64::INFINITY);
        let mut hi = Vect::<D>::repeat(f64::NEG_INFINITY);
        for (c, h) in field.centers.iter().zip(&field.halves) {
            lo = lo.inf(&c.add_scalar(-h));
            hi = hi.sup(&c.add_scalar(*h));
        }
        Self::assemble(field, inner, outside, leaves, None, (lo, hi), None)
    }

    /// `inner` for the cells of a window of a field, as [`FieldMap::new`] for the whole
    /// field would map every sample in the box `window` (local) when the window holds every
    /// cell within [`Frame::reach`] of that box: the leaves on the whole field's grid, its
    /// margin's voxel size and its bounds from `frame`. Samples outside `window` are counted
    /// ([`FieldMap::beyond_window`]); their results are not the whole field's.
    pub fn in_window(
        field: &Field<D>,
        inner: Deformer<D>,
        outside: Outside,
        frame: &Frame<D>,
        window: (Vect<D>, Vect<D>),
    ) -> Result<Self> {
        let leaves = Leaves::in_frame(&field.centers, &field.halves, frame.lower, frame.edge)
            .map_err(Error::solver)?;
        Self::assemble(
            field,
            inner,
            outside,
            leaves,
            Some(frame.margin_shift),
            frame.bounds,
            Some(window),
        )
    }

    fn assemble(
        field: &Field<D>,
        inner: Deformer<D>,
        outside: Outside,
        leaves: Leaves<D>,
        margin_shift: Option<u32>,
        bounds: (Vect<D>, Vect<D>),
        window: Option<(Vect<D>, Vect<D>)>,
    ) -> Result<Self> {
        let prescribed = field.prescribed.clone();
        if !prescribed.cells.is_empty() && prescribed.cells.len() != field.centers.len() {
            return Err(Error::solver("the prescribed cells do not match the cells"));
        }
        let normal_maps = prescribed
            .maps
            .iter()
            .map(|m| m.linear.try_inverse().map_or(m.linear, |i| i.transpose()))
            .collect();
        let identity = prescribed
            .maps
            .iter()
            .map(|m| *m == Affine::identity())
            .collect();
        let whole_cells: Vec<u32> = prescribed
            .cells
            .iter()
            .map(|&m| match m != UNPRESCRIBED && prescribed.is_shaped(m) {
                true => UNPRESCRIBED,
                false => m,
            })
            .collect();
        let bands = bands(&leaves, &whole_cells);
        let shapes = prescribed.shapes.clone();
        let margin = Margin::new(&leaves, margin_shift);
        Ok(Self {
            inner,
            origin: field.origin,
            halves: field.halves.clone(),
            prescribed,
            whole_cells,
            shapes,
            normal_maps,
            identity,
            leaves,
            bands,
            margin,
            bounds,
            outside,
            tally: Mutex::new(OutsideTally::default()),
            window,
            beyond_window: Default::default(),
            heights_kept: field.heights_kept,
            trend: (!field.trend.is_identity()).then(|| field.trend.clone()),
        })
    }

    /// What a window of this field's cells needs from it ([`FieldMap::in_window`]).
    pub fn frame(&self) -> Frame<D> {
        Frame {
            lower: self.leaves.lower,
            edge: self.leaves.edge,
            margin_shift: self.margin.shift,
            bounds: self.bounds,
            largest_half: self.halves.iter().cloned().fold(0.0, f64::max),
        }
    }

    /// Samples met outside the window's box ([`FieldMap::in_window`]; 0 for a whole
    /// field): when any were, the results are not the whole field's.
    pub fn beyond_window(&self) -> usize {
        self.beyond_window
            .load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Counts the samples of `points` (world) outside the window's box.
    fn check_window(&self, origin: &Vect<D>, points: &[Vect<D>]) {
        let Some((lo, hi)) = &self.window else {
            return;
        };
        let beyond = points
            .iter()
            .filter(|p| {
                let x = *p - origin;
                !(0..D).all(|a| x[a] >= lo[a] && x[a] <= hi[a])
            })
            .count();
        if beyond > 0 {
            self.beyond_window
                .fetch_add(beyond, std::sync::atomic::Ordering::Relaxed);
        }
    }

    /// The margin: samples within this distance of a cell (in each axis) are inside the
    /// field's domain.
    pub fn margin(&self) -> f64 {
        self.leaves.edge * f64::from(1u32 << self.margin.shift.min(31))
    }

    /// World position of the field's local frame.
    pub fn origin(&self) -> Vect<D> {
        self.origin
    }

    /// The transfer without the constraints.
    pub fn inner(&self) -> &Deformer<D> {
        &self.inner
    }

    /// The samples beyond the margin met since the last [`FieldMap::reset_outside`], by
    /// [`Warp::warp_run`] and [`Warp::warp_with_normal`] (the calls that produce output).
    pub fn outside(&self) -> OutsideTally<D> {
        *self.tally.lock().expect("not poisoned")
    }

    /// Forgets the samples counted beyond the margin.
    pub fn reset_outside(&self) {
        *self.tally.lock().expect("not poisoned") = OutsideTally::default();
    }

    /// What happens beyond the margin.
    pub fn outside_policy(&self) -> Outside {
        self.outside
    }

    /// The distance of the local point `x` from the cells' bounding box.
    fn distance(&self, x: &Vect<D>) -> f64 {
        let (lo, hi) = &self.bounds;
        Vect::<D>::from_fn(|a, _| (lo[a] - x[a]).max(x[a] - hi[a]).max(0.0)).norm()
    }

    fn classify(&self, v: &[i64; D]) -> Class {
        let band = || {
            if (0..NEIGHBORS[D] as usize).any(|k| self.bands.shell.contains_key(&neighbor(v, k))) {
                Class::Band
            } else {
                Class::Free
            }
        };
        let among = match self.leaves.leaf(v) {
            Some(c) => match self.whole_cells.get(c) {
                Some(&m) if m != UNPRESCRIBED => return Class::Exact(m),
                _ => true,
            },
            None => self.margin.holds(v),
        };
        if !among {
            return Class::Outside;
        }
        if !self.shapes.is_empty() {
            // The voxel's center (world) and half-diagonal: a shape whose signed distance
            // there is below minus that holds the whole voxel; within the band and that, the
            // band reaches it.
            let edge = self.leaves.edge;
            let center =
                Vect::<D>::from_fn(|a, _| self.leaves.lower[a] + (v[a] as f64 + 0.5) * edge)
                    + self.origin;
            let reach = 0.5 * edge * (D as f64).sqrt() * (1.0 + 1e-9);
            let mut near = false;
            for (m, shape) in &self.shapes {
                let d = shape.signed_distance(&center);
                if d < -reach {
                    return Class::Exact(*m);
                }
                near |= d < self.shape_band() + reach;
            }
            if near {
                return Class::Band;
            }
        }
        band()
    }

    /// The band of a region with a border: [`SHAPE_BAND`](super::band::SHAPE_BAND) of the
    /// smallest cells.
    fn shape_band(&self) -> f64 {
        SHAPE_BAND * self.leaves.edge
    }

    /// The class of the local point `x`; non-finite points are outside.
    #[inline]
    pub(super) fn class_of(&self, x: &Vect<D>) -> Class {
        if x.iter().all(|v| v.is_finite()) {
            self.classify(&self.leaves.voxel(x))
        } else {
            Class::Outside
        }
    }

    /// The maps whose grown regions meet the neighbors of voxel `v` (outside every prescribed
    /// cell), with the neighbors in each.
    fn masks(&self, v: &[i64; D]) -> Masks {
        let mut out = [(0u32, 0u32); 4];
        let mut n = 0;
        let mut add = |m: u32, k: usize| match out[..n].iter_mut().find(|e| e.0 == m) {
            Some(e) => e.1 |= 1 << k,
            None if n < 4 => {
                out[n] = (m, 1 << k);
                n += 1;
            }
            None => {}
        };
        for k in 0..NEIGHBORS[D] as usize {
            let u = neighbor(v, k);
            let held = self.leaves.leaf(&u).and_then(|c| {
                let m = self.whole_cells.get(c).copied().unwrap_or(UNPRESCRIBED);
                (m != UNPRESCRIBED).then_some(m)
            });
            if let Some(m) = held {
                add(m, k);
            }
            if let Some(&(start, len)) = self.bands.shell.get(&u) {
                for &m in &self.bands.maps[start as usize..(start + len) as usize] {
                    add(m, k);
                }
            }
        }
        (out, n)
    }

    /// The regions' weights at `x` (local; `world` in the input's coordinates, as the spec's
    /// regions are) from its masks (see the module docs): up to eight regions with a positive
    /// weight, combined where their bands meet.
    fn weights(&self, x: &Vect<D>, world: &Vect<D>, masks: &Masks) -> ([(u32, f64); 8], usize) {
        let v = self.leaves.voxel(x);
        // The kernel's mass over the voxel below, this one and the one above, per axis.
        let mass: [[f64; SIDE]; D] = std::array::from_fn(|a| {
            let t =
                ((x[a] - self.leaves.lower[a]) / self.leaves.edge - v[a] as f64).clamp(0.0, 1.0);
            let (below, above) = (smooth(0.5 * (1.0 - t)), smooth(0.5 * t));
            [below, 1.0 - below - above, above]
        });
        let full = (1u32 << NEIGHBORS[D]) - 1;
        let mut sums = [(0u32, 0.0f64); 8];
        let mut n = 0;
        if !self.shapes.is_empty() {
            for (m, shape) in &self.shapes {
                if shape.contains(world) {
                    sums[0] = (*m, 1.0);
                    return (sums, 1);
                }
                let u = shape.signed_distance(world) / self.shape_band();
                if u < 1.0 && n < 8 - masks.1 {
                    sums[n] = (*m, 1.0 - profile(u.max(0.0), 1.0 / SHAPE_BAND));
                    n += 1;
                }
            }
        }
        for &(m, mask) in &masks.0[..masks.1] {
            let w = if mask == full {
                1.0
            } else {
                let mut w = 0.0;
                let mut bits = mask;
                while bits != 0 {
                    let mut k = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let mut product = 1.0;
                    for axis in &mass {
                        product *= axis[k % SIDE];
                        k /= SIDE;
                    }
                    w += product;
                }
                1.0 - fall(1.0 - w.min(1.0))
            };
            if w > 0.0 {
                sums[n] = (m, w);
                n += 1;
            }
        }
        let n = combine(&mut sums, n);
        (sums, n)
    }

    /// The one map that has the whole weight at `x`, if one has.
    fn whole(&self, w: &[(u32, f64)]) -> Option<u32> {
        match w {
            [(m, 1.0)] => Some(*m),
            _ => None,
        }
    }

    /// `F(x) + Σ w_r (A_r(x) − F(x))` for the band weights at `x`, given `F(x)`.
    fn banded(&self, x: &Vect<D>, world: &Vect<D>, masks: &Masks, f: Vect<D>) -> Vect<D> {
        let (w, n) = self.weights(x, world, masks);
        if let Some(m) = self.whole(&w[..n]) {
            return self.prescribed.maps[m as usize].apply(x);
        }
        let mut out = f;
        for &(m, wr) in &w[..n] {
            out += (self.prescribed.maps[m as usize].apply(x) - f) * wr;
        }
        out
    }

    /// The normal under map `m` (the identity returns it as it came).
    fn exact_normal(&self, m: u32, n: &Vect<D>) -> Vect<D> {
        if self.identity[m as usize] {
            *n
        } else {
            normal_like(self.normal_maps[m as usize] * n, n)
        }
    }

    /// The normal in a band: the transfer's and the maps' blended by the weights.
    fn banded_normal(
        &self,
        x: &Vect<D>,
        world: &Vect<D>,
        masks: &Masks,
        f: Vect<D>,
        n: &Vect<D>,
    ) -> Vect<D> {
        let (w, k) = self.weights(x, world, masks);
        if let Some(m) = self.whole(&w[..k]) {
            return self.exact_normal(m, n);
        }
        let mut out = f;
        for &(m, wr) in &w[..k] {
            out += (self.exact_normal(m, n) - f) * wr;
        }
        normal_like(out, n)
    }

    /// The transfer's value at `x`, after the trend.
    fn field(&self, x: &Vect<D>) -> Vect<D> {
        let y = self.inner.warp(x);
        match &self.trend {
            Some(t) => t.apply(&y),
            None => y,
        }
    }

    /// A normal `m` at the transfer's value `y`, turned by the trend there.
    fn trend_normal(t: &TrendMap<D>, y: &Vect<D>, m: Vect<D>, n: &Vect<D>) -> Vect<D> {
        match t.jacobian(y).try_inverse() {
            Some(inverse) => normal_like(inverse.transpose() * m, n),
            None => m,
        }
    }

    /// The transfer's normal at `x`, after the trend.
    fn field_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        match &self.trend {
            Some(t) => {
                let (y, m) = self.inner.warp_with_normal(x, n);
                Self::trend_normal(t, &y, m, n)
            }
            None => self.inner.warp_normal(x, n),
        }
    }

    /// [`Self::field`] and [`Self::field_normal`] together.
    fn field_with_normal(&self, x: &Vect<D>, n: &Vect<D>) -> (Vect<D>, Vect<D>) {
        let (y, m) = self.inner.warp_with_normal(x, n);
        match &self.trend {
            Some(t) => (t.apply(&y), Self::trend_normal(t, &y, m, n)),
            None => (y, m),
        }
    }

    /// The transfer's Jacobian at `x`, after the trend.
    fn field_jacobian(&self, x: &Vect<D>, h: f64) -> nalgebra::SMatrix<f64, D, D> {
        let j = self.inner.jacobian(x, h);
        match &self.trend {
            Some(t) => t.jacobian(&self.inner.warp(x)) * j,
            None => j,
        }
    }

    /// The transfer's run of samples (world coordinates), after the trend. Under a trend the
    /// transfer runs on the local points and the trend takes its local values, as for a single
    /// sample ([`Self::field_with_normal`]): a world value taken back to the local frame would
    /// not round-trip bit for bit.
    fn field_run(&self, origin: &Vect<D>, points: &[Vect<D>], out: &mut [Vect<D>]) {
        match &self.trend {
            None => self.inner.warp_run(origin, points, out),
            Some(t) => {
                let local: Vec<Vect<D>> = points.iter().map(|p| p - origin).collect();
                self.inner.warp_run(&Vect::<D>::zeros(), &local, out);
                for o in out.iter_mut() {
                    *o = t.apply(o) + origin;
                }
            }
        }
    }

    /// A field that keeps heights gives each sample of a run its own last coordinate back,
    /// bit for bit (not through the local frame's round trip).
    fn keep_heights(&self, points: &[Vect<D>], out: &mut [Vect<D>]) {
        if self.heights_kept {
            for (o, p) in out.iter_mut().zip(points) {
                o[D - 1] = p[D - 1];
            }
        }
    }

    /// The normal under a field that keeps heights: the transpose of the inverse of its
    /// Jacobian, whose last row is the height's own.
    fn level_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        let j = self.jacobian(x, 1e-3 * self.leaves.edge);
        match j.try_inverse() {
            Some(inverse) => normal_like(inverse.transpose() * n, n),
            None => *n,
        }
    }

    /// [`Warp::warp`] at the local point `x` whose input coordinates are `world`.
    fn warp_at(&self, x: &Vect<D>, world: &Vect<D>) -> Vect<D> {
        let mut y = match self.class_of(x) {
            Class::Exact(m) if self.identity[m as usize] => *x,
            Class::Exact(m) => self.prescribed.maps[m as usize].apply(x),
            Class::Free => self.field(x),
            Class::Band => self.banded(x, world, &self.masks(&self.leaves.voxel(x)), self.field(x)),
            Class::Outside => match self.outside {
                Outside::Extend => self.field(x),
                _ => *x,
            },
        };
        if self.heights_kept {
            y[D - 1] = x[D - 1];
        }
        y
    }

    /// [`Warp::warp_with_normal`] at the local point `x` whose input coordinates are `world`
    /// (a run passes its sample itself, so a band's weights read the same numbers as in
    /// [`Warp::warp_run`]).
    fn warp_with_normal_at(&self, x: &Vect<D>, world: &Vect<D>, n: &Vect<D>) -> (Vect<D>, Vect<D>) {
        if self.heights_kept {
            return (self.warp_at(x, world), self.level_normal(x, n));
        }
        let class = self.class_of(x);
        match class {
            Class::Exact(_) => (self.warp_at(x, world), self.warp_normal(x, n)),
            Class::Free => self.field_with_normal(x, n),
            Class::Band => {
                let masks = self.masks(&self.leaves.voxel(x));
                let (f, fnormal) = self.field_with_normal(x, n);
                (
                    self.banded(x, world, &masks, f),
                    self.banded_normal(x, world, &masks, fnormal, n),
                )
            }
            Class::Outside => {
                self.count_outside(x);
                match self.outside {
                    Outside::Extend => self.field_with_normal(x, n),
                    _ => (*x, *n),
                }
            }
        }
    }

    fn count_outside(&self, x: &Vect<D>) {
        let d = self.distance(x);
        self.tally.lock().expect("not poisoned").add(x, d);
    }
}

impl<const D: usize> Warp<D> for FieldMap<D>
where
    Dim<D>: Rigid<D>,
{
    fn warp(&self, x: &Vect<D>) -> Vect<D> {
        self.warp_at(x, &(x + self.origin))
    }

    fn warp_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        if self.heights_kept {
            return self.level_normal(x, n);
        }
        match self.class_of(x) {
            Class::Exact(m) => self.exact_normal(m, n),
            Class::Free => self.field_normal(x, n),
            Class::Band => {
                let masks = self.masks(&self.leaves.voxel(x));
                self.banded_normal(x, &(x + self.origin), &masks, self.field_normal(x, n), n)
            }
            Class::Outside => match self.outside {
                Outside::Extend => self.field_normal(x, n),
                _ => *n,
            },
        }
    }

    fn warp_with_normal(&self, x: &Vect<D>, n: &Vect<D>) -> (Vect<D>, Vect<D>) {
        self.warp_with_normal_at(x, &(x + self.origin), n)
    }

    fn jacobian(&self, x: &Vect<D>, h: f64) -> nalgebra::SMatrix<f64, D, D> {
        let mut j = match self.class_of(x) {
            Class::Exact(m) => self.prescribed.maps[m as usize].linear,
            Class::Free => self.field_jacobian(x, h),
            _ => super::central_jacobian(self, x, h),
        };
        if self.heights_kept {
            for a in 0..D {
                j[(D - 1, a)] = if a == D - 1 { 1.0 } else { 0.0 };
            }
        }
        j
    }

    /// Samples of cells that the identity holds keep their position and normal bits.
    fn warp_run_with_normals(
        &self,
        origin: &Vect<D>,
        points: &[Vect<D>],
        normals: &[Vect<D>],
        out: &mut [Vect<D>],
        out_normals: &mut [Vect<D>],
    ) {
        self.check_window(origin, points);
        for (((o, on), p), n) in out.iter_mut().zip(out_normals).zip(points).zip(normals) {
            let x = p - origin;
            let class = self.class_of(&x);
            let still = match class {
                Class::Exact(m) => self.identity[m as usize],
                Class::Band => {
                    let (w, k) = self.weights(&x, p, &self.masks(&self.leaves.voxel(&x)));
                    self.whole(&w[..k])
                        .is_some_and(|m| self.identity[m as usize])
                }
                Class::Outside => self.outside != Outside::Extend,
                Class::Free => false,
            };
            if still {
                if class == Class::Outside {
                    self.count_outside(&x);
                }
                (*o, *on) = (*p, *n);
            } else {
                let (y, m) = self.warp_with_normal_at(&x, p, n);
                (*o, *on) = (y + origin, m);
            }
        }
        self.keep_heights(points, out);
    }

    /// Runs of samples the transfer moves alone go to its own `warp_run`; samples of prescribed
    /// cells take their map (the identity returns the sample as it came, bit for bit).
    fn warp_run(&self, origin: &Vect<D>, points: &[Vect<D>], out: &mut [Vect<D>]) {
        self.check_window(origin, points);
        let mut tally = OutsideTally::default();
        let mut last: Option<([i64; D], Class)> = None;
        // The last band voxel's masks.
        let mut near: Option<([i64; D], Masks)> = None;
        let mut run = 0;
        let extend = self.outside == Outside::Extend;
        for i in 0..points.len() {
            let p = &points[i];
            let x = p - origin;
            let class = if x.iter().all(|v| v.is_finite()) {
                let v = self.leaves.voxel(&x);
                match last {
                    Some((lv, c)) if lv == v => c,
                    _ => {
                        let c = self.classify(&v);
                        last = Some((v, c));
                        c
                    }
                }
            } else {
                Class::Outside
            };
            let to_inner = matches!(class, Class::Free) || (extend && class == Class::Outside);
            if to_inner {
                if class == Class::Outside {
                    tally.add(&x, self.distance(&x));
                }
                continue;
            }
            if run < i {
                self.field_run(origin, &points[run..i], &mut out[run..i]);
            }
            run = i + 1;
            out[i] = match class {
                Class::Exact(m) if self.identity[m as usize] => *p,
                Class::Exact(m) => self.prescribed.maps[m as usize].apply(&x) + origin,
                Class::Band => {
                    let v = self.leaves.voxel(&x);
                    let masks = match &near {
                        Some((nv, m)) if *nv == v => *m,
                        _ => {
                            let m = self.masks(&v);
                            near = Some((v, m));
                            m
                        }
                    };
                    let (w, n) = self.weights(&x, p, &masks);
                    match self.whole(&w[..n]) {
                        // A sample the identity has whole keeps its bits.
                        Some(m) if self.identity[m as usize] => *p,
                        _ => self.banded(&x, p, &masks, self.field(&x)) + origin,
                    }
                }
                _ => {
                    tally.add(&x, self.distance(&x));
                    *p
                }
            };
        }
        if run < points.len() {
            self.field_run(origin, &points[run..], &mut out[run..]);
        }
        if tally.count > 0 {
            self.tally.lock().expect("not poisoned").merge(&tally);
        }
        self.keep_heights(points, out);
    }
}
