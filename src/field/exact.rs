//! Exact constraints and the field's domain (docs/ARCHITECTURE.md, the invariants): the layer
//! every transfer is applied through.
//!
//! **Constraints are exact, and the map stays smooth.** The blend and the RBF interpolate the
//! cells' motions between their centers, so a sample inside a fixed region but near its border
//! (or anywhere inside it, with the RBF) moved a little, and a handle's samples missed its
//! transform. [`Constrained`] adds, for every region `r` of cells that follow one prescribed map
//! `A_r` (the fixed cells and the cells kept at rest follow the identity; each handle its
//! transform; the cells of a loose part carried along, their carrier's rigid motion), a C²
//! indicator `w_r`:
//!
//! ```text
//! x' = F(x) + Σ_r w_r(x) (A_r(x) − F(x))          F: the transfer (blend or RBF)
//! w_r = s(min(1, Σ_{i ∈ r} ψ_i)),   ψ_i(x) = Π_a b((|x_a − c_i,a| − h_i) / δ_i)
//! b(t) = 1 − s(t) on [0, 1], 1 below, 0 above;   s(t) = 10t³ − 15t⁴ + 6t⁵
//! ```
//!
//! `ψ_i` is 1 on cell `i`'s box and falls to 0 within `δ_i` of it; `s` has zero first and
//! second derivatives at 0 and 1, so `w_r` is C² and the map is C² wherever `F` is. Inside a
//! prescribed cell `w_r = 1` and the sample goes to `A_r(x)` itself: a fixed sample keeps its
//! coordinates bit for bit, a handle sample follows the handle's transform to rounding. The
//! band `δ_i` is the smallest cell's edge, and at most half the gap (along the axis that
//! separates them most) to a cell of another region, so the bands of two regions never overlap
//! and a sample is exact for at most one. Regions that touch get no band between them (`δ = 0`):
//! the user asked for two motions there, and the map follows each up to the shared face.
//! Pins and soft targets are points, not regions, and are left to the transfer.
//!
//! The band is where the transfer's misfit to a region's map is paid: the Jacobian there gains
//! `(A − F) ∇wᵀ`, with `|∇w|` up to `1.875/δ`. Where the transfer already compresses space and
//! misses the map by a good part of a cell, that can fold space over. Measured on the decimated
//! dragon (11,429 vertices, 5 m cells) with its base fixed and its head turned 40° and lifted:
//! the RBF alone folds at 25 vertices, with the band of one cell at 44 (the new ones have
//! determinants of 0.01–0.8 under the RBF alone), with half a cell at 37, with two cells at 54,
//! and with bands widened to four times the misfit beside each cell (up to four cells) at 75:
//! a wider band takes in more of the space the transfer compresses, so one cell was kept. The
//! fold-over check of `deform` reports them; on the demo's bend and on twists up to 720° there
//! are none.
//!
//! **A field knows its domain.** A sample counts as inside when a cell holds it or it lies
//! within the margin of the cells: one voxel (of the size of the largest cell on the complex's
//! outer boundary, aligned with the cells) around each voxel that such a cell meets. So every
//! sample within that cell size of a cell (in each axis) is inside, and none farther than twice
//! that. What happens beyond is [`Outside`]: refused (the default of `apply`), kept unchanged,
//! or extended by the transfer as it is. Either way they are counted ([`Constrained::outside`]).
//!
//! **Lookups.** The cells are the leaves of an octree, which is rebuilt from their centers and
//! sizes alone (the field file stores nothing more, and `deform` and `apply` then locate samples
//! with the same arithmetic). A sample's voxel of the smallest cells' size gives its leaf through
//! one hash lookup per level present, the list of the prescribed cells whose band meets the voxel
//! (only voxels outside prescribed cells have one), and its margin voxel; consecutive samples of
//! a scan mostly share a voxel, whose answer is kept.

use std::sync::Mutex;

use rustc_hash::{FxHashMap, FxHashSet};

use super::leaves::{Leaves, for_each_shell};
use super::{Deformer, Field, Warp, normal_like};
use crate::error::{Error, Result};
use crate::rigid::{Affine, Dim, Mat, Rigid, Vect};

/// A cell that follows no prescribed map ([`Prescribed::cells`]).
pub const FREE: u32 = u32::MAX;

/// The maps that regions of cells follow exactly.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Prescribed<const D: usize> {
    /// For each cell, the index of its map in `maps`, or [`FREE`]; empty when no cell has one.
    pub cells: Vec<u32>,
    /// The distinct maps, in the local frame.
    pub maps: Vec<Affine<D>>,
}

impl<const D: usize> Prescribed<D> {
    /// The map of cell `c`, if it has one.
    pub fn of(&self, c: usize) -> Option<&Affine<D>> {
        match self.cells.get(c) {
            Some(&m) if m != FREE => Some(&self.maps[m as usize]),
            _ => None,
        }
    }

    /// Gives cell `c` the map `map`, sharing the index of an equal map.
    pub fn set(&mut self, c: usize, n: usize, map: Affine<D>) {
        if self.cells.is_empty() {
            self.cells = vec![FREE; n];
        }
        let k = match self.maps.iter().position(|m| *m == map) {
            Some(k) => k,
            None => {
                self.maps.push(map);
                self.maps.len() - 1
            }
        };
        self.cells[c] = k as u32;
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
enum Class {
    /// Inside a cell that follows map `k` exactly.
    Exact(u32),
    /// Among the cells, beyond every band.
    Free,
    /// Among the cells or within the margin, in the bands of the prescribed cells
    /// `band[start..start + len]`.
    Band(u32, u32),
    /// Beyond the margin.
    Outside,
}

/// Bands of prescribed cells: for each voxel that one meets outside every prescribed cell, the
/// cells, with each cell's band width.
struct Bands<const D: usize> {
    voxels: FxHashMap<[i64; D], (u32, u32)>,
    cells: Vec<u32>,
    width: Vec<f64>,
}

/// The transfer `inner` with exact constraints and a guarded domain; see the module docs.
pub struct Constrained<const D: usize> {
    inner: Deformer<D>,
    origin: Vect<D>,
    centers: Vec<Vect<D>>,
    halves: Vec<f64>,
    prescribed: Prescribed<D>,
    /// The inverse transposes of the maps' linear parts (normals).
    normal_maps: Vec<Mat<D>>,
    /// Which maps are the identity.
    identity: Vec<bool>,
    leaves: Leaves<D>,
    bands: Bands<D>,
    /// Margin voxels (of `2^margin_shift` voxels) within the margin of the cells.
    margin_voxels: FxHashSet<[i64; D]>,
    margin_shift: u32,
    /// The cells' bounding box (local).
    bounds: (Vect<D>, Vect<D>),
    outside: Outside,
    tally: Mutex<OutsideTally<D>>,
    /// For a window of a field's cells ([`Constrained::in_window`]): the box (local) its
    /// samples must lie in, and how many did not.
    window: Option<(Vect<D>, Vect<D>)>,
    beyond_window: std::sync::atomic::AtomicUsize,
}

/// What a window of a field's cells needs from the whole field to treat samples as the whole
/// field does ([`Constrained::in_window`]; saved in field files).
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
            + 2.0 * self.edge
    }
}

/// `10t³ − 15t⁴ + 6t⁵`: 0 at 0, 1 at 1, with zero first and second derivatives at both.
#[inline]
fn smooth(t: f64) -> f64 {
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

impl<const D: usize> Constrained<D>
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
        let leaves = Leaves::new(&field.centers, &field.halves).map_err(Error::Solver)?;
        let mut lo = Vect::<D>::repeat(f64::INFINITY);
        let mut hi = Vect::<D>::repeat(f64::NEG_INFINITY);
        for (c, h) in field.centers.iter().zip(&field.halves) {
            lo = lo.inf(&c.add_scalar(-h));
            hi = hi.sup(&c.add_scalar(*h));
        }
        Self::assemble(field, inner, outside, leaves, None, (lo, hi), None)
    }

    /// `inner` for the cells of a window of a field, as [`Constrained::new`] for the whole
    /// field would map every sample in the box `window` (local) when the window holds every
    /// cell within [`Frame::reach`] of that box: the leaves on the whole field's grid, its
    /// margin's voxel size and its bounds from `frame`. Samples outside `window` are counted
    /// ([`Constrained::beyond_window`]); their results are not the whole field's.
    pub fn in_window(
        field: &Field<D>,
        inner: Deformer<D>,
        outside: Outside,
        frame: &Frame<D>,
        window: (Vect<D>, Vect<D>),
    ) -> Result<Self> {
        let leaves = Leaves::in_frame(&field.centers, &field.halves, frame.lower, frame.edge)
            .map_err(Error::Solver)?;
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
            return Err(Error::Solver(
                "the prescribed cells do not match the cells".into(),
            ));
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
        let bands = bands(&leaves, field, &prescribed);
        let (margin_voxels, margin_shift) = margin(&leaves, margin_shift);
        Ok(Self {
            inner,
            origin: field.origin,
            centers: field.centers.clone(),
            halves: field.halves.clone(),
            prescribed,
            normal_maps,
            identity,
            leaves,
            bands,
            margin_voxels,
            margin_shift,
            bounds,
            outside,
            tally: Mutex::new(OutsideTally::default()),
            window,
            beyond_window: Default::default(),
        })
    }

    /// What a window of this field's cells needs from it ([`Constrained::in_window`]).
    pub fn frame(&self) -> Frame<D> {
        Frame {
            lower: self.leaves.lower,
            edge: self.leaves.edge,
            margin_shift: self.margin_shift,
            bounds: self.bounds,
            largest_half: self.halves.iter().cloned().fold(0.0, f64::max),
        }
    }

    /// Samples met outside the window's box ([`Constrained::in_window`]; 0 for a whole
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
        self.leaves.edge * f64::from(1u32 << self.margin_shift.min(31))
    }

    /// World position of the field's local frame.
    pub fn origin(&self) -> Vect<D> {
        self.origin
    }

    /// The transfer without the constraints.
    pub fn inner(&self) -> &Deformer<D> {
        &self.inner
    }

    /// The samples beyond the margin met since the last [`Constrained::reset_outside`], by
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
        let band = || match self.bands.voxels.get(v) {
            Some(&(start, len)) => Class::Band(start, len),
            None => Class::Free,
        };
        match self.leaves.leaf(v) {
            Some(c) => match self.prescribed.cells.get(c) {
                Some(&m) if m != FREE => Class::Exact(m),
                _ => band(),
            },
            None => {
                let m = v.map(|c| c >> self.margin_shift);
                if self.margin_voxels.contains(&m) {
                    band()
                } else {
                    Class::Outside
                }
            }
        }
    }

    /// The class of the local point `x`; non-finite points are outside.
    #[inline]
    fn class_of(&self, x: &Vect<D>) -> Class {
        if x.iter().all(|v| v.is_finite()) {
            self.classify(&self.leaves.voxel(x))
        } else {
            Class::Outside
        }
    }

    /// The regions' weights at `x` from the band cells `start..start + len`: up to `D + 1`
    /// regions with a positive weight (bands of two regions do not overlap, so one in practice).
    fn weights(&self, x: &Vect<D>, start: u32, len: u32) -> ([(u32, f64); 4], usize) {
        let mut sums = [(0u32, 0.0f64); 4];
        let mut n = 0;
        for &c in &self.bands.cells[start as usize..(start + len) as usize] {
            let c = c as usize;
            let delta = self.bands.width[c];
            let (center, h) = (&self.centers[c], self.halves[c]);
            let mut psi = 1.0;
            for a in 0..D {
                let out = (x[a] - center[a]).abs() - h;
                if out > 0.0 {
                    if out >= delta {
                        psi = 0.0;
                        break;
                    }
                    psi *= 1.0 - smooth(out / delta);
                }
            }
            if psi > 0.0 {
                let m = self.prescribed.cells[c];
                match sums[..n].iter_mut().find(|s| s.0 == m) {
                    Some(s) => s.1 += psi,
                    None if n < 4 => {
                        sums[n] = (m, psi);
                        n += 1;
                    }
                    None => {}
                }
            }
        }
        for s in &mut sums[..n] {
            s.1 = smooth(s.1.min(1.0));
        }
        let total: f64 = sums[..n].iter().map(|s| s.1).sum();
        if total > 1.0 {
            for s in &mut sums[..n] {
                s.1 /= total;
            }
        }
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
    fn banded(&self, x: &Vect<D>, start: u32, len: u32, f: Vect<D>) -> Vect<D> {
        let (w, n) = self.weights(x, start, len);
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
    fn banded_normal(&self, x: &Vect<D>, start: u32, len: u32, f: Vect<D>, n: &Vect<D>) -> Vect<D> {
        let (w, k) = self.weights(x, start, len);
        if let Some(m) = self.whole(&w[..k]) {
            return self.exact_normal(m, n);
        }
        let mut out = f;
        for &(m, wr) in &w[..k] {
            out += (self.exact_normal(m, n) - f) * wr;
        }
        normal_like(out, n)
    }

    fn count_outside(&self, x: &Vect<D>) {
        let d = self.distance(x);
        self.tally.lock().expect("not poisoned").add(x, d);
    }
}

impl<const D: usize> Warp<D> for Constrained<D>
where
    Dim<D>: Rigid<D>,
{
    fn warp(&self, x: &Vect<D>) -> Vect<D> {
        match self.class_of(x) {
            Class::Exact(m) if self.identity[m as usize] => *x,
            Class::Exact(m) => self.prescribed.maps[m as usize].apply(x),
            Class::Free => self.inner.warp(x),
            Class::Band(s, l) => self.banded(x, s, l, self.inner.warp(x)),
            Class::Outside => match self.outside {
                Outside::Extend => self.inner.warp(x),
                _ => *x,
            },
        }
    }

    fn warp_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        match self.class_of(x) {
            Class::Exact(m) => self.exact_normal(m, n),
            Class::Free => self.inner.warp_normal(x, n),
            Class::Band(s, l) => self.banded_normal(x, s, l, self.inner.warp_normal(x, n), n),
            Class::Outside => match self.outside {
                Outside::Extend => self.inner.warp_normal(x, n),
                _ => *n,
            },
        }
    }

    fn warp_with_normal(&self, x: &Vect<D>, n: &Vect<D>) -> (Vect<D>, Vect<D>) {
        let class = self.class_of(x);
        match class {
            Class::Exact(_) => (self.warp(x), self.warp_normal(x, n)),
            Class::Free => self.inner.warp_with_normal(x, n),
            Class::Band(s, l) => {
                let (f, fnormal) = self.inner.warp_with_normal(x, n);
                (
                    self.banded(x, s, l, f),
                    self.banded_normal(x, s, l, fnormal, n),
                )
            }
            Class::Outside => {
                self.count_outside(x);
                match self.outside {
                    Outside::Extend => self.inner.warp_with_normal(x, n),
                    _ => (*x, *n),
                }
            }
        }
    }

    fn jacobian(&self, x: &Vect<D>, h: f64) -> nalgebra::SMatrix<f64, D, D> {
        match self.class_of(x) {
            Class::Exact(m) => self.prescribed.maps[m as usize].linear,
            Class::Free => self.inner.jacobian(x, h),
            _ => super::central_jacobian(self, x, h),
        }
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
                Class::Band(s, l) => {
                    let (w, k) = self.weights(&x, s, l);
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
                let (y, m) = self.warp_with_normal(&x, n);
                (*o, *on) = (y + origin, m);
            }
        }
    }

    /// Runs of samples the transfer moves alone go to its own `warp_run`; samples of prescribed
    /// cells take their map (the identity returns the sample as it came, bit for bit).
    fn warp_run(&self, origin: &Vect<D>, points: &[Vect<D>], out: &mut [Vect<D>]) {
        self.check_window(origin, points);
        let mut tally = OutsideTally::default();
        let mut last: Option<([i64; D], Class)> = None;
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
                self.inner
                    .warp_run(origin, &points[run..i], &mut out[run..i]);
            }
            run = i + 1;
            out[i] = match class {
                Class::Exact(m) if self.identity[m as usize] => *p,
                Class::Exact(m) => self.prescribed.maps[m as usize].apply(&x) + origin,
                Class::Band(s, l) => {
                    let (w, n) = self.weights(&x, s, l);
                    match self.whole(&w[..n]) {
                        // A sample the identity has whole keeps its bits.
                        Some(m) if self.identity[m as usize] => *p,
                        _ => self.banded(&x, s, l, self.inner.warp(&x)) + origin,
                    }
                }
                _ => {
                    tally.add(&x, self.distance(&x));
                    *p
                }
            };
        }
        if run < points.len() {
            self.inner.warp_run(origin, &points[run..], &mut out[run..]);
        }
        if tally.count > 0 {
            self.tally.lock().expect("not poisoned").merge(&tally);
        }
    }
}

/// The bands of the prescribed cells (see the module docs).
fn bands<const D: usize>(
    leaves: &Leaves<D>,
    field: &Field<D>,
    prescribed: &Prescribed<D>,
) -> Bands<D> {
    let n = field.centers.len();
    let mut width = vec![leaves.edge; n];
    let mut entries: Vec<([i64; D], u32)> = Vec::new();
    if prescribed.cells.is_empty() {
        return Bands {
            voxels: FxHashMap::default(),
            cells: Vec::new(),
            width,
        };
    }
    for (c, &m) in prescribed.cells.iter().enumerate() {
        if m == FREE {
            continue;
        }
        let (shift, coord) = leaves.keys[c];
        let lo = coord.map(|k| k << shift);
        let hi = coord.map(|k| ((k + 1) << shift) - 1);
        let from = lo.map(|k| k - 1);
        let to = hi.map(|k| k + 1);
        for_each_shell(from, to, Some((lo, hi)), |v| {
            let outside_prescribed = match leaves.leaf(&v) {
                Some(j) => prescribed.cells[j] == FREE,
                None => true,
            };
            if outside_prescribed {
                entries.push((v, c as u32));
            }
        });
    }
    entries.sort_unstable();
    // Bands of different regions must not overlap: at most half the gap between the cells.
    let mut start = 0;
    while start < entries.len() {
        let mut end = start + 1;
        while end < entries.len() && entries[end].0 == entries[start].0 {
            end += 1;
        }
        let group = &entries[start..end];
        for (k, &(_, i)) in group.iter().enumerate() {
            for &(_, j) in &group[k + 1..] {
                let (i, j) = (i as usize, j as usize);
                if prescribed.cells[i] == prescribed.cells[j] {
                    continue;
                }
                let gap = (0..D)
                    .map(|a| {
                        (field.centers[i][a] - field.centers[j][a]).abs()
                            - field.halves[i]
                            - field.halves[j]
                    })
                    .fold(0.0f64, f64::max);
                width[i] = width[i].min(0.5 * gap);
                width[j] = width[j].min(0.5 * gap);
            }
        }
        start = end;
    }
    let mut voxels = FxHashMap::default();
    let mut cells = Vec::with_capacity(entries.len());
    let mut start = 0;
    while start < entries.len() {
        let v = entries[start].0;
        let first = cells.len() as u32;
        while start < entries.len() && entries[start].0 == v {
            let c = entries[start].1;
            if width[c as usize] > 0.0 {
                cells.push(c);
            }
            start += 1;
        }
        let len = cells.len() as u32 - first;
        if len > 0 {
            voxels.insert(v, (first, len));
        }
    }
    Bands {
        voxels,
        cells,
        width,
    }
}

/// The margin voxels and their size (as a shift of the voxels): the size of the largest cell
/// on the complex's outer boundary (a cell with a face that no leaf of its size or larger
/// covers), and every margin voxel within one of a voxel that such a cell meets.
/// The [`Frame`] of the whole `field` (for saving it).
pub(crate) fn frame_of<const D: usize>(field: &Field<D>) -> Result<Frame<D>> {
    let leaves = Leaves::new(&field.centers, &field.halves).map_err(Error::Solver)?;
    let (_, margin_shift) = margin(&leaves, None);
    let mut lo = Vect::<D>::repeat(f64::INFINITY);
    let mut hi = Vect::<D>::repeat(f64::NEG_INFINITY);
    for (c, h) in field.centers.iter().zip(&field.halves) {
        lo = lo.inf(&c.add_scalar(-h));
        hi = hi.sup(&c.add_scalar(*h));
    }
    Ok(Frame {
        lower: leaves.lower,
        edge: leaves.edge,
        margin_shift,
        bounds: (lo, hi),
        largest_half: field.halves.iter().cloned().fold(0.0, f64::max),
    })
}

fn margin<const D: usize>(leaves: &Leaves<D>, fixed: Option<u32>) -> (FxHashSet<[i64; D]>, u32) {
    let boundary: Vec<usize> = (0..leaves.keys.len())
        .filter(|&c| {
            let (shift, coord) = leaves.keys[c];
            // In a window, a cell larger than the whole field's margin voxel is not on its
            // boundary (it only looks so where the window cuts its neighbors away).
            fixed.is_none_or(|f| shift <= f)
                && (0..D).any(|a| {
                    [-1i64, 1].iter().any(|&side| {
                        let mut next = coord;
                        next[a] += side;
                        !leaves.covered(shift, &next)
                    })
                })
        })
        .collect();
    let shift = fixed.unwrap_or_else(|| {
        boundary
            .iter()
            .map(|&c| leaves.keys[c].0)
            .max()
            .unwrap_or(0)
    });
    let mut set = FxHashSet::default();
    for &c in &boundary {
        let (s, coord) = leaves.keys[c];
        // Every boundary cell is at most the margin voxel's size: it lies in one.
        let v = coord.map(|k| k >> (shift - s));
        for_each_shell(v.map(|k| k - 1), v.map(|k| k + 1), None, |u| {
            set.insert(u);
        });
    }
    (set, shift)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_step_is_c2() {
        assert_eq!(smooth(0.0), 0.0);
        assert_eq!(smooth(1.0), 1.0);
        let d = |t: f64| 30.0 * t * t * (1.0 - t) * (1.0 - t);
        assert_eq!(d(0.0), 0.0);
        assert_eq!(d(1.0), 0.0);
        let e = 1e-6;
        assert!(((smooth(0.5 + e) - smooth(0.5 - e)) / (2.0 * e) - d(0.5)).abs() < 1e-6);
    }
}
