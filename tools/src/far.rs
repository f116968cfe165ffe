//! The RBF's sum over centers with the far field approximated over a hierarchy of the centers
//! (Barnes–Hut), as issue 5 proposed: built and measured by `tools/exact`, and not shipped.
//!
//! **Why not.** On the dragon at 5.5k cells (`tools/exact`) the approximation errs by 22 %, 64 %
//! and 86 % of the model's extent at opening angles 0.3, 0.5 and 0.7. It took 1.97, 1.02 and
//! 0.62 s for 480k points with the library's vector kernel summing the leaves (before this
//! module moved out of the library; here the leaves are summed by a scalar loop), against 0.74 s
//! for the exact vectorized sum of every center: the triharmonic
//! weights cancel terms some 10⁴ times larger than the result, so truncated moments err by a
//! large fraction of the result, and at the cell counts a dense factorization allows the exact
//! sum is as fast. A far field would need expansions of far higher order (a fast multipole
//! method for `r³`) to be both accurate and worth it.
//!
//! The centers are split recursively at the median of the longest axis of their box, down to
//! leaves of at most [`LEAF`] centers. Each node keeps, per displacement component, the moments
//! of its kernel weights `a_i` about its centroid `z` (`δ_i = c_i − z`, `ρ = max |δ_i|`) up to
//! the third order. With `u = y − z`, `r = |u|` and `φ(x) = |x|³`, Taylor's expansion of
//! `φ(u − δ)` to the third order gives the node's sum
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
//! and the node's at most `3/8 A4 / (r − ρ)` with `A4 = Σ |a_i| |δ_i|⁴` kept per node. A node is
//! used whole when `ρ ≤ θ r` (the opening angle `θ`; `r > ρ` always); `Tree::sum` returns
//! the sum of the used nodes' bounds with the value, a guaranteed bound on the approximation
//! error at that point (rounding aside). Otherwise the node is opened, and a leaf is summed
//! exactly. With `θ = 0` only single-center nodes are expanded, exactly.

#![allow(clippy::needless_range_loop)]

/// Leaves hold at most this many centers.
pub const LEAF: usize = 24;

/// The hierarchy over the centers of an RBF, with its weights.
pub struct Tree<const D: usize> {
    /// Centers in the tree's order, axis by axis (scaled).
    centers: [Vec<f64>; D],
    /// Weights in the tree's order, component by component.
    weights: [Vec<f64>; D],
    nodes: Vec<Node<D>>,
    theta: f64,
}

struct Node<const D: usize> {
    start: usize,
    end: usize,
    /// Child node indices; `None` for a leaf.
    children: Option<[usize; 2]>,
    z: [f64; D],
    rho: f64,
    /// Per component `k`: the moments of the module docs.
    m0: [f64; D],
    m1: [[f64; D]; D],
    m2: [[[f64; D]; D]; D],
    m3v: [[f64; D]; D],
    m3: [[[[f64; D]; D]; D]; D],
    a4: [f64; D],
}

impl<const D: usize> Tree<D> {
    /// The hierarchy over `centers` (axis by axis) with kernel `weights` (component by
    /// component), opened at angle `theta`.
    pub fn new(centers: &[Vec<f64>; D], weights: &[Vec<f64>; D], theta: f64) -> Self {
        let n = centers[0].len();
        let mut order: Vec<usize> = (0..n).collect();
        let mut nodes = Vec::new();
        split(centers, &mut order, 0, &mut nodes);
        let centers: [Vec<f64>; D] =
            std::array::from_fn(|a| order.iter().map(|&i| centers[a][i]).collect());
        let weights: [Vec<f64>; D] =
            std::array::from_fn(|k| order.iter().map(|&i| weights[k][i]).collect());
        for node in &mut nodes {
            node.moments(&centers, &weights);
        }
        Self {
            centers,
            weights,
            nodes,
            theta: theta.max(0.0),
        }
    }

    /// `Σ_i a_ki |y − c_i|³` for each component `k`, and a bound on the error of each.
    pub fn sum(&self, y: &[f64; D]) -> ([f64; D], [f64; D]) {
        let mut sums = [0.0; D];
        let mut bound = [0.0; D];
        let mut stack = [0usize; 128];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top]];
            let u: [f64; D] = std::array::from_fn(|a| y[a] - node.z[a]);
            let r = u.iter().map(|v| v * v).sum::<f64>().sqrt();
            if r > node.rho && node.rho <= self.theta * r {
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
                let near = exact_sum(y, &self.centers, &self.weights, node.start..node.end);
                for k in 0..D {
                    sums[k] += near[k];
                }
            }
        }
        (sums, bound)
    }

    /// The exact sum over the tree's centers (for comparisons).
    pub fn exact(&self, y: &[f64; D]) -> [f64; D] {
        exact_sum(y, &self.centers, &self.weights, 0..self.centers[0].len())
    }
}

/// `Σ_i w_k[i] |y − c_i|³` over the centers `range`.
fn exact_sum<const D: usize>(
    y: &[f64; D],
    centers: &[Vec<f64>; D],
    weights: &[Vec<f64>; D],
    range: std::ops::Range<usize>,
) -> [f64; D] {
    let mut sums = [0.0; D];
    for i in range {
        let r2: f64 = (0..D).map(|a| (y[a] - centers[a][i]).powi(2)).sum();
        let r3 = r2 * r2.sqrt();
        for k in 0..D {
            sums[k] += weights[k][i] * r3;
        }
    }
    sums
}

/// Appends the node over `order[..]` (which starts at `start` of the whole order) and its
/// subtree to `nodes`; returns its index.
fn split<const D: usize>(
    centers: &[Vec<f64>; D],
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

    /// Numbers in `[-1, 1)`, seeded.
    fn random() -> impl FnMut() -> f64 {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(0x2545_f491_4f6c_dd1d);
        move || rng.random_range(-1.0..1.0)
    }

    /// One cluster seen from ever farther: the expansion's error falls like `1/r` (the
    /// fourth-order remainder), where a wrong second- or third-order term would make it grow
    /// like `r` or stay flat.
    #[test]
    fn the_expansion_error_falls_with_distance() {
        let mut next = random();
        let n = 20;
        let centers: [Vec<f64>; 3] =
            std::array::from_fn(|_| (0..n).map(|_| 0.1 * next()).collect());
        let weights: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
        let tree = Tree::new(&centers, &weights, 1.0);
        for _ in 0..10 {
            let dir = [next(), next(), next()];
            let errors: Vec<f64> = [1.0, 10.0, 100.0]
                .iter()
                .map(|r| {
                    let y = dir.map(|v| v * r);
                    let (got, bound) = tree.sum(&y);
                    let exact = tree.exact(&y);
                    (0..3)
                        .map(|k| {
                            let e = (got[k] - exact[k]).abs();
                            assert!(e <= bound[k] * (1.0 + 1e-6), "{e} > {}", bound[k]);
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

    /// Random centers and weights: the approximation is within its stated bound everywhere,
    /// the bound shrinks with the angle, and `θ = 0` is the exact sum to rounding.
    #[test]
    fn the_far_field_stays_within_its_bound() {
        let mut next = random();
        let n = 3000;
        let centers: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
        let weights: [Vec<f64>; 3] = std::array::from_fn(|_| (0..n).map(|_| next()).collect());
        let abs: [Vec<f64>; 3] = weights.clone().map(|w| w.iter().map(|v| v.abs()).collect());
        let points: Vec<[f64; 3]> = (0..200).map(|_| [next(), next(), 1.5 * next()]).collect();
        let mut previous = f64::MAX;
        for theta in [0.7, 0.5, 0.3, 0.0] {
            let tree = Tree::new(&centers, &weights, theta);
            let mut worst_bound = 0.0f64;
            for y in &points {
                let (got, bound) = tree.sum(y);
                let exact = tree.exact(y);
                let magnitude = exact_sum(y, &centers, &abs, 0..n);
                for k in 0..3 {
                    let rounding = 1e-14 * magnitude[k];
                    assert!(
                        (got[k] - exact[k]).abs() <= bound[k] + rounding,
                        "θ = {theta}"
                    );
                    worst_bound = worst_bound.max(bound[k]);
                }
            }
            if theta == 0.0 {
                assert_eq!(worst_bound, 0.0);
            } else {
                assert!(worst_bound > 0.0 && worst_bound < previous, "θ = {theta}");
            }
            previous = worst_bound;
        }
    }
}
