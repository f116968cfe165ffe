//! The field's domain: the margin of voxels around its cells within which a sample counts as
//! inside (see [`super::FieldMap`]), and the [`Frame`] a saved field keeps of it.

use rayon::prelude::*;
use rustc_hash::FxHashSet;

use super::leaves::{Leaves, for_each_shell};
use super::{Field, Frame};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// The [`Frame`] of the whole `field` (for saving it).
pub(crate) fn frame_of<const D: usize>(field: &Field<D>) -> Result<Frame<D>> {
    let leaves = Leaves::new(&field.centers, &field.halves).map_err(Error::solver)?;
    let margin_shift = Margin::new(&leaves, None).shift;
    let mut lo = Vect::<D>::repeat(f64::INFINITY);
    let mut hi = Vect::<D>::repeat(f64::NEG_INFINITY);
    for (c, h) in field.centers.iter().zip(&field.halves) {
        lo = lo.inf(&c.add_scalar(-h));
        hi = hi.sup(&c.add_scalar(*h));
    }
    Ok(Frame {
        lower: leaves.lower,
        edge: leaves.edge,
        margin_shift,
        bounds: (lo, hi),
        largest_half: field.halves.iter().cloned().fold(0.0, f64::max),
    })
}

/// The margin of a field's cells: the voxels within which a sample in no cell still counts as
/// inside. Margin voxels are the size of the largest cell on the complex's outer boundary (a
/// cell with a face that no leaf of its size or larger covers), and the margin is every margin
/// voxel within one of a margin voxel that such a cell lies in.
///
/// It keeps the margin voxels the boundary cells lie in, and a lookup looks for one among the
/// 3^D around a voxel (at most 3^D probes, for a sample in no cell within the cells' box; a
/// transfer looks up each run of samples in one voxel once). A deformation's samples all lie
/// in the cells they made, so its lookups are few, while the grown set was counted for every
/// field: on a terrain one cell thick, whose every cell is on the boundary, the 1.14M cells
/// at 2 m grow to 3.6M margin voxels, 1.4 s to count (BENCHMARKS.md §4).
pub(super) struct Margin<const D: usize> {
    /// The margin voxels' size, as a shift of the leaves' voxels.
    pub shift: u32,
    /// The margin voxels the boundary cells lie in (each at most a margin voxel's size).
    seeds: FxHashSet<[i64; D]>,
    /// The box of the seeds' voxels, grown by one.
    lo: [i64; D],
    hi: [i64; D],
}

impl<const D: usize> Margin<D> {
    /// The margin of the cells of `leaves`, its voxels of size `fixed` where given (a window's:
    /// the whole field's), else of its largest boundary cell's size.
    pub fn new(leaves: &Leaves<D>, fixed: Option<u32>) -> Self {
        let boundary = boundary(leaves, fixed);
        let shift = fixed.unwrap_or_else(|| {
            boundary
                .iter()
                .map(|&c| leaves.keys[c].0)
                .max()
                .unwrap_or(0)
        });
        let mut lo = [i64::MAX; D];
        let mut hi = [i64::MIN; D];
        let seeds: FxHashSet<[i64; D]> = boundary
            .iter()
            .map(|&c| {
                let (s, coord) = leaves.keys[c];
                let v = coord.map(|k| k >> (shift - s));
                for a in 0..D {
                    lo[a] = lo[a].min(v[a] - 1);
                    hi[a] = hi[a].max(v[a] + 1);
                }
                v
            })
            .collect();
        Self {
            shift,
            seeds,
            lo,
            hi,
        }
    }

    /// Whether the leaf voxel `voxel` (of [`Leaves::voxel`]) is within the margin: its margin
    /// voxel within one of a boundary cell's.
    pub fn holds(&self, voxel: &[i64; D]) -> bool {
        let v = voxel.map(|k| k >> self.shift);
        if (0..D).any(|a| v[a] < self.lo[a] || v[a] > self.hi[a]) {
            return false;
        }
        if self.seeds.contains(&v) {
            return true;
        }
        let mut found = false;
        for_each_shell(v.map(|k| k - 1), v.map(|k| k + 1), None, |u| {
            found = found || self.seeds.contains(&u);
        });
        found
    }
}

/// The cells on the complex's outer boundary: those with a face that no leaf of their size or
/// larger covers. In a window (`fixed`: the whole field's margin voxel), a cell larger than the
/// margin voxel is not on its boundary (it only looks so where the window cuts its neighbors
/// away).
fn boundary<const D: usize>(leaves: &Leaves<D>, fixed: Option<u32>) -> Vec<usize> {
    (0..leaves.keys.len())
        .into_par_iter()
        .filter(|&c| {
            let (shift, coord) = leaves.keys[c];
            fixed.is_none_or(|f| shift <= f)
                && (0..D).any(|a| {
                    [-1i64, 1].iter().any(|&side| {
                        let mut next = coord;
                        next[a] += side;
                        !leaves.covered(shift, &next)
                    })
                })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The margin's lookups give the voxels that inserting each boundary cell's box of 3^D
    /// margin voxels gives, on cells of two sizes (a window's fixed size too).
    #[test]
    fn a_lookup_is_the_grown_boxes() {
        // An L of small cells (edge 1) beside a row of large ones (edge 2).
        let (mut centers, mut halves) = (Vec::new(), Vec::new());
        for x in 0..6 {
            for y in 0..3 {
                if x < 2 || y == 0 {
                    centers.push(Vect::<2>::new(x as f64 + 0.5, y as f64 + 0.5));
                    halves.push(0.5);
                }
            }
        }
        for x in 0..3 {
            centers.push(Vect::<2>::new(2.0 * x as f64 + 1.0, -1.0));
            halves.push(1.0);
        }
        let leaves = Leaves::new(&centers, &halves).unwrap();
        for fixed in [None, Some(1), Some(2)] {
            let margin = Margin::new(&leaves, fixed);
            let mut grown = FxHashSet::default();
            for &c in &boundary(&leaves, fixed) {
                let (s, coord) = leaves.keys[c];
                let v = coord.map(|k| k >> (margin.shift - s));
                for_each_shell(v.map(|k| k - 1), v.map(|k| k + 1), None, |u| {
                    grown.insert(u);
                });
            }
            assert!(grown.len() > 9, "{fixed:?}: {}", grown.len());
            for x in -16..24 {
                for y in -16..24 {
                    let voxel = [x, y];
                    let v = voxel.map(|k| k >> margin.shift);
                    assert_eq!(margin.holds(&voxel), grown.contains(&v), "{fixed:?} {v:?}");
                }
            }
        }
    }
}
