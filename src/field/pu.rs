//! The partition-of-unity RBF: the triharmonic RBF of [`super::Rbf`] fitted on small
//! overlapping patches and blended by C² weights, so that its fit is O(n) and its evaluation
//! O(patch size) per sample, whatever the number of cells.
//!
//! - **Patches.** Space is cut into a regular grid of boxes of edge `s`, the smallest cell's
//!   edge times a power of `2^¼`, the smallest for which the boxes that hold a cell center hold
//!   at least [`PATCH_CENTERS`] on average (steps of `√2` overshot it up to twice on a terrain,
//!   and a sample's cost grows with the centers its patches fit); every box that meets a cell is a patch. A patch's
//!   weight is the tensor product of Wendland's C² function `ψ(t) = (1 − t)⁴ (4t + 1)` over
//!   `t = |x_a − m_a| / r` with `m` the box's middle and `r = (½ + OVERLAP) s`, so neighboring
//!   patches overlap by `OVERLAP · s` on each side and every point of the cells lies inside
//!   some patch's support.
//! - **Fits.** Each patch fits the triharmonic RBF with its linear part to the displacements of
//!   the centers in its support (and, for a patch with fewer than [`MIN_FIT`] centers there,
//!   the [`MIN_FIT`] nearest to its middle): `f_p`.
//! - **Blend.** `d(x) = Σ_p ψ_p(x) f_p(x) / Σ_p ψ_p(x)`. It is C² wherever the weights' sum is
//!   positive (the weights are C², the fits C²); it interpolates the centers, because every
//!   patch whose weight is positive at a center fits that center; and where all the centers of
//!   the patches around a point move by one rigid motion, every fit reproduces that motion (it
//!   is linear in `x`), and so does the blend.
//! - **Outside every support** (only beyond the field's margin, with `--outside extend`) the
//!   nearest patch's fit is used alone.
//!
//! A sample meets at most `2^D` patches, `(1 + 2·OVERLAP)^D` on average (3.4 in 3D), each a sum
//! over its few dozen centers, so the cost per sample does not grow with the cells.
//!
//! **Evaluation of a run of samples** ([`Warp::warp_run`]) goes patch by patch: each patch's
//! fit sums its centers once for four of the samples it weighs (the kernel's loads shared and
//! its latencies overlapped; the scan order of a file rarely gives four consecutive samples the
//! same patches, which the former grouping needed), and each sample then blends its own
//! patches in its own order, so the bits are [`Warp::warp`]'s. Measured with `tools/pu
//! --terrain` (1M points in scan order, 2 threads): 3.0–3.7M points/s before, 4.2–5.4M after,
//! together with the `2^¼` patch steps and the kernel's square root (`field::simd`); 5.2–5.9M
//! with each box of a sample's neighborhood looked up once while kept by a hash, and the next
//! patch prefetched (4.5M at 1M cells, where the terrain has as many cells as points and each
//! patch serves few samples of a run); 6.6–7.6M (5.1M at 1M cells) with [`PATCH_CENTERS`] 20
//! instead of 24, the largest gap to the dense RBF on the coarse dragon going from 0.71 % to
//! 0.82 % of the largest displacement.
//! Narrower overlaps are faster still (0.2: about 25 % more) but took the dense-RBF agreement
//! on the coarse dragon from 0.71 % to 0.83 % of the largest displacement, too near the 1 %
//! the issue allows.

use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::{Field, Rbf, Warp, normal_like};
use crate::cells::floor;
use crate::error::{Error, Result};
use crate::rigid::{Motion, Vect};

/// The centers a patch box holds on average at least (it sets the patches' size).
pub(crate) const PATCH_CENTERS: f64 = 20.0;

/// How far a patch's support reaches past its box on each side, in box edges.
pub(crate) const OVERLAP: f64 = 0.25;

/// The fewest centers a patch fits.
pub(crate) const MIN_FIT: usize = 12;

/// The partition-of-unity RBF transfer of a field.
pub struct PuRbf<const D: usize> {
    /// Lower corner of box 0 (local frame).
    lower: Vect<D>,
    /// The boxes' edge.
    edge: f64,
    /// `1 / edge`.
    inv_edge: f64,
    /// `1 / ((½ + OVERLAP) edge)`: a patch's weight falls to zero at this distance's inverse.
    inv_reach: f64,
    /// Box coordinates → patch.
    index: FxHashMap<[i64; D], u32>,
    /// The patches, by box order.
    patches: Vec<Patch<D>>,
    /// The patches' middles, for the nearest patch outside every support.
    middles: kiddo::ImmutableKdTree<f64, D>,
    /// The cells the patches fit, kept for fits made on demand ([`PuRbf::lazy`]; `None` when
    /// every fit was made up front).
    source: Option<Field<D>>,
    /// Fits made on demand that failed (their patches are left out of the blend).
    failed: AtomicUsize,
}

/// The patches around a point with their weights (the first `.1` of `.0`).
type Around = ([(u32, f64); 8], usize);

/// The patches that may weigh the points of one box's part: the box, the sides of its
/// neighbors, and the patches with the bits of the axes along which each is the neighbor.
#[derive(Clone, Copy)]
struct Candidates<const D: usize> {
    home: [i64; D],
    side: [i64; D],
    patches: [(u32, u8); 8],
    count: usize,
}

/// Where the patches of a PU are and which cells each fits ([`PuRbf::layout_of`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Layout<const D: usize> {
    /// Box 0's lower corner (local frame).
    pub lower: Vect<D>,
    /// The boxes' edge.
    pub edge: f64,
    /// Each patch's box and the cells it fits, in ascending order.
    pub patches: Vec<([i64; D], Vec<u32>)>,
}

/// How many boxes' neighborhoods [`PuRbf::warp_run`] keeps (a power of two: they are kept by
/// a hash of the box).
const HOODS: usize = 64;

/// A neighbor box not looked up yet (`u32::MAX`: looked up, no patch).
const UNKNOWN: u32 = u32::MAX - 1;

/// The patches of the `3^D` boxes around `home`, box `home + o` at `Σ_a (o_a + 1) 3^a`, each
/// looked up when a sample first needs it, and the group of each in a run (fields are 2D or
/// 3D: `3^D ≤ 27`).
struct Hood<const D: usize> {
    home: [i64; D],
    patches: [u32; 27],
    groups: [u32; 27],
}

impl<const D: usize> Hood<D> {
    fn new(home: [i64; D]) -> Self {
        Self {
            home,
            patches: [UNKNOWN; 27],
            groups: [0; 27],
        }
    }

    /// The slot of `home` among [`HOODS`].
    fn slot(home: &[i64; D]) -> usize {
        let h = home.iter().fold(0u64, |h, &k| {
            (h ^ k as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
        });
        (h >> 58) as usize % HOODS
    }

    /// The candidates of a sample of the box with neighbors on `side`, as
    /// [`PuRbf::candidates`] finds them, and their groups; `look` gives the patch (if any) of
    /// a box and its group, for the boxes not looked up yet.
    #[inline]
    fn candidates(
        &mut self,
        side: &[i64; D],
        mut look: impl FnMut(&[i64; D]) -> Option<(u32, u32)>,
    ) -> (Candidates<D>, [u32; 8]) {
        let mut c = Candidates {
            home: self.home,
            side: *side,
            patches: [(0u32, 0u8); 8],
            count: 0,
        };
        let mut groups = [0u32; 8];
        for bits in 0..1usize << D {
            if (0..D).any(|a| bits >> a & 1 == 1 && side[a] == 0) {
                continue;
            }
            let mut at = 0;
            let mut stride = 1;
            for (a, s) in side.iter().enumerate() {
                at += (1 + (bits >> a & 1) as i64 * s) as usize * stride;
                stride *= 3;
            }
            if self.patches[at] == UNKNOWN {
                let k: [i64; D] =
                    std::array::from_fn(|a| self.home[a] + (bits >> a & 1) as i64 * side[a]);
                (self.patches[at], self.groups[at]) = look(&k).unwrap_or((u32::MAX, 0));
            }
            if self.patches[at] != u32::MAX {
                c.patches[c.count] = (self.patches[at], bits as u8);
                groups[c.count] = self.groups[at];
                c.count += 1;
            }
        }
        (c, groups)
    }
}

/// A patch: its box middle, the cells it fits, and its fit once made.
struct Patch<const D: usize> {
    middle: Vect<D>,
    members: Vec<u32>,
    fit: OnceLock<Option<Rbf<D>>>,
}

/// Wendland's C² function on `[0, 1]`: `(1 − t)⁴ (4t + 1)`, zero beyond.
#[inline]
fn wendland(t: f64) -> f64 {
    if t >= 1.0 {
        0.0
    } else {
        let u = 1.0 - t;
        let u2 = u * u;
        u2 * u2 * (4.0 * t + 1.0)
    }
}

/// The slope of [`wendland`]: `−20 t (1 − t)³`, zero at both ends.
#[inline]
fn wendland_slope(t: f64) -> f64 {
    if t >= 1.0 {
        0.0
    } else {
        let u = 1.0 - t;
        -20.0 * t * u * u * u
    }
}

impl<const D: usize> PuRbf<D> {
    /// Cuts the field into patches and fits each (in parallel).
    pub fn new(field: &Field<D>) -> Result<Self> {
        let mut pu = Self::layout(field)?;
        pu.patches.par_iter_mut().try_for_each(|p| {
            let fit = Rbf::new_serial(&patch_field(field, &p.members))?;
            let _ = p.fit.set(Some(fit));
            // Every fit is made: the members are not needed again.
            p.members = Vec::new();
            Ok::<_, Error>(())
        })?;
        Ok(pu)
    }

    /// Cuts the field into patches and fits each only when a sample first needs it: a tile
    /// of a large field fits only the patches around it (`apply`), with the same bits as
    /// [`PuRbf::new`], since each patch's fit depends on its own cells only. A fit that fails
    /// here (where [`PuRbf::new`] would have returned the error) is left out of the blend and
    /// counted ([`PuRbf::fits`]).
    pub fn lazy(field: &Field<D>) -> Result<Self> {
        Ok(Self::layout(field)?.fitting_from(field))
    }

    /// The patches of `field` and the members of each, none fitted yet.
    fn layout(field: &Field<D>) -> Result<Self> {
        let n = field.centers.len();
        if n == 0 {
            return Err(Error::solver("the field has no cells"));
        }
        let smallest = 2.0 * field.halves.iter().cloned().fold(f64::INFINITY, f64::min);
        let mut lo = Vect::<D>::repeat(f64::INFINITY);
        for (c, h) in field.centers.iter().zip(&field.halves) {
            lo = lo.inf(&c.add_scalar(-h));
        }
        let lower = lo;
        let box_of = |x: &Vect<D>, edge: f64| -> [i64; D] {
            std::array::from_fn(|a| floor((x[a] - lower[a]) / edge))
        };
        // The smallest power-of-two box edge whose occupied boxes hold enough centers.
        let mut edge = smallest;
        for _ in 0..40 {
            let mut count: FxHashMap<[i64; D], usize> = FxHashMap::default();
            for c in &field.centers {
                *count.entry(box_of(c, edge)).or_default() += 1;
            }
            if n as f64 / count.len() as f64 >= PATCH_CENTERS || count.len() == 1 {
                break;
            }
            edge *= 2f64.powf(0.25);
        }
        // Every box that meets a cell is a patch.
        let mut keys: Vec<[i64; D]> = Vec::new();
        {
            let mut seen = rustc_hash::FxHashSet::default();
            for (c, &h) in field.centers.iter().zip(&field.halves) {
                let from = box_of(&c.add_scalar(-h), edge);
                let to = box_of(&c.add_scalar(h * (1.0 - 1e-12)), edge);
                let mut k = from;
                loop {
                    if seen.insert(k) {
                        keys.push(k);
                    }
                    let Some(a) = (0..D).find(|&a| k[a] < to[a]) else {
                        break;
                    };
                    k[a] += 1;
                    k[..a].copy_from_slice(&from[..a]);
                }
            }
        }
        keys.sort_unstable();
        // The centers by box, for gathering each patch's fit.
        let mut by_box: FxHashMap<[i64; D], Vec<u32>> = FxHashMap::default();
        for (i, c) in field.centers.iter().enumerate() {
            by_box.entry(box_of(c, edge)).or_default().push(i as u32);
        }
        let reach = (0.5 + OVERLAP) * edge;
        let at: Vec<[f64; D]> = field.centers.iter().map(|c| (*c).into()).collect();
        let near = kiddo::ImmutableKdTree::new_from_slice(&at)
            .map_err(|e| Error::solver(format!("kd-tree over cell centers: {e:?}")))?;
        let middle =
            |k: &[i64; D]| Vect::<D>::from_fn(|a, _| lower[a] + (k[a] as f64 + 0.5) * edge);
        let members: Vec<Vec<u32>> = keys
            .par_iter()
            .map(|k| gather(field, &by_box, &near, k, &middle(k), reach))
            .collect();
        Self::assemble(lower, edge, keys, members)
    }

    /// The patches of boxes `keys` (edge `edge`, box 0's lower corner at `lower`) fitting the
    /// cells `members` each, none fitted yet.
    fn assemble(
        lower: Vect<D>,
        edge: f64,
        keys: Vec<[i64; D]>,
        members: Vec<Vec<u32>>,
    ) -> Result<Self> {
        let reach = (0.5 + OVERLAP) * edge;
        let patches: Vec<Patch<D>> = keys
            .iter()
            .zip(members)
            .map(|(k, members)| Patch {
                middle: Vect::<D>::from_fn(|a, _| lower[a] + (k[a] as f64 + 0.5) * edge),
                members,
                fit: OnceLock::new(),
            })
            .collect();
        let index = keys
            .iter()
            .enumerate()
            .map(|(p, k)| (*k, p as u32))
            .collect();
        let points: Vec<[f64; D]> = patches.iter().map(|p| p.middle.into()).collect();
        Ok(Self {
            lower,
            edge,
            inv_edge: 1.0 / edge,
            inv_reach: 1.0 / reach,
            index,
            middles: kiddo::ImmutableKdTree::new_from_slice(&points)
                .map_err(|e| Error::solver(format!("kd-tree over patches: {e:?}")))?,
            patches,
            source: None,
            failed: AtomicUsize::new(0),
        })
    }

    /// The layout of the patches of `field`, for saving it ([`super::SavedField`]): box 0's
    /// lower corner, the boxes' edge, and each patch's box and cells.
    pub fn layout_of(field: &Field<D>) -> Result<Layout<D>> {
        let pu = Self::layout(field)?;
        let mut keys = vec![[0i64; D]; pu.patches.len()];
        for (k, &p) in &pu.index {
            keys[p as usize] = *k;
        }
        Ok(Layout {
            lower: pu.lower,
            edge: pu.edge,
            patches: keys
                .into_iter()
                .zip(pu.patches)
                .map(|(k, patch)| (k, patch.members))
                .collect(),
        })
    }

    /// The PU of `layout` over `field`, fitting each patch on demand as [`PuRbf::lazy`] does:
    /// a window of a saved field's cells (whose patches' cells are all in `field`, their
    /// indices mapped to it in the same order) gives the whole field's bits.
    pub fn from_layout(field: &Field<D>, layout: Layout<D>) -> Result<Self> {
        let n = field.centers.len() as u32;
        if !(layout.edge > 0.0 && layout.edge.is_finite())
            || layout
                .patches
                .iter()
                .any(|(_, m)| m.is_empty() || m.iter().any(|&i| i >= n))
        {
            return Err(Error::solver("the PU layout does not match the cells"));
        }
        let (keys, members) = layout.patches.into_iter().unzip();
        Ok(Self::assemble(layout.lower, layout.edge, keys, members)?.fitting_from(field))
    }

    /// These patches, fitted on demand from the cells of `field` (kept without their
    /// prescribed maps, which the fits do not use).
    fn fitting_from(self, field: &Field<D>) -> Self {
        Self {
            source: Some(Field {
                origin: field.origin,
                centers: field.centers.clone(),
                halves: field.halves.clone(),
                motions: field.motions.clone(),
                prescribed: Default::default(),
                heights_kept: false,
                trend: Default::default(),
            }),
            ..self
        }
    }

    /// The fit of patch `p`, made now if it was not (`None`: it failed).
    #[inline]
    fn fit(&self, p: u32) -> Option<&Rbf<D>> {
        let patch = &self.patches[p as usize];
        patch
            .fit
            .get_or_init(|| {
                let fit = self
                    .source
                    .as_ref()
                    .and_then(|f| Rbf::new_serial(&patch_field(f, &patch.members)).ok());
                if fit.is_none() {
                    self.failed.fetch_add(1, Ordering::Relaxed);
                }
                fit
            })
            .as_ref()
    }

    /// Patches fitted so far, in all, and fits that failed.
    pub fn fits(&self) -> (usize, usize, usize) {
        let made = self
            .patches
            .iter()
            .filter(|p| p.fit.get().is_some())
            .count();
        (
            made,
            self.patches.len(),
            self.failed.load(Ordering::Relaxed),
        )
    }

    /// Patches in all.
    pub fn patch_count(&self) -> usize {
        self.patches.len()
    }

    /// The patches' box edge.
    pub fn patch_edge(&self) -> f64 {
        self.edge
    }

    /// The patches whose support holds the local point `x`, with their weights, in a fixed
    /// order (the box of `x`, then its neighbors on the near sides, by the bits of the axes).
    #[inline]
    fn around(&self, x: &Vect<D>) -> Around {
        let (home, side) = self.boxes_of(x);
        self.weigh(x, &self.candidates(&home, &side)).0
    }

    /// The box of the local point `x` and, along each axis, the side (−1, 0 or 1) of the
    /// neighbor whose support reaches `x` (0: none does).
    #[inline]
    fn boxes_of(&self, x: &Vect<D>) -> ([i64; D], [i64; D]) {
        let t: [f64; D] = std::array::from_fn(|a| (x[a] - self.lower[a]) * self.inv_edge);
        let home: [i64; D] = t.map(floor);
        let side: [i64; D] = std::array::from_fn(|a| {
            let f = t[a] - home[a] as f64;
            if f < OVERLAP {
                -1
            } else if f > 1.0 - OVERLAP {
                1
            } else {
                0
            }
        });
        (home, side)
    }

    /// The patches of the box `home` and of its neighbors on the `side`s, with the bits of the
    /// axes along which each is the neighbor, in the order of those bits (boxes that meet no
    /// cell have none).
    #[inline]
    fn candidates(&self, home: &[i64; D], side: &[i64; D]) -> Candidates<D> {
        let mut out = [(0u32, 0u8); 8];
        let mut n = 0;
        for bits in 0..1usize << D {
            if (0..D).any(|a| bits >> a & 1 == 1 && side[a] == 0) {
                continue;
            }
            let k: [i64; D] = std::array::from_fn(|a| home[a] + (bits >> a & 1) as i64 * side[a]);
            if let Some(&p) = self.index.get(&k)
                && n < out.len()
            {
                out[n] = (p, bits as u8);
                n += 1;
            }
        }
        Candidates {
            home: *home,
            side: *side,
            patches: out,
            count: n,
        }
    }

    /// The candidates whose weight at `x` is positive, with those weights: per axis the
    /// weights of the home box's patch and of the neighbor's, multiplied along the axes.
    #[inline]
    /// Also returns, for each, its index among the candidates.
    fn weigh(&self, x: &Vect<D>, c: &Candidates<D>) -> (Around, [u8; 8]) {
        let axis = |a: usize, k: i64| {
            let middle = self.lower[a] + (k as f64 + 0.5) * self.edge;
            wendland((x[a] - middle).abs() * self.inv_reach)
        };
        let home: [f64; D] = std::array::from_fn(|a| axis(a, c.home[a]));
        let near: [f64; D] = std::array::from_fn(|a| {
            if c.side[a] == 0 {
                0.0
            } else {
                axis(a, c.home[a] + c.side[a])
            }
        });
        let mut out = [(0u32, 0.0f64); 8];
        let mut which = [0u8; 8];
        let mut n = 0;
        for (k, &(p, bits)) in c.patches[..c.count].iter().enumerate() {
            let mut w = 1.0;
            for a in 0..D {
                w *= if bits >> a & 1 == 1 { near[a] } else { home[a] };
            }
            if w > 0.0 {
                out[n] = (p, w);
                which[n] = k as u8;
                n += 1;
            }
        }
        ((out, n), which)
    }

    /// The displacement at the local point `x`.
    pub fn displacement(&self, x: &Vect<D>) -> Vect<D> {
        let (around, n) = self.around(x);
        self.blend(x, &around[..n])
    }

    /// The Jacobian of the map `x ↦ x + displacement(x)` at the local point `x`, in closed
    /// form. With `W = Σ w_p` over the patches fitted around `x` and `d = Σ w_p d_p / W` their
    /// blend, `∂d = Σ (w_p ∂d_p + (d_p − d) ∇w_pᵀ) / W`: each fit's own Jacobian
    /// ([`Rbf::jacobian`]) and the slopes of the weights (products of [`wendland`] along the
    /// axes). Where no fitted patch weighs `x`, the nearest fit's.
    pub fn jacobian(&self, x: &Vect<D>) -> nalgebra::SMatrix<f64, D, D> {
        let (home, side) = self.boxes_of(x);
        let candidates = self.candidates(&home, &side);
        let ((around, n), which) = self.weigh(x, &candidates);
        let identity = nalgebra::SMatrix::<f64, D, D>::identity();
        let mut total = 0.0;
        let mut slopes = Vect::<D>::zeros();
        let mut sum = Vect::<D>::zeros();
        let mut inner = nalgebra::SMatrix::<f64, D, D>::zeros();
        for (&(p, w), &k) in around[..n].iter().zip(&which[..n]) {
            let Some(fit) = self.fit(p) else {
                continue;
            };
            let slope = self.weight_slope(x, &candidates, candidates.patches[k as usize].1);
            let d = fit.displacement(x);
            total += w;
            slopes += slope;
            sum += d * w;
            inner += (fit.jacobian(x) - identity) * w + d * slope.transpose();
        }
        if total > 0.0 {
            return identity + (inner - (sum / total) * slopes.transpose()) / total;
        }
        self.nearest(x).map_or(identity, |fit| fit.jacobian(x))
    }

    /// The gradient at `x` of the weight of the candidate whose axes' bits are `bits` (the
    /// neighbor's box along a set bit, the home box's along the others), as [`PuRbf::weigh`]
    /// weighs it.
    fn weight_slope(&self, x: &Vect<D>, c: &Candidates<D>, bits: u8) -> Vect<D> {
        let parts: [(f64, f64); D] = std::array::from_fn(|a| {
            let k = c.home[a] + if bits >> a & 1 == 1 { c.side[a] } else { 0 };
            let offset = x[a] - (self.lower[a] + (k as f64 + 0.5) * self.edge);
            let t = offset.abs() * self.inv_reach;
            (
                wendland(t),
                wendland_slope(t) * offset.signum() * self.inv_reach,
            )
        });
        Vect::<D>::from_fn(|a, _| {
            (0..D)
                .map(|b| if b == a { parts[b].1 } else { parts[b].0 })
                .product()
        })
    }

    /// The weighted mean of the fits of `around` at `x` (the nearest patch's fit where none
    /// holds `x`, or none of them could be fitted).
    fn blend(&self, x: &Vect<D>, around: &[(u32, f64)]) -> Vect<D> {
        let mut total = 0.0;
        let mut sum = Vect::<D>::zeros();
        for &(p, w) in around {
            if let Some(fit) = self.fit(p) {
                total += w;
                sum += fit.displacement(x) * w;
            }
        }
        if total > 0.0 {
            return sum / total;
        }
        self.nearest(x)
            .map_or(Vect::<D>::zeros(), |fit| fit.displacement(x))
    }

    /// The fit of the patch nearest to `x` (outside every support), or of the nearest of the
    /// eight nearest that could be fitted.
    fn nearest(&self, x: &Vect<D>) -> Option<&Rbf<D>> {
        let p: [f64; D] = (*x).into();
        let eight = std::num::NonZero::new(8).expect("8 > 0");
        self.middles
            .query(&p)
            .nearest_n::<kiddo::SquaredEuclidean<f64>>(eight)
            .execute()
            .iter()
            .find_map(|r| self.fit(r.item))
    }
}

/// The sub-field of a patch's `members`. Where their centers lie in a plane (a terrain one
/// cell thick) or on a line, the fit's linear part would be undetermined: each center then gets
/// two companions half a cell off that plane on either side, displaced by the cell's own rigid
/// motion, so the fit learns the cells' rotations there instead of failing.
fn patch_field<const D: usize>(field: &Field<D>, members: &[u32]) -> Field<D> {
    let mut sub = Field {
        origin: Vect::<D>::zeros(),
        centers: members.iter().map(|&i| field.centers[i as usize]).collect(),
        halves: members.iter().map(|&i| field.halves[i as usize]).collect(),
        motions: members.iter().map(|&i| field.motions[i as usize]).collect(),
        prescribed: Default::default(),
        heights_kept: false,
        trend: Default::default(),
    };
    let k = members.len() as f64;
    let mean = sub.centers.iter().fold(Vect::<D>::zeros(), |s, c| s + c) / k;
    let mut cov = nalgebra::SMatrix::<f64, D, D>::zeros();
    for c in &sub.centers {
        let d = c - mean;
        cov += d * d.transpose();
    }
    let eigen = nalgebra::DMatrix::from_fn(D, D, |r, c| cov[(r, c)] / k).symmetric_eigen();
    let largest = eigen.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let flat: Vec<Vect<D>> = (0..D)
        .filter(|&a| eigen.eigenvalues[a] <= 1e-6 * largest.max(f64::MIN_POSITIVE))
        .map(|a| Vect::<D>::from_fn(|r, _| eigen.eigenvectors[(r, a)]))
        .collect();
    if flat.is_empty() {
        return sub;
    }
    for &i in members {
        let (c, h, m) = (
            field.centers[i as usize],
            field.halves[i as usize],
            field.motions[i as usize],
        );
        for axis in &flat {
            for side in [-1.0, 1.0] {
                let at = c + axis * (side * h);
                sub.centers.push(at);
                sub.halves.push(h);
                sub.motions.push(Motion {
                    rot: m.rot,
                    pos: m.apply(&c, &at),
                });
            }
        }
    }
    sub
}

/// The centers in the support of the patch of box `k` (middle `m`, half-width `reach`, so they
/// lie in the boxes around `k`) and, where those are fewer than [`MIN_FIT`], also the
/// [`MIN_FIT`] centers nearest to `m` (sparse cells far apart), from the kd-tree `near`.
fn gather<const D: usize>(
    field: &Field<D>,
    by_box: &FxHashMap<[i64; D], Vec<u32>>,
    near: &kiddo::ImmutableKdTree<f64, D>,
    k: &[i64; D],
    m: &Vect<D>,
    reach: f64,
) -> Vec<u32> {
    let mut members = Vec::new();
    let mut v = k.map(|c| c - 1);
    loop {
        if let Some(list) = by_box.get(&v) {
            members.extend(list.iter().copied().filter(|&i| {
                let c = &field.centers[i as usize];
                (0..D).all(|a| (c[a] - m[a]).abs() <= reach)
            }));
        }
        let Some(a) = (0..D).find(|&a| v[a] < k[a] + 1) else {
            break;
        };
        v[a] += 1;
        for b in 0..a {
            v[b] = k[b] - 1;
        }
    }
    if members.len() < MIN_FIT {
        let at: [f64; D] = (*m).into();
        let count = std::num::NonZero::new(MIN_FIT).expect("MIN_FIT > 0");
        members.extend(
            near.query(&at)
                .nearest_n::<kiddo::SquaredEuclidean<f64>>(count)
                .execute()
                .iter()
                .map(|r| r.item),
        );
    }
    members.sort_unstable();
    members.dedup();
    members
}

impl<const D: usize> Warp<D> for PuRbf<D> {
    #[inline]
    fn warp(&self, x: &Vect<D>) -> Vect<D> {
        x + self.displacement(x)
    }

    /// The samples are evaluated patch by patch: each patch's fit runs over its centers once
    /// for every four samples it weighs (`Rbf::displacements4`, the same bits as one by one),
    /// and each sample then blends its patches' displacements in its own order, so every
    /// result has [`Warp::warp`]'s bits whatever the other samples of the run.
    fn warp_run(&self, origin: &Vect<D>, points: &[Vect<D>], out: &mut [Vect<D>]) {
        let xs: Vec<Vect<D>> = points.iter().map(|p| p - origin).collect();
        // The patches around each sample, and the group (of slots, by patch) of each. Each box
        // of the 3^D around a sample's box is looked up once while the box is kept among
        // [`HOODS`] by a hash (a scan's strip crosses a row of boxes back and forth, and
        // samples of a mesh come in any order); a sample's candidates are picked from them.
        let mut group: FxHashMap<u32, u32> = FxHashMap::default();
        let mut patch_of_group: Vec<u32> = Vec::new();
        let mut slot_group: Vec<u32> = Vec::with_capacity(4 * xs.len());
        let mut hoods: Vec<Option<Hood<D>>> = (0..HOODS).map(|_| None).collect();
        let sets: Vec<Around> = xs
            .iter()
            .map(|x| {
                let (home, side) = self.boxes_of(x);
                let slot = &mut hoods[Hood::slot(&home)];
                let hood = match slot {
                    Some(h) if h.home == home => h,
                    _ => slot.insert(Hood::new(home)),
                };
                let (candidates, groups) = hood.candidates(&side, |k| {
                    let &p = self.index.get(k)?;
                    let g = *group.entry(p).or_insert_with(|| {
                        patch_of_group.push(p);
                        patch_of_group.len() as u32 - 1
                    });
                    Some((p, g))
                });
                let (set, which) = self.weigh(x, &candidates);
                for &k in &which[..set.1] {
                    slot_group.push(groups[k as usize]);
                }
                set
            })
            .collect();
        // Slot `start[i] + k` holds the displacement of sample `i` by its `k`-th patch.
        let mut start = Vec::with_capacity(xs.len() + 1);
        start.push(0usize);
        for (_, n) in &sets {
            start.push(start.last().copied().unwrap_or(0) + n);
        }
        let slots = start[xs.len()];
        let mut first = vec![0usize; patch_of_group.len() + 1];
        for &g in &slot_group {
            first[g as usize + 1] += 1;
        }
        for g in 0..patch_of_group.len() {
            first[g + 1] += first[g];
        }
        let mut order = vec![(0u32, 0u32); slots]; // (sample, slot), by group
        let mut fill = first.clone();
        for (i, w) in start.windows(2).enumerate() {
            for slot in w[0]..w[1] {
                let g = slot_group[slot] as usize;
                order[fill[g]] = (i as u32, slot as u32);
                fill[g] += 1;
            }
        }
        let mut moved = vec![Vect::<D>::zeros(); slots];
        let mut fitted = vec![false; slots];
        let used: Vec<usize> = (0..patch_of_group.len())
            .filter(|&g| first[g] < first[g + 1])
            .collect();
        for (u, &g) in used.iter().enumerate() {
            // (A neighbor's patch that weighs none of the samples is not fitted for them.)
            let Some(fit) = self.fit(patch_of_group[g]) else {
                continue;
            };
            // The next patch's numbers come from memory while this one is summed (a large
            // field's patches are not in the caches).
            if let Some(next) = used.get(u + 1).and_then(|&h| self.fit(patch_of_group[h])) {
                next.prefetch();
            }
            for four in order[first[g]..first[g + 1]].chunks(4) {
                let at: [Vect<D>; 4] =
                    std::array::from_fn(|s| xs[four[s.min(four.len() - 1)].0 as usize]);
                let d = fit.displacements4(&at);
                for (s, &(_, slot)) in four.iter().enumerate() {
                    moved[slot as usize] = d[s];
                    fitted[slot as usize] = true;
                }
            }
        }
        for (i, x) in xs.iter().enumerate() {
            let (set, n) = &sets[i];
            let mut total = 0.0;
            let mut sum = Vect::<D>::zeros();
            for k in 0..*n {
                let slot = start[i] + k;
                if fitted[slot] {
                    total += set[k].1;
                    sum += moved[slot] * set[k].1;
                }
            }
            let d = if total > 0.0 {
                sum / total
            } else {
                self.nearest(x)
                    .map_or(Vect::<D>::zeros(), |fit| fit.displacement(x))
            };
            out[i] = x + d + origin;
        }
    }

    /// The closed form ([`PuRbf::jacobian`]); `h` is not used.
    fn jacobian(&self, x: &Vect<D>, _h: f64) -> nalgebra::SMatrix<f64, D, D> {
        PuRbf::jacobian(self, x)
    }

    /// The normal mapped by the inverse transpose of the Jacobian, with its length.
    fn warp_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        let j = PuRbf::jacobian(self, x);
        let mapped = j.try_inverse().map(|inv| inv.transpose() * n).unwrap_or(*n);
        normal_like(mapped, n)
    }
}
