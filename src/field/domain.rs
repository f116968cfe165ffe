//! The field's domain: the margin of voxels around its cells within which a sample counts as
//! inside (see [`super::FieldMap`]), and the [`Frame`] a saved field keeps of it.

use rustc_hash::FxHashSet;

use super::leaves::{Leaves, for_each_shell};
use super::{Field, Frame};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// The [`Frame`] of the whole `field` (for saving it).
pub(crate) fn frame_of<const D: usize>(field: &Field<D>) -> Result<Frame<D>> {
    let leaves = Leaves::new(&field.centers, &field.halves).map_err(Error::solver)?;
    let (_, margin_shift) = margin(&leaves, None);
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

/// The margin voxels and their size (as a shift of the voxels): the size of the largest cell
/// on the complex's outer boundary (a cell with a face that no leaf of its size or larger
/// covers), and every margin voxel within one of a voxel that such a cell meets.
pub(super) fn margin<const D: usize>(
    leaves: &Leaves<D>,
    fixed: Option<u32>,
) -> (FxHashSet<[i64; D]>, u32) {
    let boundary: Vec<usize> = (0..leaves.keys.len())
        .filter(|&c| {
            let (shift, coord) = leaves.keys[c];
            // In a window, a cell larger than the whole field's margin voxel is not on its
            // boundary (it only looks so where the window cuts its neighbors away).
            fixed.is_none_or(|f| shift <= f)
                && (0..D).any(|a| {
                    [-1i64, 1].iter().any(|&side| {
                        let mut next = coord;
                        next[a] += side;
                        !leaves.covered(shift, &next)
                    })
                })
        })
        .collect();
    let shift = fixed.unwrap_or_else(|| {
        boundary
            .iter()
            .map(|&c| leaves.keys[c].0)
            .max()
            .unwrap_or(0)
    });
    let mut set = FxHashSet::default();
    for &c in &boundary {
        let (s, coord) = leaves.keys[c];
        // Every boundary cell is at most the margin voxel's size: it lies in one.
        let v = coord.map(|k| k >> (shift - s));
        for_each_shell(v.map(|k| k - 1), v.map(|k| k + 1), None, |u| {
            set.insert(u);
        });
    }
    (set, shift)
}
