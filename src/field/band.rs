//! The band where an exact region's map blends into the field (see the module docs of
//! [`super::exact`]): the weight's profile across it, and the regions of prescribed cells grown
//! by one voxel, from which a sample's weight is found.

use rustc_hash::FxHashMap;

use super::UNPRESCRIBED;
use super::leaves::{Leaves, for_each_shell};

/// `10t³ − 15t⁴ + 6t⁵`: 0 at 0, 1 at 1, with zero first and second derivatives at both.
#[inline]
pub(super) fn smooth(t: f64) -> f64 {
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

/// Where the transfer meets a region it has already left the region's map by about half the
/// first free cell's motion: its rate times this fraction of the band (see the module docs).
pub(super) const HEAD_START: f64 = 0.5 / (2 * GROW) as f64;

/// The band of a region with a border, in smallest cells, over which its profile takes up a head
/// start of a whole cell (the most the transfer can lead such a region by): measured from the
/// region itself it costs no more than a narrower one (no masks), and the map's rate peaks at
/// 1.33 times the field's over it, where over two cells it would reach 1.61.
pub(super) const SHAPE_BAND: f64 = 4.0;

/// The band's profile takes the field up over this fraction of it at each end (see the module
/// docs).
pub(super) const EASE: f64 = 0.1;

/// `∫₀ᵗ smooth`.
#[inline]
fn smooth_integral(t: f64) -> f64 {
    t * t * t * t * (2.5 + t * (-3.0 + t))
}

/// The `t` in `[0, 1]` with `smooth(t) = v`.
pub(super) fn smooth_inverse(v: f64) -> f64 {
    if v <= 0.0 {
        return 0.0;
    }
    if v >= 1.0 {
        return 1.0;
    }
    // Near its ends `smooth` is cubic; Newton's method from there converges in a few steps.
    let mut t = if v < 0.5 {
        (0.1 * v).cbrt()
    } else {
        1.0 - (0.1 * (1.0 - v)).cbrt()
    };
    for _ in 0..8 {
        let slope = 30.0 * t * t * (1.0 - t) * (1.0 - t);
        if slope < 1e-12 {
            break;
        }
        t = (t - (smooth(t) - v) / slope).clamp(0.0, 1.0);
    }
    t
}

/// How much of the field a sample takes where the kernel puts `v` of its mass outside a region:
/// `σ(u)` at `u = smooth⁻¹(v)`, the fraction of the band crossed at a flat border. `σ` makes the
/// map's rate `h = ((u + a) σ(u))'` for a field that leads the region's map by `a` of the band
/// ([`HEAD_START`]) and grows at a steady rate: `h` rises as `smooth` to its peak over the first
/// [`EASE`] of the band, holds it, and eases back to the field's own rate over the last.
pub(super) fn fall(v: f64) -> f64 {
    profile(smooth_inverse(v), HEAD_START)
}

/// `σ(u)`: the share of the field at `u` of the band from a region's border ([`fall`]).
pub(super) fn profile(u: f64, head_start: f64) -> f64 {
    if u <= 0.0 {
        return 0.0;
    }
    if u >= 1.0 {
        return 1.0;
    }
    let (a, e) = (head_start, EASE);
    // The peak that makes `∫₀¹ h = 1 + a`.
    let peak = (1.0 + a - 0.5 * e) / (1.0 - e);
    let integral = if u <= e {
        peak * e * smooth_integral(u / e)
    } else if u <= 1.0 - e {
        peak * (0.5 * e + u - e)
    } else {
        let t = (u - 1.0 + e) / e;
        peak * (1.0 - 1.5 * e) + e * (peak * t - (peak - 1.0) * smooth_integral(t))
    };
    (integral / (u + a)).clamp(0.0, 1.0)
}

/// The regions grown by one voxel (see the module docs): for each voxel around a prescribed
/// cell, `maps[start..start + len]`, the maps of the prescribed cells it touches (itself
/// possibly inside another prescribed cell).
pub(super) struct Bands<const D: usize> {
    pub(super) shell: FxHashMap<[i64; D], (u32, u32)>,
    pub(super) maps: Vec<u32>,
}

/// For a voxel near a region: up to four maps, each with the mask of the voxel's neighbors that
/// lie in the map's grown region (bit `k` for neighbor `k`, offsets `o ∈ {−1, 0, 1}^D`,
/// `k = Σ_a (o_a + 1)·3^a`).
pub(super) type Masks = ([(u32, u32); 4], usize);

/// A region grows by this many voxels, and the kernel reaches this many voxels each way: the
/// band is `2·GROW` of the smallest cells wide (the masks and the masses are written for 1).
pub(super) const GROW: usize = 1;

/// The neighbors along one axis, the voxel itself included.
pub(super) const SIDE: usize = 2 * GROW + 1;

/// How many neighbors a voxel has, itself included (`SIDE^D`), by dimension.
pub(super) const NEIGHBORS: [u32; 4] = [
    1,
    SIDE as u32,
    (SIDE * SIDE) as u32,
    (SIDE * SIDE * SIDE) as u32,
];

/// The voxel `v` moved by neighbor `k`'s offsets (see [`Bands`]).
pub(super) fn neighbor<const D: usize>(v: &[i64; D], mut k: usize) -> [i64; D] {
    std::array::from_fn(|a| {
        let o = (k % SIDE) as i64 - GROW as i64;
        k /= SIDE;
        v[a] + o
    })
}

/// The regions of the prescribed cells grown by one voxel (see the module docs).
pub(super) fn bands<const D: usize>(leaves: &Leaves<D>, cells: &[u32]) -> Bands<D> {
    use rayon::prelude::*;
    let mut shell: Vec<([i64; D], u32)> = Vec::new();
    for (c, &m) in cells.iter().enumerate() {
        if m == UNPRESCRIBED {
            continue;
        }
        let (shift, coord) = leaves.keys[c];
        let lo = coord.map(|k| k << shift);
        let hi = coord.map(|k| ((k + 1) << shift) - 1);
        for_each_shell(lo.map(|k| k - 1), hi.map(|k| k + 1), Some((lo, hi)), |v| {
            shell.push((v, m));
        });
    }
    shell.par_sort_unstable();
    shell.dedup();
    let mut voxels = FxHashMap::default();
    voxels.reserve(shell.len());
    let mut maps = Vec::with_capacity(shell.len());
    let mut start = 0;
    while start < shell.len() {
        let v = shell[start].0;
        let first = maps.len() as u32;
        while start < shell.len() && shell[start].0 == v {
            maps.push(shell[start].1);
            start += 1;
        }
        voxels.insert(v, (first, maps.len() as u32 - first));
    }
    Bands {
        shell: voxels,
        maps,
    }
}

/// The weights of the `n` regions whose bands meet at one point, combined: each region's
/// weight `w_r` counts as `w_r Π_{q≠r} (1 − w_q)` and the field's as `Π_q (1 − w_q)`, over
/// their sum. A region at its own border (`w_r = 1`) then has the whole weight whatever the
/// others' (so its map is continuous there), and where one band alone reaches its weight is
/// its own. Returns how many weights stay positive, moved to the front.
pub(super) fn combine(sums: &mut [(u32, f64); 8], n: usize) -> usize {
    if n < 2 {
        return n;
    }
    let rest: f64 = sums[..n].iter().map(|s| 1.0 - s.1).product();
    let mut share = [0.0f64; 8];
    for i in 0..n {
        share[i] = sums[i].1
            * (0..n)
                .filter(|&j| j != i)
                .map(|j| 1.0 - sums[j].1)
                .product::<f64>();
    }
    let total = rest + share[..n].iter().sum::<f64>();
    for i in 0..n {
        sums[i].1 = if total > 0.0 {
            share[i] / total
        } else {
            // Two regions whole at once (their borders touch): shared evenly.
            f64::from(u8::from(sums[i].1 == 1.0))
                / sums[..n].iter().filter(|s| s.1 == 1.0).count() as f64
        };
    }
    let mut kept = 0;
    for i in 0..n {
        if sums[i].1 > 0.0 {
            sums[kept] = sums[i];
            kept += 1;
        }
    }
    kept
}

#[cfg(test)]
#[path = "band_tests.rs"]
mod tests;
