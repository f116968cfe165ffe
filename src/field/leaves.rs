//! The leaves of an octree rebuilt from cell centers and sizes alone: what a saved field holds
//! is enough to locate samples among its cells with the same integer arithmetic in `deform` and
//! `apply` (used by [`super::FieldMap`]).

use rustc_hash::FxHashMap;

use super::Field;
use crate::cells::floor;
use crate::rigid::Vect;

/// The leaves of the octree the cells form, found from a voxel of the smallest cells' size.
pub(super) struct Leaves<const D: usize> {
    /// Lower corner of voxel 0 (local frame).
    pub(super) lower: Vect<D>,
    /// The smallest cells' edge.
    pub(super) edge: f64,
    /// Cell sizes present, as powers of two of `edge`, ascending.
    pub(super) shifts: Vec<u32>,
    /// `(shift, coordinates in cells of that size)` → cell.
    pub(super) map: FxHashMap<(u32, [i64; D]), u32>,
    /// Each cell's shift and coordinates.
    pub(super) keys: Vec<(u32, [i64; D])>,
}

impl<const D: usize> Leaves<D> {
    /// The octree of `centers` and `halves`, or why they are not the leaves of one.
    pub(super) fn new(centers: &[Vect<D>], halves: &[f64]) -> std::result::Result<Self, String> {
        let edge = 2.0 * halves.iter().cloned().fold(f64::INFINITY, f64::min);
        let (big, &top) = halves
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .ok_or("the field has no cells")?;
        if !(edge > 0.0 && edge.is_finite() && top.is_finite()) {
            return Err(format!(
                "cell sizes from {edge} to {} are not usable",
                2.0 * top
            ));
        }
        let largest = 2.0 * top;
        let mut low = Vect::<D>::repeat(f64::INFINITY);
        for (c, h) in centers.iter().zip(halves) {
            low = low.inf(&c.add_scalar(-h));
        }
        let anchor = centers[big].add_scalar(-top);
        let lower = Vect::<D>::from_fn(|a, _| {
            anchor[a] - largest * ((anchor[a] - low[a]) / largest).ceil()
        });
        Self::in_frame(centers, halves, lower, edge)
    }

    /// The octree of a part of a field's cells, on the whole field's grid: voxel 0 at `lower`,
    /// voxels of `edge` (what [`Leaves::new`] finds for the whole field), so that a window of
    /// the cells locates samples with the same arithmetic.
    pub(super) fn in_frame(
        centers: &[Vect<D>],
        halves: &[f64],
        lower: Vect<D>,
        edge: f64,
    ) -> std::result::Result<Self, String> {
        if centers.is_empty() {
            return Err("the field has no cells".into());
        }
        if !(edge > 0.0 && edge.is_finite() && lower.iter().all(|v| v.is_finite())) {
            return Err(format!("a grid of voxels of {edge} is not usable"));
        }
        let mut shifts = Vec::new();
        let mut map = FxHashMap::default();
        map.reserve(centers.len());
        let mut keys = Vec::with_capacity(centers.len());
        for (i, (c, &h)) in centers.iter().zip(halves).enumerate() {
            let size = 2.0 * h;
            let shift = (size / edge).log2().round();
            if !(0.0..=60.0).contains(&shift) || (edge * shift.exp2() - size).abs() > 1e-9 * size {
                return Err(format!(
                    "cell {i} of size {size} is not a power of two of {edge}"
                ));
            }
            let shift = shift as u32;
            let mut coord = [0i64; D];
            for a in 0..D {
                let t = (c[a] - h - lower[a]) / size;
                if !t.is_finite() || (t - t.round()).abs() > 1e-6 || t.abs() > 1e15 {
                    return Err(format!("cell {i} is not on the grid of the others"));
                }
                coord[a] = t.round() as i64;
            }
            if map.insert((shift, coord), i as u32).is_some() {
                return Err(format!("cell {i} repeats another"));
            }
            if !shifts.contains(&shift) {
                shifts.push(shift);
            }
            keys.push((shift, coord));
        }
        shifts.sort_unstable();
        Ok(Self {
            lower,
            edge,
            shifts,
            map,
            keys,
        })
    }

    /// The voxel of the local point `x` (non-finite coordinates give an arbitrary voxel).
    #[inline]
    pub(super) fn voxel(&self, x: &Vect<D>) -> [i64; D] {
        std::array::from_fn(|a| floor((x[a] - self.lower[a]) / self.edge))
    }

    /// The leaf holding voxel `v`.
    #[inline]
    pub(super) fn leaf(&self, v: &[i64; D]) -> Option<usize> {
        self.shifts
            .iter()
            .find_map(|&s| self.map.get(&(s, v.map(|c| c >> s))))
            .map(|&i| i as usize)
    }

    /// Whether a leaf holds the cell of size `2^shift` at `coord` or one of its ancestors.
    pub(super) fn covered(&self, shift: u32, coord: &[i64; D]) -> bool {
        self.shifts
            .iter()
            .filter(|&&s| s >= shift)
            .any(|&s| self.map.contains_key(&(s, coord.map(|c| c >> (s - shift)))))
    }
}

/// Whether the cells of `field` are the leaves of an octree, as [`super::FieldMap`] needs.
pub(crate) fn check_cells<const D: usize>(field: &Field<D>) -> std::result::Result<(), String> {
    Leaves::new(&field.centers, &field.halves).map(|_| ())
}

/// As [`check_cells`], for a window of a field's cells on the whole field's grid.
pub(crate) fn check_window_cells<const D: usize>(
    field: &Field<D>,
    lower: Vect<D>,
    edge: f64,
) -> std::result::Result<(), String> {
    Leaves::in_frame(&field.centers, &field.halves, lower, edge).map(|_| ())
}

/// Calls `f` for every voxel of the box `from ..= to` (inclusive) that is not inside
/// `inner_from ..= inner_to`.
pub(super) fn for_each_shell<const D: usize>(
    from: [i64; D],
    to: [i64; D],
    inner: Option<([i64; D], [i64; D])>,
    mut f: impl FnMut([i64; D]),
) {
    let mut v = from;
    loop {
        let inside = inner.is_some_and(|(lo, hi)| (0..D).all(|a| v[a] >= lo[a] && v[a] <= hi[a]));
        if inside {
            // Jump over the inner box along axis 0.
            v[0] = inner.expect("inside").1[0];
        } else {
            f(v);
        }
        let mut a = 0;
        loop {
            if a == D {
                return;
            }
            if v[a] < to[a] {
                v[a] += 1;
                break;
            }
            v[a] = from[a];
            a += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shell_skips_the_inner_box() {
        let mut seen = Vec::new();
        for_each_shell([0, 0, 0], [3, 3, 3], Some(([1, 1, 1], [2, 2, 2])), |v| {
            seen.push(v)
        });
        assert_eq!(seen.len(), 64 - 8);
        assert!(!seen.contains(&[1, 2, 1]));
        let mut all = 0;
        for_each_shell([-1, -1], [1, 1], None, |_| all += 1);
        assert_eq!(all, 9);
    }
}
