//! The preview transfer: each sample follows a blend of the rigid motions of the `K = 4` cells
//! whose rest centers are nearest:
//!
//! ```text
//! x' = Σ_k w_k T_k(x) / Σ_k w_k
//! ```
//!
//! Two weightings ([`Weights`]):
//!
//! - **continuous** (default): `w_k = 1/d_k − 1/d_5`, with `d_5` the distance of the 5th
//!   nearest center. Where the 4-nearest set changes, the 4th and 5th are equidistant and the
//!   weight of the one that leaves or enters is zero, so the map has no seams; where the 5th and
//!   6th swap, `1/d_5` is the same for both. (At a point equidistant from all 5 the weights all
//!   vanish; it takes the plain average of the 4 there.)
//! - **inverse distance** (the paper's): `w_k = 1/d_k`, which jumps where the set changes.
//!
//! Where the blended cells all follow one motion (a fixed region, the inside of a handle), the
//! sample follows that motion exactly, without weights: the samples of a fixed region keep
//! their coordinates bit for bit (on the terrain of `tools/stream`, whose ends are fixed and
//! lifted, the blend went from 70 to 65 ns per sample).
//!
//! At `d_k → 0` the weight of that cell dominates and the limit is `T_k(x)`: a sample within
//! `1e-12` cell sizes of a center takes that cell's motion alone, which is the limit and avoids
//! dividing by zero. With fewer than 5 cells, all cells are blended by inverse distance. The
//! nearest centers come from the exact tiled search of [`super::nearest`].

use super::nearest::{Anchor, NEAR, Nearest, Neighbors};
use super::{Field, Warp, normal_like};
use crate::error::Result;
use crate::rigid::{Affine, Vect};

/// Neighbors blended per sample.
pub const K: usize = 4;

/// How the blend weighs the nearest cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Weights {
    /// `1/d_k − 1/d_5`: continuous everywhere.
    #[default]
    Continuous,
    /// `1/d_k`: the paper's, with seams where the 4-nearest set changes.
    InverseDistance,
}

/// The blend transfer of a field.
pub struct Blend<const D: usize> {
    nearest: Nearest<D>,
    /// Each cell's motion as the affine map `x ↦ R x + (p − R c)`: one read and no
    /// subtraction per blended cell.
    maps: Vec<Affine<D>>,
    weights: Weights,
    snap2: f64,
}

impl<const D: usize> Blend<D> {
    /// Builds the nearest-center search over the field's rest centers.
    pub fn new(field: &Field<D>, weights: Weights) -> Result<Self> {
        let smallest = field.halves.iter().cloned().fold(f64::MAX, f64::min);
        Ok(Self {
            nearest: Nearest::new(&field.centers, &field.halves)?,
            maps: field
                .motions
                .iter()
                .zip(&field.centers)
                .map(|(m, c)| Affine {
                    linear: m.rot,
                    translation: m.pos - m.rot * c,
                })
                .collect(),
            weights,
            snap2: (1e-12 * smallest).powi(2),
        })
    }

    /// The nearest-center search (for benchmarks and the brute-force comparison).
    pub fn nearest(&self) -> &Nearest<D> {
        &self.nearest
    }

    /// The blended cells and their normalized weights (summing to one) at the local point `x`.
    #[inline]
    pub fn weights(&self, x: &Vect<D>) -> ([(usize, f64); K], usize) {
        self.weights_of(&self.nearest.find(&(*x).into()))
    }

    /// The blended cells and their normalized weights for the nearest centers `nb`.
    #[inline(always)]
    fn weights_of(&self, nb: &Neighbors) -> ([(usize, f64); K], usize) {
        let mut out = [(0usize, 0.0f64); K];
        if nb.n == 0 {
            return (out, 0);
        }
        if nb.d2[0] <= self.snap2 {
            out[0] = (nb.cells[0] as usize, 1.0);
            return (out, 1);
        }
        let n = nb.n.min(K);
        let cut = match self.weights {
            Weights::Continuous if nb.n == NEAR => 1.0 / nb.d2[NEAR - 1].sqrt(),
            _ => 0.0,
        };
        let mut total = 0.0;
        for (slot, (&c, &d2)) in out.iter_mut().zip(nb.cells.iter().zip(&nb.d2)) {
            let w = 1.0 / d2.sqrt() - cut;
            *slot = (c as usize, w);
            total += w;
        }
        if total > 0.0 {
            let inv = 1.0 / total;
            for slot in &mut out[..n] {
                slot.1 *= inv;
            }
        } else {
            for slot in &mut out[..n] {
                slot.1 = 1.0 / n as f64;
            }
        }
        (out, n)
    }

    /// `x'` and the turned normal from one set of weights: `Σ w_k T_k(x)` and the normal turned
    /// by the blended rotation `Σ w_k R_k`, with its length. A point with no neighbors (a
    /// non-finite coordinate) stays where it is.
    #[inline]
    fn blend(&self, x: &Vect<D>, n: Option<&Vect<D>>) -> (Vect<D>, Vect<D>) {
        self.blend_with(x, n, &self.nearest.find(&(*x).into()))
    }

    /// [`Self::blend`] with the nearest centers `nb` of `x` already found.
    #[inline(always)]
    fn blend_with(&self, x: &Vect<D>, n: Option<&Vect<D>>, nb: &Neighbors) -> (Vect<D>, Vect<D>) {
        match self.shared(nb) {
            Some(map) => self.rigid(map, x, n),
            None => self.weighted(x, n, nb),
        }
    }

    /// The one motion every blended cell of `nb` follows, if they do.
    #[inline(always)]
    fn shared(&self, nb: &Neighbors) -> Option<&Affine<D>> {
        let (&first, rest) = nb.cells[..nb.n.min(K)].split_first()?;
        let map = &self.maps[first as usize];
        rest.iter()
            .all(|&c| self.maps[c as usize] == *map)
            .then_some(map)
    }

    /// [`Self::blend_with`] where the blended cells move differently: the weighted sum.
    #[inline(always)]
    fn weighted(&self, x: &Vect<D>, n: Option<&Vect<D>>, nb: &Neighbors) -> (Vect<D>, Vect<D>) {
        let (w, k) = self.weights_of(nb);
        if k == 0 {
            return (*x, n.copied().unwrap_or_else(Vect::<D>::zeros));
        }
        let mut moved = Vect::<D>::zeros();
        for &(c, wk) in &w[..k] {
            moved += self.maps[c].apply(x) * wk;
        }
        let Some(n) = n else {
            return (moved, Vect::<D>::zeros());
        };
        let mut turned = Vect::<D>::zeros();
        for &(c, wk) in &w[..k] {
            turned += self.maps[c].linear * n * wk;
        }
        (moved, normal_like(turned, n))
    }

    /// `x` and its normal under one cell's motion `map`, which every blended cell follows.
    #[inline(always)]
    fn rigid(&self, map: &Affine<D>, x: &Vect<D>, n: Option<&Vect<D>>) -> (Vect<D>, Vect<D>) {
        let turned = n.map_or_else(Vect::<D>::zeros, |n| normal_like(map.linear * n, n));
        (map.apply(x), turned)
    }
}

impl<const D: usize> Warp<D> for Blend<D> {
    #[inline]
    fn warp(&self, x: &Vect<D>) -> Vect<D> {
        self.blend(x, None).0
    }

    fn warp_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        self.blend(x, Some(n)).1
    }

    fn warp_with_normal(&self, x: &Vect<D>, n: &Vect<D>) -> (Vect<D>, Vect<D>) {
        self.blend(x, Some(n))
    }

    /// Consecutive samples of a scan mostly share their nearest centers: found once, they are
    /// reused while provably still the nearest ([`Nearest::find_reusing`]), with the same bits.
    ///
    /// A sample whose blended cells are all at rest is returned as it came: the round trip
    /// through the local frame, `(p − origin) + origin`, could change its last bit.
    fn warp_run(&self, origin: &Vect<D>, points: &[Vect<D>], out: &mut [Vect<D>]) {
        let mut anchor = Anchor::default();
        let rest = Affine::<D>::identity();
        for (o, p) in out.iter_mut().zip(points) {
            let x = p - origin;
            let nb = self.nearest.find_reusing(&x.into(), &mut anchor);
            *o = match self.shared(&nb) {
                Some(map) if *map == rest => *p,
                Some(map) => map.apply(&x) + origin,
                None => self.weighted(&x, None, &nb).0 + origin,
            };
        }
    }
}
