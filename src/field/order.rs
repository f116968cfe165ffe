//! A spatially coherent order for evaluating a run of samples.
//!
//! The transfers evaluate fastest on samples that come near one another: the blend reuses a
//! sample's nearest centers for the next, the partition of unity sums each patch's fit once for
//! all the samples of a run it weighs, and the exact regions hand the transfer whole runs of
//! free samples. A file's records come in any order (flight lines, time, merged tiles, other
//! tools' output), so [`apply_into`](super::apply_into) evaluates each run in the order of
//! [`Order`] (a Morton order, unless the samples' own is coherent already) and scatters the
//! results back into the records' order: every result depends on its own sample alone, so the
//! order changes no bit, only the time.

use crate::rigid::Vect;

/// Bits of the Morton key: `30 / D` per axis (1,024 steps along the longest extent in 3D).
const BITS: u32 = 30;

/// Bits sorted per pass of the radix sort.
const DIGIT: u32 = 15;

/// An evaluation order of a run of samples and its inverse; both empty where the samples'
/// own order is coherent already.
#[derive(Debug, Clone, Default)]
pub struct Order {
    /// The samples' indices in the order they are evaluated.
    pub(crate) order: Vec<u32>,
    /// Where each sample comes in `order`.
    pub(crate) place: Vec<u32>,
}

impl Order {
    /// The coherent order of `points`, in the buffers of `self`: their Morton keys
    /// (`morton_keys`) sorted by two passes of a radix sort, samples of one cube in their own
    /// order; or none (their own order) where at most one in 8 (`KEEP`) consecutive samples
    /// crosses into another cube of a 64-step grid: a scan, or a file sorted into strips, costs
    /// nothing to sort then.
    pub fn compute<const D: usize>(&mut self, points: &[Vect<D>]) {
        self.order.clear();
        self.place.clear();
        // The indices are 32-bit: a run longer than that keeps its own order.
        if u32::try_from(points.len()).is_err() {
            return;
        }
        let keys = morton_keys(points);
        let coarse = |k: u32| k >> (D as u32 * (BITS / D as u32 - 6));
        let crossings = keys
            .windows(2)
            .filter(|w| coarse(w[0]) != coarse(w[1]))
            .count();
        if crossings * KEEP <= keys.len() {
            return;
        }
        let mut by_low = Vec::new();
        counting_sort(0..keys.len() as u32, &keys, 0, &mut by_low);
        counting_sort(by_low.into_iter(), &keys, DIGIT, &mut self.order);
        self.place.resize(self.order.len(), 0);
        for (k, &i) in self.order.iter().enumerate() {
            self.place[i as usize] = k as u32;
        }
    }

    /// The coherent order of `points`.
    pub fn of<const D: usize>(points: &[Vect<D>]) -> Self {
        let mut order = Self::default();
        order.compute(points);
        order
    }
}

/// Samples in their own order are coherent when at most one in this many crosses into another
/// cube of the coarse grid.
const KEEP: usize = 8;

/// The Morton keys of `points` on a grid over their bounding box (`2^(30 / D)` cubes along its
/// longest extent). Samples with a coordinate that is not finite have key 0.
fn morton_keys<const D: usize>(points: &[Vect<D>]) -> Vec<u32> {
    let bits = BITS / D as u32;
    let side = 1u32 << bits;
    let mut lo = Vect::<D>::repeat(f64::INFINITY);
    let mut hi = Vect::<D>::repeat(f64::NEG_INFINITY);
    for p in points.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let longest = (hi - lo).max();
    let scale = if longest > 0.0 && longest.is_finite() {
        side as f64 / longest
    } else {
        0.0
    };
    // `spread[q]`: the bits of `q` moved `D` places apart.
    let spread: Vec<u32> = (0..side)
        .map(|q| (0..bits).map(|b| ((q >> b) & 1) << (b * D as u32)).sum())
        .collect();
    points
        .iter()
        .map(|p| {
            let mut key = 0;
            for a in 0..D {
                // `as` saturates: NaN to 0, the far side of the box to `side`, clamped below.
                let q = (((p[a] - lo[a]) * scale) as u32).min(side - 1);
                key |= spread[q as usize] << a;
            }
            key
        })
        .collect()
}

/// `indices` stably sorted by the digit of `keys` at `shift`, into `out`.
fn counting_sort(
    indices: impl Iterator<Item = u32> + Clone,
    keys: &[u32],
    shift: u32,
    out: &mut Vec<u32>,
) {
    let digit = |i: u32| ((keys[i as usize] >> shift) & ((1 << DIGIT) - 1)) as usize;
    let mut start = vec![0u32; (1 << DIGIT) + 1];
    for i in indices.clone() {
        start[digit(i) + 1] += 1;
    }
    for d in 1..start.len() {
        start[d] += start[d - 1];
    }
    out.clear();
    out.resize(keys.len(), 0);
    for i in indices {
        let at = &mut start[digit(i)];
        out[*at as usize] = i;
        *at += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_order_is_a_permutation_that_groups_neighbors() {
        let mut next = crate::field::test_numbers(7);
        let mut points: Vec<Vect<3>> = (0..5000)
            .map(|_| Vect::<3>::new(100.0 * next(), 100.0 * next(), next()))
            .collect();
        points.push(Vect::<3>::new(f64::NAN, 0.0, 0.0));
        points.push(Vect::<3>::new(f64::INFINITY, 0.0, 0.0));
        let order = Order::of(&points).order;
        let mut seen = order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..points.len() as u32).collect::<Vec<_>>());
        // Consecutive finite samples in the new order are far closer than in the old.
        let step = |ix: &mut dyn Iterator<Item = usize>| {
            let ix: Vec<usize> = ix.filter(|&i| i < 5000).collect();
            ix.windows(2)
                .map(|w| (points[w[0]] - points[w[1]]).norm())
                .sum::<f64>()
                / ix.len() as f64
        };
        let before = step(&mut (0..points.len()));
        let after = step(&mut order.iter().map(|&i| i as usize));
        assert!(after < before / 10.0, "{after} vs {before}");
        // A scan, row after row, keeps its own order.
        let scan: Vec<Vect<3>> = (0..5000)
            .map(|i| Vect::<3>::new((i % 1000) as f64 * 0.1, (i / 1000) as f64 * 0.1, 0.0))
            .collect();
        assert!(Order::of(&scan).order.is_empty());
    }
}
