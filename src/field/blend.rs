//! The paper's preview transfer: each sample follows the inverse-distance blend of the rigid
//! motions of the 4 cells whose rest centers are nearest (kiddo kd-tree):
//!
//! ```text
//! x' = Σ_k w_k T_k(x) / Σ_k w_k,   w_k = 1 / d_k,   d_k = |x − c_k|
//! ```
//!
//! At `d_k → 0` the weight of that cell dominates and the limit is `T_k(x)`: a sample within
//! `1e-12` cell sizes of a center takes that cell's motion alone, which is the limit and avoids
//! dividing by zero. With fewer than 4 cells, all cells are blended.

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};

use super::{Field, Warp};
use crate::error::{Error, Result};
use crate::rigid::{Motion, Vect};

/// Neighbors blended per sample.
pub const K: usize = 4;

/// The blend transfer of a field.
pub struct Blend<const D: usize> {
    tree: ImmutableKdTree<f64, D>,
    centers: Vec<Vect<D>>,
    motions: Vec<Motion<D>>,
    k: NonZero<usize>,
    snap: f64,
}

impl<const D: usize> Blend<D> {
    /// Builds the kd-tree over the field's rest centers.
    pub fn new(field: &Field<D>) -> Result<Self> {
        let pts: Vec<[f64; D]> = field.centers.iter().map(|c| (*c).into()).collect();
        let tree = ImmutableKdTree::new_from_slice(&pts)
            .map_err(|e| Error::Solver(format!("kd-tree over cell centers: {e:?}")))?;
        let k = NonZero::new(K.min(field.centers.len()))
            .ok_or_else(|| Error::Solver("the field has no cells".into()))?;
        let smallest = field.halves.iter().cloned().fold(f64::MAX, f64::min);
        Ok(Self {
            tree,
            centers: field.centers.clone(),
            motions: field.motions.clone(),
            k,
            snap: 1e-12 * smallest,
        })
    }

    /// The blended cells and their normalized weights (summing to one) at the local point `x`.
    pub fn weights(&self, x: &Vect<D>) -> ([(usize, f64); K], usize) {
        let q: [f64; D] = (*x).into();
        let near = self
            .tree
            .query(&q)
            .nearest_n::<SquaredEuclidean<f64>>(self.k)
            .execute();
        let mut out = [(0usize, 0.0f64); K];
        let n = near.len().min(K);
        if let Some(first) = near.first()
            && first.distance.sqrt() <= self.snap
        {
            out[0] = (first.item as usize, 1.0);
            return (out, 1);
        }
        let mut total = 0.0;
        for (slot, r) in out.iter_mut().zip(&near) {
            let w = 1.0 / r.distance.sqrt();
            *slot = (r.item as usize, w);
            total += w;
        }
        for slot in &mut out[..n] {
            slot.1 /= total;
        }
        (out, n)
    }
}

impl<const D: usize> Blend<D> {
    /// `x'` and the turned normal from one set of weights: `Σ w_k T_k(x)` and the normal turned
    /// by the blended rotation `Σ w_k R_k`, renormalized.
    fn blend(&self, x: &Vect<D>, n: Option<&Vect<D>>) -> (Vect<D>, Vect<D>) {
        let (w, k) = self.weights(x);
        let mut moved = Vect::<D>::zeros();
        let mut turned = Vect::<D>::zeros();
        for &(c, wk) in &w[..k] {
            moved += self.motions[c].apply(&self.centers[c], x) * wk;
            if let Some(n) = n {
                turned += self.motions[c].rot * n * wk;
            }
        }
        let len = turned.norm();
        match n {
            Some(_) if len > 0.0 && len.is_finite() => (moved, turned / len),
            Some(n) => (moved, *n),
            None => (moved, turned),
        }
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
}
