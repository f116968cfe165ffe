//! The empty space of a build (paper §5): the occupied cells of every level, the maximal empty
//! cells ("blocks") that tile the rest of the grid, and their classification inside or
//! outside the shape, by winding numbers or by an exterior flood fill. A block lies in no
//! occupied cell, so the surface does not cross it and it is wholly inside or outside.
//!
//! The blocks are as many as the occupied cells make them (at most `2^D − 1` children of each
//! occupied cell, and the level-0 cells beside occupied ones), except for level-0 cells smaller
//! than the shape (`root_blocks`), which are all blocks.

use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::morton::{coords, morton};
use super::winding::Winding;
use super::{CellKey, Grid, Inside};
use crate::rigid::Vect;

/// The level-0 cells of `grid` (over a box of `extent`) that are blocks of the empty space
/// whether or not an occupied cell is beside them: none when nothing is inside (`inside`
/// [`Inside::None`]) or a level-0 cell is at least as large as the box's shortest extent (the
/// default levels: then an inside point lies within one level-0 cell of the surface, see
/// `empty_blocks`); else all of them, since the inside may lie farther than a level-0 cell from
/// every occupied one.
pub(super) fn root_blocks<const D: usize>(grid: &Grid<D>, extent: &Vect<D>, inside: Inside) -> u64 {
    // Past rounding: the default levels give a level-0 cell of the shortest extent exactly.
    if inside == Inside::None || grid.size0 * (1.0 + 1e-9) >= extent.min() {
        return 0;
    }
    let count: f64 = grid.dims0.iter().map(|&n| n as f64).product();
    count.min(u64::MAX as f64) as u64
}

/// The occupied cells of every level, coarsest first, as sorted Morton codes: a cell is
/// occupied when one of its finest descendants is.
pub(super) fn pyramid<const D: usize>(grid: &Grid<D>, finest: Vec<u64>) -> Vec<Vec<u64>> {
    let mut levels = vec![finest];
    for _ in 0..grid.max_level {
        let fine = levels.last().expect("finest level present");
        // A parent's code is its child's shifted right: the order is kept.
        let mut coarse: Vec<u64> = fine.iter().map(|c| c >> D).collect();
        coarse.dedup();
        levels.push(coarse);
    }
    levels.reverse();
    levels
}

/// The maximal empty cells near the shape: every cell of level 0 that is not occupied but
/// touches an occupied one (edges and corners included), and every child that is not occupied
/// of an occupied cell above the finest level. With the level-0 cells far from the shape,
/// which are outside, they tile the grid's empty space, and each is wholly inside or wholly
/// outside the shape (the surface lies in occupied cells). With `every_root`, every level-0 cell
/// that is not occupied is a block. Returned as `(level, code)`.
pub(super) fn empty_blocks<const D: usize>(
    grid: &Grid<D>,
    levels: &[Vec<u64>],
    every_root: bool,
) -> Vec<(u8, u64)> {
    // Level 0: the empty cells among the 3^D around each occupied one. A level-0 cell at least
    // as large as the box's shortest extent with no occupied neighbor can hold neither the
    // surface nor any inside: it is outside, and is not enumerated (a grid of 35,000 × 70,000
    // of them around four samples was 2.45e9 blocks). Smaller level-0 cells (`every_root`, a
    // `max_level` below the default) are all enumerated: the inside reaches past their
    // neighbors.
    let every = every_root.then(|| {
        let total: i64 = grid.dims0.iter().product();
        (0..total)
            .into_par_iter()
            .map(|mut i| {
                let c: [i64; D] = std::array::from_fn(|a| {
                    let v = i % grid.dims0[a];
                    i /= grid.dims0[a];
                    v
                });
                morton(&c)
            })
            .filter(|code| levels[0].binary_search(code).is_err())
            .collect::<Vec<u64>>()
    });
    let mut near: Vec<u64> = every.unwrap_or_else(|| {
        levels[0]
            .iter()
            .flat_map(|&code| {
                let c = coords::<D>(code);
                (0..3usize.pow(D as u32)).filter_map(move |k| {
                    let mut n = c;
                    for (a, v) in n.iter_mut().enumerate() {
                        *v += (k / 3usize.pow(a as u32) % 3) as i64 - 1;
                        if *v < 0 || *v >= grid.dims0[a] {
                            return None;
                        }
                    }
                    Some(morton(&n))
                })
            })
            .filter(|code| levels[0].binary_search(code).is_err())
            .collect()
    });
    near.sort_unstable();
    near.dedup();
    let mut blocks: Vec<(u8, u64)> = near.into_iter().map(|code| (0, code)).collect();
    for level in 1..levels.len() {
        let (parents, children) = (&levels[level - 1], &levels[level]);
        // Both are sorted and the children of a parent are the codes `p << D ..`: one merge.
        let mut j = 0;
        for &p in parents {
            for child in p << D..(p + 1) << D {
                while j < children.len() && children[j] < child {
                    j += 1;
                }
                if children.get(j) != Some(&child) {
                    blocks.push((level as u8, child));
                }
            }
        }
    }
    blocks
}

/// Classifies the empty blocks by the winding number of `winding`: the surface lies in
/// occupied cells only, so the winding number cannot cross ½ inside a block, and one
/// evaluation at its center classifies it.
pub(super) fn classify_winding<const D: usize>(
    grid: &Grid<D>,
    blocks: &[(u8, u64)],
    winding: &Winding,
) -> Vec<bool> {
    blocks
        .par_iter()
        .map(|&(level, code)| {
            let c = grid.center(&CellKey {
                level,
                coord: coords(code),
            });
            winding
                .at(&Vect::<3>::from_fn(|a, _| if a < D { c[a] } else { 0.0 }))
                .abs()
                >= 0.5
        })
        .collect()
}

/// Classifies the empty blocks by the exterior flood fill: a block is outside when a path of
/// empty face-adjacent cells leads from it to the grid's border. The blocks are joined by a
/// union-find: each block looks across each face at the cell of its own level there; an empty
/// block there, or the coarser empty block that holds that cell, is joined to it, and an
/// occupied one is left to its own finer empty blocks, which find this block from their side.
/// So every pair of blocks sharing a face is joined once, as the finest cells of a dense grid
/// would be, and the work goes with the blocks.
pub(super) fn classify_flood<const D: usize>(
    grid: &Grid<D>,
    levels: &[Vec<u64>],
    blocks: &[(u8, u64)],
) -> Vec<bool> {
    let mut index: Vec<FxHashMap<u64, u32>> = vec![FxHashMap::default(); levels.len()];
    for (k, &(level, code)) in blocks.iter().enumerate() {
        index[level as usize].insert(code, k as u32);
    }
    let outside = blocks.len() as u32;
    let mut parent: Vec<u32> = (0..=outside).collect();
    fn root(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    // The joins are found in parallel and applied in order, a bounded batch of blocks at a
    // time.
    const BATCH: usize = 1 << 18;
    for (b, batch) in blocks.chunks(BATCH).enumerate() {
        let joins: Vec<(u32, u32)> = batch
            .par_iter()
            .enumerate()
            .fold(Vec::new, |mut out, (i, &(level, code))| {
                let k = (b * BATCH + i) as u32;
                let dims = grid.dims(level);
                let c = coords::<D>(code);
                for a in 0..D {
                    for step in [-1i64, 1] {
                        let mut n = c;
                        n[a] += step;
                        if n[a] < 0 || n[a] >= dims[a] {
                            out.push((k, outside));
                            continue;
                        }
                        let (mut l, mut m) = (level as usize, morton(&n));
                        loop {
                            if let Some(&other) = index[l].get(&m) {
                                out.push((k, other));
                                break;
                            }
                            if levels[l].binary_search(&m).is_ok() {
                                break;
                            }
                            if l == 0 {
                                // An empty level-0 cell far from the shape: outside.
                                out.push((k, outside));
                                break;
                            }
                            l -= 1;
                            m >>= D;
                        }
                    }
                }
                out
            })
            .reduce(Vec::new, |mut a, b| {
                a.extend(b);
                a
            });
        for (a, b) in joins {
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            // The outside node stays a root, so a block is outside when its root is.
            if ra != rb {
                if ra == outside {
                    parent[rb as usize] = ra;
                } else {
                    parent[ra as usize] = rb;
                }
            }
        }
    }
    drop(index);
    (0..outside)
        .map(|k| root(&mut parent, k) != outside)
        .collect()
}
