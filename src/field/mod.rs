//! Transfer of the cells' rigid motions to the samples (paper §6; docs/ARCHITECTURE.md, the
//! stages).
//!
//! A [`Field`] is the solved state that defines the space warp: the cells' rest centers and
//! rigid motions in the local frame. Two transfers turn it into a map of space:
//!
//! - [`Blend`] (preview, fast): `x' = Σ w_k T_k(x) / Σ w_k` over the `k = 4` nearest rest
//!   centers, `w_k = 1/d_k − 1/d_5` (continuous) or the paper's `w_k = 1/d_k`;
//! - [`Rbf`] (final, smooth): triharmonic `φ(r) = r³` plus a linear polynomial interpolating
//!   the center displacements `T_i(c_i) − c_i` exactly.
//!
//! Both implement [`Warp`], the one per-sample kernel; [`apply`] is the one driver that runs it
//! over a slice of world-coordinate samples in parallel, so in-memory and streaming callers give
//! identical results.

mod band;
mod blend;
mod domain;
mod exact;
pub mod far;
mod file;
pub mod grid;
mod leaves;
mod maps;
mod nearest;
mod order;
mod pu;
mod rbf;
mod simd;

pub use crate::spec::Shape;
pub use blend::{Blend, Weights};
pub use exact::{FieldMap, Frame, Outside, OutsideTally, Prescribed, UNPRESCRIBED};
pub use file::SavedField;
pub use nearest::{Anchor, NEAR, Nearest, Neighbors};
pub use order::Order;
pub use pu::{Layout, PuRbf};
pub use rbf::Rbf;

use rayon::prelude::*;

use crate::error::Result;
use crate::rigid::{Affine, Dim, Motion, Rigid, Vect};
use crate::solve::trend::TrendMap;
use crate::solve::{Role, Solution};

/// The solved deformation: cells and their rigid motions, in the local frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Field<const D: usize> {
    /// World position of the local frame's origin.
    pub origin: Vect<D>,
    /// Rest centers of the cells (local).
    pub centers: Vec<Vect<D>>,
    /// Half edge lengths of the cells.
    pub halves: Vec<f64>,
    /// Rigid motion of each cell (local).
    pub motions: Vec<Motion<D>>,
    /// The maps that the fixed and handle cells follow exactly ([`FieldMap`]).
    pub prescribed: Prescribed<D>,
    /// The field moves the horizontal coordinates only: every sample keeps its last
    /// coordinate (its height) as it came ([`FieldMap`]). So it is for a scan pulled by 2D
    /// control points alone ([`Field::from_solution`]), which prescribe no height.
    pub heights_kept: bool,
    /// The control points' trend `T` (local frame; `crate::solve::trend`): the transfer's
    /// values go through it, while the prescribed maps are the edit's own (the cells' motions
    /// are those of `F` in the edit `T ∘ F`). The identity without a trend.
    pub trend: TrendMap<D>,
}

impl<const D: usize> Field<D> {
    /// The cells' cubes' bounding box in world coordinates (`None` without cells).
    pub fn domain(&self) -> Option<(Vect<D>, Vect<D>)> {
        let mut lo = Vect::<D>::repeat(f64::INFINITY);
        let mut hi = Vect::<D>::repeat(f64::NEG_INFINITY);
        for (c, &h) in self.centers.iter().zip(&self.halves) {
            let world = self.origin + c;
            lo = lo.inf(&world.add_scalar(-h));
            hi = hi.sup(&world.add_scalar(h));
        }
        (!self.centers.is_empty()).then_some((lo, hi))
    }

    /// The cells' edge lengths, one per octree level they occupy, smallest first, with how
    /// many cells have each.
    pub fn cell_sizes(&self) -> Vec<(f64, usize)> {
        let mut sizes: Vec<(f64, usize)> = Vec::new();
        for &h in &self.halves {
            match sizes.iter_mut().find(|(s, _)| *s == 2.0 * h) {
                Some((_, n)) => *n += 1,
                None => sizes.push((2.0 * h, 1)),
            }
        }
        sizes.sort_by(|a, b| a.0.total_cmp(&b.0));
        sizes
    }

    /// The field of a solution: its fixed cells and the cells it kept at rest follow the
    /// identity exactly, each handle's cells its transform, and a pinned cell (its pinned
    /// point held where the pin sends it) and a carried part's cells their own rigid motion.
    pub fn from_solution(solution: &Solution<D>) -> Self
    where
        Dim<D>: Rigid<D>,
    {
        let constraints = &solution.constraints;
        let n = solution.complex.len();
        let maps: Vec<Affine<D>> = (0..constraints.handles.len())
            .map(|k| constraints.handle_map(k, 1.0))
            .collect();
        let mut prescribed = Prescribed::default();
        // The regions with a border take the cells whose centers they hold (the module docs of
        // `exact`); a role's other cells (of a connected part where its region holds no
        // center) are held whole.
        let origin = solution.complex.grid.origin;
        let shaped: Vec<Option<u32>> = constraints
            .region_roles()
            .map(|role| {
                let map = match role {
                    Role::Handle(k) => maps[k as usize],
                    _ => Affine::identity(),
                };
                let shape = constraints.shape_of(role)?;
                Some(prescribed.shaped(map, shape.clone()))
            })
            .collect();
        let inside = |role: Role, c: usize| {
            let k = match role {
                Role::Handle(k) => 1 + k as usize,
                _ => 0,
            };
            let shape = constraints.shape_of(role)?;
            let center = solution.complex.cells[c].center + origin;
            shaped[k].filter(|_| shape.contains(&center))
        };
        for (c, role) in constraints.roles.iter().enumerate() {
            match role {
                Role::Fixed => match inside(*role, c) {
                    Some(k) => prescribed.put(c, n, k),
                    None => prescribed.set(c, n, Affine::identity()),
                },
                Role::Handle(k) => match inside(*role, c) {
                    Some(m) => prescribed.put(c, n, m),
                    None => prescribed.set(c, n, maps[*k as usize]),
                },
                Role::Rest => prescribed.set(c, n, Affine::identity()),
                Role::Carried(_) | Role::Pin(_) => {
                    // The cell's rigid motion, exactly: A(x) = R (x − c) + p, after the trend.
                    let m = &solution.motions[c];
                    let center = solution.complex.cells[c].center;
                    let own = Affine {
                        linear: m.rot,
                        translation: m.pos - m.rot * center,
                    };
                    // After a trend, its first order about the cell's new center (a part's cells
                    // are small against the trend's curvature).
                    let map = match constraints.trend.is_identity() {
                        true => own,
                        false => constraints.trend.linearized(&m.pos).after(&own),
                    };
                    prescribed.set(c, n, map);
                }
                Role::Free => {}
            }
        }
        Self {
            origin: solution.complex.grid.origin,
            centers: solution.complex.cells.iter().map(|c| c.center).collect(),
            halves: solution.complex.cells.iter().map(|c| c.half).collect(),
            motions: solution.motions.clone(),
            prescribed,
            heights_kept: keeps_heights(constraints),
            trend: constraints.trend.clone(),
        }
    }
}

/// Whether the edit prescribes no height: 3D samples whose only constraints besides fixed
/// regions are 2D control points (`x, y → X, Y`, exact or not), which say nothing of the
/// heights. The solve still holds their heights lightly (so that the cells do not tilt to
/// shorten horizontal distances), but the cells' motions turn a little about horizontal axes
/// wherever the pull bends the scan, and that would move heights nobody asked to move (up to
/// 9 cm under a 0.3 m pull on a forest scan): such a field keeps every height as it came.
fn keeps_heights<const D: usize>(constraints: &crate::solve::Constraints<D>) -> bool {
    D == 3
        && constraints.handles.is_empty()
        && constraints.pins.iter().all(|p| p.target.is_some())
        && !constraints.targets.is_empty()
        && constraints.targets.iter().all(|t| t.mask[D - 1] < 1.0)
}

/// Which transfer to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Transfer {
    /// Continuous blend of the 4 nearest cells' motions (fast preview; [`Weights::Continuous`]).
    #[default]
    Blend,
    /// The paper's inverse-distance blend of the 4 nearest cells' motions
    /// ([`Weights::InverseDistance`]).
    BlendIdw,
    /// Triharmonic RBF interpolation of the cell-center displacements (smooth, final).
    Rbf,
    /// The partition-of-unity RBF: triharmonic fits on overlapping patches blended by C²
    /// weights ([`PuRbf`]; smooth, for any number of cells).
    Pu,
}

/// A map of space in the local frame: the per-sample kernel of every driver.
pub trait Warp<const D: usize>: Sync {
    /// Where the local point `x` goes.
    fn warp(&self, x: &Vect<D>) -> Vect<D>;

    /// The normal `n` at the local point `x` after the warp (the transpose of its inverse Jacobian), with `n`'s length.
    fn warp_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D>;

    /// Both [`Warp::warp`] and [`Warp::warp_normal`] at `x`; transfers that find neighbors
    /// per sample override it to find them once.
    fn warp_with_normal(&self, x: &Vect<D>, n: &Vect<D>) -> (Vect<D>, Vect<D>) {
        (self.warp(x), self.warp_normal(x, n))
    }

    /// The Jacobian of the map at the local point `x`, by central differences of step `h`
    /// (transfers with a closed form override it).
    fn jacobian(&self, x: &Vect<D>, h: f64) -> nalgebra::SMatrix<f64, D, D> {
        central_jacobian(self, x, h)
    }

    /// Moves the world-coordinate `points` into `out`, in order, through the local frame whose
    /// origin is `origin`: `out[i] = warp(points[i] − origin) + origin`. Transfers may reuse work
    /// between consecutive samples, but each result is [`Warp::warp`]'s, bit for bit, except
    /// that a sample the transfer leaves at rest may come back as it was (skipping the round
    /// trip through the local frame, which can change a last bit).
    fn warp_run(&self, origin: &Vect<D>, points: &[Vect<D>], out: &mut [Vect<D>]) {
        for (o, p) in out.iter_mut().zip(points) {
            *o = self.warp(&(p - origin)) + origin;
        }
    }

    /// [`Warp::warp_run`] with normals: `out[i], out_normals[i]` from
    /// [`Warp::warp_with_normal`] at `points[i] − origin`, with the same allowance for samples
    /// left at rest.
    fn warp_run_with_normals(
        &self,
        origin: &Vect<D>,
        points: &[Vect<D>],
        normals: &[Vect<D>],
        out: &mut [Vect<D>],
        out_normals: &mut [Vect<D>],
    ) {
        for (((o, on), p), n) in out.iter_mut().zip(out_normals).zip(points).zip(normals) {
            let (x, m) = self.warp_with_normal(&(p - origin), n);
            (*o, *on) = (x + origin, m);
        }
    }
}

/// The Jacobian of `warp` at the local point `x` by central differences of step `h`.
pub fn central_jacobian<const D: usize>(
    warp: &(impl Warp<D> + ?Sized),
    x: &Vect<D>,
    h: f64,
) -> nalgebra::SMatrix<f64, D, D> {
    let mut j = nalgebra::SMatrix::<f64, D, D>::zeros();
    for a in 0..D {
        let mut e = Vect::<D>::zeros();
        e[a] = h;
        let column = (warp.warp(&(x + e)) - warp.warp(&(x - e))) / (2.0 * h);
        j.set_column(a, &column);
    }
    j
}

/// A transfer built for a field, ready to warp samples.
pub enum Deformer<const D: usize> {
    /// See [`Blend`].
    Blend(Box<Blend<D>>),
    /// See [`Rbf`].
    Rbf(Rbf<D>),
    /// See [`PuRbf`].
    Pu(Box<PuRbf<D>>),
}

impl<const D: usize> Deformer<D> {
    /// Builds `transfer` for `field` (the RBF factors its dense system here).
    pub fn new(field: &Field<D>, transfer: Transfer) -> Result<Self> {
        Ok(match transfer {
            Transfer::Blend => Self::Blend(Box::new(Blend::new(field, Weights::Continuous)?)),
            Transfer::BlendIdw => {
                Self::Blend(Box::new(Blend::new(field, Weights::InverseDistance)?))
            }
            Transfer::Rbf => Self::Rbf(Rbf::new(field)?),
            Transfer::Pu => Self::Pu(Box::new(PuRbf::new(field)?)),
        })
    }

    /// As [`Deformer::new`], but the PU fits each patch only when a sample first needs it
    /// ([`PuRbf::lazy`]): for applying a field to a tile of what it covers.
    pub fn on_demand(field: &Field<D>, transfer: Transfer) -> Result<Self> {
        match transfer {
            Transfer::Pu => Ok(Self::Pu(Box::new(PuRbf::lazy(field)?))),
            t => Self::new(field, t),
        }
    }

    /// The RBF evaluated through its far field within `tolerance` ([`Rbf::with_tolerance`]);
    /// a blend, or no tolerance, is returned as it is.
    pub fn with_rbf_tolerance(self, tolerance: Option<f64>) -> Result<Self> {
        Ok(match (self, tolerance) {
            (Self::Rbf(r), Some(t)) => Self::Rbf(r.with_tolerance(t)?),
            (d, _) => d,
        })
    }
}

impl<const D: usize> Warp<D> for Deformer<D> {
    #[inline]
    fn warp(&self, x: &Vect<D>) -> Vect<D> {
        match self {
            Self::Blend(b) => b.warp(x),
            Self::Rbf(r) => r.warp(x),
            Self::Pu(p) => p.warp(x),
        }
    }

    #[inline]
    fn warp_normal(&self, x: &Vect<D>, n: &Vect<D>) -> Vect<D> {
        match self {
            Self::Blend(b) => b.warp_normal(x, n),
            Self::Rbf(r) => r.warp_normal(x, n),
            Self::Pu(p) => p.warp_normal(x, n),
        }
    }

    #[inline]
    fn warp_with_normal(&self, x: &Vect<D>, n: &Vect<D>) -> (Vect<D>, Vect<D>) {
        match self {
            Self::Blend(b) => b.warp_with_normal(x, n),
            Self::Rbf(r) => r.warp_with_normal(x, n),
            Self::Pu(p) => p.warp_with_normal(x, n),
        }
    }

    fn warp_run(&self, origin: &Vect<D>, points: &[Vect<D>], out: &mut [Vect<D>]) {
        match self {
            Self::Blend(b) => b.warp_run(origin, points, out),
            Self::Rbf(r) => r.warp_run(origin, points, out),
            Self::Pu(p) => p.warp_run(origin, points, out),
        }
    }

    fn jacobian(&self, x: &Vect<D>, h: f64) -> nalgebra::SMatrix<f64, D, D> {
        match self {
            Self::Blend(b) => b.jacobian(x, h),
            Self::Rbf(r) => Warp::jacobian(r, x, h),
            Self::Pu(p) => p.jacobian(x),
        }
    }
}

/// `v`, the normal `n` turned by a transfer, scaled to `n`'s length; `n` itself where `v` has
/// no direction (zero or not finite). A normal keeps its length through a deformation, whatever
/// it is (files hold unit normals, and others: area-weighted, or scaled by a tool), and a zero
/// normal stays zero. Lengths are taken without overflow, so the largest single-precision
/// normals (1e37 and past) stay finite.
#[inline]
pub(crate) fn normal_like<const D: usize>(v: Vect<D>, n: &Vect<D>) -> Vect<D> {
    let (turned, wanted) = (length(&v), length(n));
    if turned > 0.0 && turned.is_finite() && wanted.is_finite() {
        // `v / turned` is a unit vector, so the product stays within `wanted`.
        (v / turned) * wanted
    } else {
        *n
    }
}

/// The Euclidean length of `v`, with its largest component factored out where the sum of
/// squares would overflow (or underflow).
#[inline]
fn length<const D: usize>(v: &Vect<D>) -> f64 {
    let squares = v.norm_squared();
    if squares.is_finite() && squares >= f64::MIN_POSITIVE {
        return squares.sqrt();
    }
    let largest = v.amax();
    if largest > 0.0 && largest.is_finite() {
        largest * (v / largest).norm()
    } else {
        largest
    }
}

/// A deterministic stream of numbers in `[-1, 1)` (xorshift) for the unit tests of the
/// transfers.
#[cfg(test)]
pub(crate) fn test_numbers(seed: u64) -> impl FnMut() -> f64 {
    let mut x = seed;
    move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// Samples per parallel task.
const CHUNK: usize = 4096;

/// Moves world-coordinate `points` and their `normals` (empty, or one per point) by `warp`
/// into `moved` and `moved_normals`, in their coherent [`Order`] ([`apply_in_order`]).
pub fn apply_into<const D: usize>(
    warp: &impl Warp<D>,
    origin: &Vect<D>,
    points: &[Vect<D>],
    normals: &[Vect<D>],
    moved: &mut Vec<Vect<D>>,
    moved_normals: &mut Vec<Vect<D>>,
) {
    let order = Order::of(points);
    apply_in_order(warp, origin, points, normals, &order, moved, moved_normals);
}

/// Moves world-coordinate `points` and their `normals` (empty, or one per point) by `warp`
/// into `moved` and `moved_normals`, evaluating them in `order` (the [`Order`] of `points`; in
/// their own order where it is empty), in parallel over pieces of it, and gathering the results
/// back into the order of `points`: each sample's result depends on that sample alone, so
/// neither the order nor the pieces change a bit, and samples in any order cost what samples
/// in scan order cost.
pub fn apply_in_order<const D: usize>(
    warp: &impl Warp<D>,
    origin: &Vect<D>,
    points: &[Vect<D>],
    normals: &[Vect<D>],
    order: &Order,
    moved: &mut Vec<Vect<D>>,
    moved_normals: &mut Vec<Vect<D>>,
) {
    if order.order.is_empty() {
        moved.resize(points.len(), Vect::<D>::zeros());
        moved_normals.resize(normals.len(), Vect::<D>::zeros());
        warp_pieces(warp, origin, points, normals, moved, moved_normals);
        return;
    }
    let gather = |from: &[Vect<D>]| -> Vec<Vect<D>> {
        if from.is_empty() {
            return Vec::new();
        }
        order.order.par_iter().map(|&i| from[i as usize]).collect()
    };
    let scatter = |from: &[Vect<D>], to: &mut Vec<Vect<D>>| {
        to.resize(from.len(), Vect::<D>::zeros());
        to.par_iter_mut()
            .zip(&order.place)
            .for_each(|(v, &k)| *v = from[k as usize]);
    };
    let (xs, ns) = (gather(points), gather(normals));
    let mut ys = vec![Vect::<D>::zeros(); xs.len()];
    let mut ms = vec![Vect::<D>::zeros(); ns.len()];
    warp_pieces(warp, origin, &xs, &ns, &mut ys, &mut ms);
    scatter(&ys, moved);
    scatter(&ms, moved_normals);
}

/// `points` and `normals` (empty, or one per point) warped into `out` and `out_normals` (of
/// their lengths), in parallel over pieces of [`CHUNK`] samples.
fn warp_pieces<const D: usize>(
    warp: &impl Warp<D>,
    origin: &Vect<D>,
    points: &[Vect<D>],
    normals: &[Vect<D>],
    out: &mut [Vect<D>],
    out_normals: &mut [Vect<D>],
) {
    if normals.is_empty() {
        out.par_chunks_mut(CHUNK)
            .zip(points.par_chunks(CHUNK))
            .for_each(|(out, inp)| warp.warp_run(origin, inp, out));
        return;
    }
    out.par_chunks_mut(CHUNK)
        .zip(out_normals.par_chunks_mut(CHUNK))
        .zip(points.par_chunks(CHUNK).zip(normals.par_chunks(CHUNK)))
        .for_each(|((out, out_n), (ps, ns))| {
            warp.warp_run_with_normals(origin, ps, ns, out, out_n)
        });
}

/// Which of the world-coordinate `points` the map folds over (their indices, in order): where
/// the Jacobian determinant of `warp` (central differences of step `h`, or the closed form) is
/// not positive, space is turned inside out. Parallel.
pub fn foldovers<const D: usize>(
    warp: &impl Warp<D>,
    origin: &Vect<D>,
    points: &[Vect<D>],
    h: f64,
) -> Vec<usize> {
    points
        .par_iter()
        .enumerate()
        .filter(|(_, p)| {
            let det = determinant(&warp.jacobian(&(*p - origin), h));
            det.is_nan() || det <= 0.0
        })
        .map(|(i, _)| i)
        .collect()
}

/// The determinant of a small square matrix, by elimination with partial pivoting.
pub(crate) fn determinant<const D: usize>(m: &nalgebra::SMatrix<f64, D, D>) -> f64 {
    let mut a = *m;
    let mut det = 1.0;
    for k in 0..D {
        let p = (k..D)
            .max_by(|&i, &j| a[(i, k)].abs().total_cmp(&a[(j, k)].abs()))
            .expect("k < D");
        if a[(p, k)] == 0.0 {
            return 0.0;
        }
        if p != k {
            a.swap_rows(p, k);
            det = -det;
        }
        det *= a[(k, k)];
        for i in k + 1..D {
            let f = a[(i, k)] / a[(k, k)];
            for j in k..D {
                a[(i, j)] -= f * a[(k, j)];
            }
        }
    }
    det
}

/// Moves world-coordinate `points` in place by `warp`, whose local frame has its origin at
/// `origin` ([`apply_into`]).
pub fn apply<const D: usize>(warp: &impl Warp<D>, origin: &Vect<D>, points: &mut [Vect<D>]) {
    let mut moved = Vec::new();
    apply_into(warp, origin, points, &[], &mut moved, &mut Vec::new());
    points.copy_from_slice(&moved);
}
