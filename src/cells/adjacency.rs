//! Face adjacency across levels.
//!
//! Every leaf looks across each of its `2D` faces for the leaf of the same level (pairs of equal
//! cells are taken from the lower cell only) or, failing that, for a larger leaf that contains the
//! neighboring position (found from the smaller side only). Smaller leaves across a face find
//! this one themselves, so every pair appears exactly once without a search downwards.

use rayon::prelude::*;

use super::{CellComplex, CellKey, FacePair};

pub(super) fn face_pairs<const D: usize>(complex: &CellComplex<D>) -> Vec<FacePair> {
    let mut pairs: Vec<FacePair> = complex
        .cells
        .par_iter()
        .enumerate()
        .flat_map_iter(|(i, cell)| {
            let dims = complex.grid.dims(cell.key.level);
            let mut found = Vec::new();
            for axis in 0..D {
                for dir in [-1i64, 1] {
                    let mut coord = cell.key.coord;
                    coord[axis] += dir;
                    if coord[axis] < 0 || coord[axis] >= dims[axis] {
                        continue;
                    }
                    let across = CellKey {
                        level: cell.key.level,
                        coord,
                    };
                    let j = if let Some(j) = complex.find(&across) {
                        if dir < 0 {
                            continue;
                        }
                        j
                    } else if let Some(j) = std::iter::successors(across.parent(), |k| k.parent())
                        .find_map(|k| complex.find(&k))
                    {
                        j
                    } else {
                        continue;
                    };
                    let other = &complex.cells[j];
                    let area = (2.0 * cell.half.min(other.half)).powi(D as i32 - 1);
                    found.push(FacePair {
                        i: i.min(j) as u32,
                        j: i.max(j) as u32,
                        weight: area / (cell.half + other.half),
                    });
                }
            }
            found
        })
        .collect();
    pairs.par_sort_unstable_by_key(|p| (p.i, p.j));
    pairs
}
