//! The RBF's sum over centers with far clusters of centers replaced by their moment expansion
//! (Barnes–Hut), under a tolerance the caller sets: every coordinate of the displacement is
//! within the tolerance of the exact sum's, guaranteed by the remainder bound below (rounding
//! aside). `deform --rbf-tolerance` selects it; without it the RBF sums every center exactly.
//!
//! **Tree and moments.** The centers are split recursively at the median of the longest axis
//! of their box, down to leaves of at most [`LEAF`] centers. Each node keeps, per displacement
//! component, the moments of its kernel weights `a_i` about its centroid `z` (`δ_i = c_i − z`,
//! `ρ = max |δ_i|`) up to the third order. With `u = y − z`, `r = |u|` and `φ(x) = |x|³`,
//! Taylor's expansion of `φ(u − δ)` to the third order gives the node's sum
//!
//! ```text
//! Σ a_i φ(y − c_i) ≈ M0 r³ − 3 r (u·M1) + 3/2 (r tr M2 + uᵀ M2 u / r)
//!                    − 1/2 (3 (u·m3) / r − M3[u,u,u] / r³)
//! M0 = Σ a,  M1 = Σ a δ,  M2 = Σ a δ δᵀ,  m3 = Σ a δ |δ|²,  M3 = Σ a δ⊗δ⊗δ
//! ```
//!
//! **Error bound.** Along a line, the fourth derivative of `|x|³` is `9 (1 − cos²)² / |x|`, at
//! most `9 / |x|`, and on the segment from `u` to `u − δ_i` the distance to the origin is at
//! least `r − ρ`. The remainder of each term is therefore at most `3/8 |a_i| |δ_i|⁴ / (r − ρ)`,
//! and the node's at most `3/8 A4 / (r − ρ)` with `A4 = Σ |a_i| |δ_i|⁴` kept per node.
//!
//! **Tolerance.** A node of `m` of the `n` centers gets the share `τ m / n` of the tolerance
//! `τ`, and its expansion is used only where its bound fits that share: `r ≥ ρ + 3/8 A4 / (τ m
//! / n)` (per node, one precomputed radius). The nodes used at a point hold disjoint sets of
//! centers, so their bounds add up to at most `τ`, and the rest is summed exactly (leaves, by
//! the vector kernel of `field::simd`). Nodes of fewer than `MIN_EXPANDED` centers are
//! never expanded: an expansion takes some 150 scalar operations per component, about what the
//! vector kernel spends on 100 centers (an estimate from the kernel's measured rate, not a
//! measurement of the expansion).
//!
//! **What it buys, measured** (`tools/exact`, the 480k-vertex dragon bent at 5.5k cells; see
//! `BENCHMARKS.md`): nothing there. The triharmonic weights cancel terms some 10⁴ times larger
//! than the result, so `A4` is large: at a tolerance of 1 % of the extent the first node may be
//! expanded 90 extents from the model, at 1e-4 9,000 extents. Points where no node can be
//! expanded ([`FarField::expands_at`], one test per point) take the exact vector sum, so the
//! option costs nothing there. Nodes are chosen by the error bound, not by an opening angle
//! alone (which errs by up to 86 % of the extent; BENCHMARKS.md §13), so a tolerance the user
//! sets cannot be exceeded.

#![allow(clippy::needless_range_loop)]

/// Leaves hold at most this many centers.
pub const LEAF: usize = 24;

/// Nodes of fewer centers are summed exactly, never expanded.
pub(crate) const MIN_EXPANDED: usize = 96;

/// The hierarchy over the centers of an RBF, with its weights.
#[derive(Clone)]
pub struct FarField<const D: usize> {
    /// Centers in the tree's order, axis by axis (scaled).
    centers: [Vec<f64>; D],
    /// Weights in the tree's order, component by component.
    weights: [Vec<f64>; D],
    nodes: Vec<Node<D>>,
    /// Within this distance of the root's centroid no node's expansion can be used: every
    /// center is summed exactly there ([`Self::expands_at`]).
    near: f64,
}

#[derive(Clone)]
struct Node<const D: usize> {
    start: usize,
    end: usize,
    /// Child node indices; `None` for a leaf.
    children: Option<[usize; 2]>,
    z: [f64; D],
    rho: f64,
    /// The distance from `z` from which the expansion is used (`∞`: never).
    accept: f64,
    /// Per component `k`: the moments of the module docs.
    m0: [f64; D],
    m1: [[f64; D]; D],
    m2: [[[f64; D]; D]; D],
    m3v: [[f64; D]; D],
    m3: [[[[f64; D]; D]; D]; D],
    a4: [f64; D],
}

impl<const D: usize> FarField<D> {
    /// The hierarchy over `centers` (axis by axis) with kernel `weights` (component by
    /// component), whose sums err by at most `tolerance` per component.
    pub fn new(centers: [&[f64]; D], weights: [&[f64]; D], tolerance: f64) -> Self {
        let n = centers[0].len();
        let mut order: Vec<usize> = (0..n).collect();
        let mut nodes = Vec::new();
        split(&centers, &mut order, 0, &mut nodes);
        let centers: [Vec<f64>; D] =
            std::array::from_fn(|a| order.iter().map(|&i| centers[a][i]).collect());
        let weights: [Vec<f64>; D] =
            std::array::from_fn(|k| order.iter().map(|&i| weights[k][i]).collect());
        for node in &mut nodes {
            node.moments(&centers, &weights);
            let count = node.end - node.start;
            let share = tolerance.max(0.0) * count as f64 / n.max(1) as f64;
            let a4 = node.a4.iter().cloned().fold(0.0, f64::max);
            node.accept = if count < MIN_EXPANDED || share <= 0.0 {
                f64::INFINITY
            } else {
                node.rho + 0.375 * a4 / share
            };
        }
        // No node is used at points nearer than this to the root's centroid.
        let root = nodes[0].z;
        let near = nodes
            .iter()
            .map(|node| {
                let offset: f64 = (0..D).map(|a| (node.z[a] - root[a]).powi(2)).sum();
                node.accept - offset.sqrt()
            })
            .fold(f64::INFINITY, f64::min);
        Self {
            centers,
            weights,
            nodes,
            near: near * (1.0 - 1e-9),
        }
    }

    /// Whether some node's expansion may be used at `y`; where not, [`Self::sum`] is the exact
    /// sum and callers may use a faster exact evaluation. `r(y, z) ≤ |y − z_root| + |z_root −
    /// z|`, so no node is used while `|y − z_root|` stays below every node's `accept − |z_root
    /// − z|`.
    #[inline]
    pub fn expands_at(&self, y: &[f64; D]) -> bool {
        let root = &self.nodes[0].z;
        let r2: f64 = (0..D).map(|a| (y[a] - root[a]).powi(2)).sum();
        self.near <= 0.0 || r2 >= self.near * self.near
    }

    /// The distance from the root's centroid within which no expansion is used.
    pub fn reach(&self) -> f64 {
        self.near
    }

    /// `Σ_i a_ki |y − c_i|³` for each component `k`, within the tolerance.
    #[inline]
    pub fn sum(&self, y: &[f64; D]) -> [f64; D] {
        self.sum_with_bound(y).0
    }

    /// [`Self::sum`] and the bound on the error of each component (at most the tolerance).
    pub fn sum_with_bound(&self, y: &[f64; D]) -> ([f64; D], [f64; D]) {
        let mut sums = [0.0; D];
        let mut bound = [0.0; D];
        let mut stack = [0usize; 128];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top]];
            let u: [f64; D] = std::array::from_fn(|a| y[a] - node.z[a]);
            let r = u.iter().map(|v| v * v).sum::<f64>().sqrt();
            if r > node.rho && r >= node.accept {
                let far = node.expansion(&u, r);
                for k in 0..D {
                    sums[k] += far[k];
                    bound[k] += 0.375 * node.a4[k] / (r - node.rho);
                }
            } else if let Some([left, right]) = node.children {
                stack[top] = right;
                stack[top + 1] = left;
                top += 2;
            } else {
                let range = node.start..node.end;
                let near = super::simd::sum::<D, D>(
                    y,
                    &self.centers.each_ref().map(|c| &c[range.clone()]),
                    &self.weights.each_ref().map(|w| &w[range.clone()]),
                );
                for k in 0..D {
                    sums[k] += near[k];
                }
            }
        }
        (sums, bound)
    }
}

/// Appends the node over `order[..]` (which starts at `start` of the whole order) and its
/// subtree to `nodes`; returns its index.
fn split<const D: usize>(
    centers: &[&[f64]; D],
    order: &mut [usize],
    start: usize,
    nodes: &mut Vec<Node<D>>,
) -> usize {
    let index = nodes.len();
    nodes.push(Node {
        start,
        end: start + order.len(),
        children: None,
        z: [0.0; D],
        rho: 0.0,
        accept: f64::INFINITY,
        m0: [0.0; D],
        m1: [[0.0; D]; D],
        m2: [[[0.0; D]; D]; D],
        m3v: [[0.0; D]; D],
        m3: [[[[0.0; D]; D]; D]; D],
        a4: [0.0; D],
    });
    if order.len() > LEAF {
        let mut lo = [f64::MAX; D];
        let mut hi = [f64::MIN; D];
        for &i in order.iter() {
            for a in 0..D {
                lo[a] = lo[a].min(centers[a][i]);
                hi[a] = hi[a].max(centers[a][i]);
            }
        }
        let axis = (0..D)
            .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
            .unwrap_or(0);
        let mid = order.len() / 2;
        order.select_nth_unstable_by(mid, |&i, &j| {
            centers[axis][i]
                .total_cmp(&centers[axis][j])
                .then(i.cmp(&j))
        });
        let (left, right) = order.split_at_mut(mid);
        let l = split(centers, left, start, nodes);
        let r = split(centers, right, start + mid, nodes);
        nodes[index].children = Some([l, r]);
    }
    index
}

impl<const D: usize> Node<D> {
    /// The centroid, radius and moments over the node's range.
    fn moments(&mut self, centers: &[Vec<f64>; D], weights: &[Vec<f64>; D]) {
        let range = self.start..self.end;
        let count = range.len() as f64;
        self.z = std::array::from_fn(|a| centers[a][range.clone()].iter().sum::<f64>() / count);
        for i in range {
            let d: [f64; D] = std::array::from_fn(|a| centers[a][i] - self.z[a]);
            let d2: f64 = d.iter().map(|v| v * v).sum();
            self.rho = self.rho.max(d2.sqrt());
            for k in 0..D {
                let w = weights[k][i];
                self.m0[k] += w;
                self.a4[k] += w.abs() * d2 * d2;
                for a in 0..D {
                    self.m1[k][a] += w * d[a];
                    self.m3v[k][a] += w * d[a] * d2;
                    for b in 0..D {
                        self.m2[k][a][b] += w * d[a] * d[b];
                        for c in 0..D {
                            self.m3[k][a][b][c] += w * d[a] * d[b] * d[c];
                        }
                    }
                }
            }
        }
    }

    /// The node's sum at `u = y − z`, `r = |u| > 0`, by its expansion.
    #[inline]
    fn expansion(&self, u: &[f64; D], r: f64) -> [f64; D] {
        let (inv, r3) = (1.0 / r, r * r * r);
        std::array::from_fn(|k| {
            let (mut u1, mut tr2, mut u2, mut u3v, mut u3) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for a in 0..D {
                u1 += u[a] * self.m1[k][a];
                tr2 += self.m2[k][a][a];
                u3v += u[a] * self.m3v[k][a];
                for b in 0..D {
                    u2 += u[a] * self.m2[k][a][b] * u[b];
                    for c in 0..D {
                        u3 += self.m3[k][a][b][c] * u[a] * u[b] * u[c];
                    }
                }
            }
            self.m0[k] * r3 - 3.0 * r * u1 + 1.5 * (r * tr2 + u2 * inv)
                - 0.5 * (3.0 * u3v * inv - u3 * inv * inv * inv)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::simd::slices;

    /// `Σ_i w_k[i] |y − c_i|³` term by term, and the same sum of `|w_k[i]|` terms (the scale of
    /// its rounding).
    fn exact<const D: usize>(
        y: &[f64; D],
        centers: &[Vec<f64>; D],
        weights: &[Vec<f64>; D],
    ) -> ([f64; D], [f64; D]) {
        let (mut sums, mut magnitude) = ([0.0; D], [0.0; D]);
        for i in 0..centers[0].len() {
            let r2: f64 = (0..D).map(|a| (y[a] - centers[a][i]).powi(2)).sum();
            let r3 = r2 * r2.sqrt();
            for k in 0..D {
                sums[k] += weights[k][i] * r3;
                magnitude[k] += weights[k][i].abs() * r3;
            }
        }
        (sums, magnitude)
    }

    /// One cluster seen from ever farther: the expansion is within its bound, and its error
    /// falls like `1/r` (the fourth-order remainder), where a wrong second- or third-order term
    /// would make it grow like `r` or stay flat.
    #[test]
    fn the_expansion_error_falls_with_distance() {
        let mut next = super::super::test_numbers(11);
        let n = 20;
        let centers: [Vec<f64>; 3] =
            std::array::from_fn(|_| (0..n).map(|_| 0.1 * next()).collect());
        let weights: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
        let tree = FarField::new(slices(&centers), slices(&weights), 1.0);
        let node = &tree.nodes[0];
        assert_eq!(node.end - node.start, n);
        for _ in 0..10 {
            let dir = [next(), next(), next()];
            let errors: Vec<f64> = [1.0, 10.0, 100.0]
                .iter()
                .map(|r| {
                    let y = dir.map(|v| v * r);
                    let u: [f64; 3] = std::array::from_fn(|a| y[a] - node.z[a]);
                    let r = u.iter().map(|v| v * v).sum::<f64>().sqrt();
                    let got = node.expansion(&u, r);
                    let (want, magnitude) = exact(&y, &centers, &weights);
                    (0..3)
                        .map(|k| {
                            let e = (got[k] - want[k]).abs();
                            let bound = 0.375 * node.a4[k] / (r - node.rho);
                            assert!(e <= bound + 1e-14 * magnitude[k], "{e} > {bound}");
                            e
                        })
                        .fold(0.0, f64::max)
                })
                .collect();
            assert!(
                errors[1] < 0.2 * errors[0] && errors[2] < 0.2 * errors[1],
                "{errors:?}"
            );
        }
    }

    /// Random centers and weights, points near and far: every component is within the
    /// tolerance of the exact sum, loose tolerances do expand nodes (the bound is used), and a
    /// zero tolerance sums every center exactly.
    #[test]
    fn the_far_field_stays_within_its_tolerance() {
        let mut next = super::super::test_numbers(5);
        let n = 3000;
        let centers: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
        let weights: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
        let points: Vec<[f64; 3]> = (0..300)
            .map(|i| {
                let s = [1.0, 10.0, 1000.0][i % 3];
                [s * next(), s * next(), s * next()]
            })
            .collect();
        // A tolerance beyond every node's bound: expansions are used even at the centroid.
        let loose = FarField::new(slices(&centers), slices(&weights), 1e12);
        assert!(loose.reach() < 0.0 && loose.expands_at(&loose.nodes[0].z));
        for tolerance in [10.0, 1.0, 0.1, 0.0] {
            let tree = FarField::new(slices(&centers), slices(&weights), tolerance);
            let mut used = 0.0f64;
            for y in &points {
                let (got, bound) = tree.sum_with_bound(y);
                let (want, magnitude) = exact(y, &centers, &weights);
                for k in 0..3 {
                    let rounding = 1e-14 * magnitude[k];
                    assert!(bound[k] <= tolerance * (1.0 + 1e-12), "τ = {tolerance}");
                    assert!(
                        (got[k] - want[k]).abs() <= bound[k] + rounding,
                        "τ = {tolerance}: {} > {}",
                        (got[k] - want[k]).abs(),
                        bound[k]
                    );
                    used = used.max(bound[k]);
                }
            }
            assert!(!tree.expands_at(&tree.nodes[0].z) || tolerance > 0.0);
            if tolerance == 0.0 {
                assert_eq!(used, 0.0);
            } else {
                assert!(used > 0.0, "τ = {tolerance}: no node was expanded");
            }
        }
    }
}
