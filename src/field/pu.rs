//! The partition-of-unity RBF (issue 15): the triharmonic RBF of [`super::Rbf`] fitted on small
//! overlapping patches and blended by C² weights, so that its fit is O(n) and its evaluation
//! O(patch size) per sample, whatever the number of cells.
//!
//! - **Patches.** Space is cut into a regular grid of boxes of edge `s`, a power of two of the
//!   smallest cell's edge, the smallest for which the boxes that hold a cell center hold at
//!   least [`PATCH_CENTERS`] on average; every box that meets a cell is a patch. A patch's
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

use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::leaves::floor;
use super::{Field, Rbf, Warp, unit_or};
use crate::error::{Error, Result};
use crate::rigid::{Motion, Vect};

/// The centers a patch box holds on average at least (it sets the patches' size).
pub const PATCH_CENTERS: f64 = 24.0;

/// How far a patch's support reaches past its box on each side, in box edges.
pub const OVERLAP: f64 = 0.25;

/// The fewest centers a patch fits.
pub const MIN_FIT: usize = 12;

/// The partition-of-unity RBF transfer of a field.
pub struct PuRbf<const D: usize> {
    /// Lower corner of box 0 (local frame).
    lower: Vect<D>,
    /// The boxes' edge.
    edge: f64,
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
        Ok(Self {
            source: Some(Field {
                origin: field.origin,
                centers: field.centers.clone(),
                halves: field.halves.clone(),
                motions: field.motions.clone(),
                prescribed: Default::default(),
            }),
            ..Self::layout(field)?
        })
    }

    /// The patches of `field` and the members of each, none fitted yet.
    fn layout(field: &Field<D>) -> Result<Self> {
        let n = field.centers.len();
        if n == 0 {
            return Err(Error::Solver("the field has no cells".into()));
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
            edge *= std::f64::consts::SQRT_2;
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
            .map_err(|e| Error::Solver(format!("kd-tree over cell centers: {e:?}")))?;
        let middle =
            |k: &[i64; D]| Vect::<D>::from_fn(|a, _| lower[a] + (k[a] as f64 + 0.5) * edge);
        let patches: Vec<Patch<D>> = keys
            .par_iter()
            .map(|k| {
                let middle = middle(k);
                Patch {
                    middle,
                    members: gather(field, &by_box, &near, k, &middle, reach),
                    fit: OnceLock::new(),
                }
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
            index,
            middles: kiddo::ImmutableKdTree::new_from_slice(&points)
                .map_err(|e| Error::Solver(format!("kd-tree over patches: {e:?}")))?,
            patches,
            source: None,
            failed: AtomicUsize::new(0),
        })
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
    fn around(&self, x: &Vect<D>) -> ([(u32, f64); 8], usize) {
        let reach = (0.5 + OVERLAP) * self.edge;
        // The box of `x` and, along each axis, its neighbor on the near side when `x` is within
        // the overlap of it.
        let t: [f64; D] = std::array::from_fn(|a| (x[a] - self.lower[a]) / self.edge);
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
        let mut out = [(0u32, 0.0f64); 8];
        let mut n = 0;
        for bits in 0..1usize << D {
            if (0..D).any(|a| bits >> a & 1 == 1 && side[a] == 0) {
                continue;
            }
            let k: [i64; D] = std::array::from_fn(|a| home[a] + (bits >> a & 1) as i64 * side[a]);
            let Some(&p) = self.index.get(&k) else {
                continue;
            };
            let m = &self.patches[p as usize].middle;
            let mut w = 1.0;
            for a in 0..D {
                w *= wendland((x[a] - m[a]).abs() / reach);
            }
            if w > 0.0 && n < out.len() {
                out[n] = (p, w);
                n += 1;
            }
        }
        (out, n)
    }

    /// The displacement at the local point `x`.
    pub fn displacement(&self, x: &Vect<D>) -> Vect<D> {
        let (around, n) = self.around(x);
        self.blend(x, &around[..n])
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

    /// Four consecutive samples among the same patches (the common case in a scan) share each
    /// patch's pass over its centers; the same bits as [`Warp::warp`].
    fn warp_run(&self, origin: &Vect<D>, points: &[Vect<D>], out: &mut [Vect<D>]) {
        let xs: Vec<Vect<D>> = points.iter().map(|p| p - origin).collect();
        let sets: Vec<([(u32, f64); 8], usize)> = xs.iter().map(|x| self.around(x)).collect();
        let same = |a: &([(u32, f64); 8], usize), b: &([(u32, f64); 8], usize)| {
            a.1 == b.1 && (0..a.1).all(|k| a.0[k].0 == b.0[k].0)
        };
        let mut i = 0;
        while i < xs.len() {
            let n = sets[i].1;
            if n > 0 && i + 4 <= xs.len() && (1..4).all(|s| same(&sets[i], &sets[i + s])) {
                let four: [Vect<D>; 4] = std::array::from_fn(|s| xs[i + s]);
                let mut total = [0.0f64; 4];
                let mut sum = [Vect::<D>::zeros(); 4];
                for k in 0..n {
                    let Some(fit) = self.fit(sets[i].0[k].0) else {
                        continue;
                    };
                    let d = fit.displacements4(&four);
                    for s in 0..4 {
                        let w = sets[i + s].0[k].1;
                        total[s] += w;
                        sum[s] += d[s] * w;
                    }
                }
                if total.iter().all(|&t| t > 0.0) {
                    for s in 0..4 {
                        out[i + s] = four[s] + sum[s] / total[s] + origin;
                    }
                    i += 4;
                    continue;
                }
            }
            let x = &xs[i];
            let (set, n) = &sets[i];
            out[i] = x + self.blend(x, &set[..*n]) + origin;
            i += 1;
        }
    }

    /// The normal mapped by the inverse transpose of the Jacobian (central differences of a
    /// thousandth of a patch), renormalized.
    fn warp_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        let j = super::central_jacobian(self, x, 1e-3 * self.edge);
        let mapped = j.try_inverse().map(|inv| inv.transpose() * n).unwrap_or(*n);
        unit_or(mapped, n)
    }
}
