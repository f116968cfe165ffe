//! The finest cells a mesh's triangles overlap (`cells::build`'s occupied cells of a mesh).
//!
//! Each triangle's closed cells are tested against it exactly ([`triangle_box_overlap`]), the
//! cells grown by a millionth of their size; which cells are tested is this module's: those of
//! the triangle's box, column by column along the axis its normal leans to most, between the
//! heights its plane takes over each column ([`Column`]), so that a triangle much larger than
//! the cells costs about its area in cells, not its box's volume.

use rayon::prelude::*;

use super::floor;
use super::morton::morton;
use super::{CellKey, Grid, triangle_box_overlap};
use crate::error::{Error, Result};
use crate::rigid::Vect;
use crate::said::{Opt, Said};

/// Morton codes of the finest cells overlapped by `triangles`. The cells each triangle will
/// test are counted first and checked against the budget `limit`.
pub(super) fn triangle_cells<const D: usize>(
    grid: &Grid<D>,
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    limit: u64,
) -> Result<Vec<u64>> {
    let dims = grid.dims(grid.max_level);
    let size = grid.finest_size();
    let n = points.len();
    if let Some(t) = triangles
        .iter()
        .find(|t| t.iter().any(|&v| v as usize >= n))
    {
        return Err(Error::input(format!(
            "a face refers to vertex {} but there are {n} vertices",
            t.iter().max().unwrap_or(&0)
        )));
    }
    let local = |t: &[u32; 3]| -> [[f64; 3]; 3] {
        t.map(|v| {
            let p = points[v as usize] - grid.origin;
            std::array::from_fn(|a| if a < D { p[a] } else { 0.0 })
        })
    };
    // The closed cells touching each vertex, i·s ≤ x and (i + 1)·s ≥ x, with a margin against
    // rounding (the exact test decides): a triangle's box touches the cells from the least
    // of its vertices' first cells to the greatest of their last, the same cells as its box's
    // corners give (each bound is a nondecreasing function of the coordinate), found once a
    // vertex. (24 bytes a vertex, as its position: no more than the mesh already holds.) The
    // clamps bind only for a vertex outside the grid, which has a cell of margin around the
    // samples' bounds.
    let mut spans = vec![[[0i32; 3]; 2]; n];
    spans.par_iter_mut().zip(points).for_each(|(span, p)| {
        let p = p - grid.origin;
        for a in 0..D {
            let t = (p[a] - grid.lower[a]) / size;
            // ⌈t⌉ − 1 = −⌊−t⌋ − 1 (libm's floor and ceil are calls on baseline x86-64).
            span[0][a] = (-floor(-(t - 1e-9)) - 1).clamp(0, dims[a] - 1) as i32;
            span[1][a] = floor(t + 1e-9).clamp(0, dims[a] - 1) as i32;
        }
    });
    let range = |t: &[u32; 3]| -> ([i64; 3], [i64; 3]) {
        let [a, b, c] = t.map(|v| &spans[v as usize]);
        (
            std::array::from_fn(|k| a[0][k].min(b[0][k]).min(c[0][k]) as i64),
            std::array::from_fn(|k| a[1][k].max(b[1][k]).max(c[1][k]) as i64),
        )
    };
    let lower: [f64; 3] = std::array::from_fn(|a| if a < D { grid.lower[a] } else { 0.0 });
    // The cells to be tested, counted first (no more are kept): each of a triangle's columns
    // tests at most `Column::most` of them, counted in a few operations a triangle (not column
    // by column: a triangle a kilometer across has 10¹⁰ columns of centimeter cells).
    let candidates: f64 = triangles
        .par_iter()
        .map(|t| {
            let (lo, hi) = range(t);
            let column = Column::new(&local(t), lower, size);
            let (u, v, w) = column.axes;
            let depth = (hi[w] - lo[w] + 1) as f64;
            (hi[u] - lo[u] + 1) as f64 * (hi[v] - lo[v] + 1) as f64 * column.most().min(depth)
        })
        .sum();
    crate::memory::check(
        format!(
            "rasterizing {} triangles into cells of size {}",
            crate::human::count(triangles.len() as u64),
            crate::human::length(size, size)
        ),
        candidates * 8.0,
        limit,
        smaller_cells(),
    )?;
    // The closed cell, grown by a millionth of its size: a surface lying on a cell face (a box
    // mesh whose extent is a whole number of cells, as a bar of 10 × 1 × 1 at 0.02 is) marks
    // the cells on both sides. At exactly half a cell, the rounding of the cells' centers
    // decided per triangle which side it marked, or neither: the bar at 0.02 had 57,027
    // boundary cells in 190 parts joined by edges only (210,016 in one now), at 0.01 42,562
    // of its 840,016.
    let half = 0.5 * size * (1.0 + 1e-6);
    let cells: Vec<u64> = triangles
        .par_iter()
        .fold(Vec::new, |mut out, t| {
            let (lo, hi) = range(t);
            if lo == hi {
                // The triangle's box lies in this one cell (a small triangle); runs of
                // triangles in one cell (a mesh's order) are stored once.
                let coord: [i64; D] = std::array::from_fn(|a| lo[a]);
                let code = morton(&coord);
                if out.last() != Some(&code) {
                    out.push(code);
                }
                return out;
            }
            let tri = local(t);
            let column = Column::new(&tri, lower, size);
            let (u, v, w) = column.axes;
            for iu in lo[u]..=hi[u] {
                for iv in lo[v]..=hi[v] {
                    // Only the cells of this column that the triangle's plane crosses can
                    // overlap it (the exact test decides).
                    let (from, to) = column.span(iu, iv);
                    for iw in from.max(lo[w])..=to.min(hi[w]) {
                        let mut c3 = [0i64; 3];
                        (c3[u], c3[v], c3[w]) = (iu, iv, iw);
                        let coord: [i64; D] = std::array::from_fn(|a| c3[a]);
                        let center = grid.center(&CellKey {
                            level: grid.max_level,
                            coord,
                        });
                        let c: [f64; 3] = std::array::from_fn(|a| center[a]);
                        if triangle_box_overlap(&tri, c, half) {
                            out.push(morton(&coord));
                        }
                    }
                }
            }
            out
        })
        .reduce(Vec::new, |mut a, b| {
            a.extend(b);
            a
        });
    Ok(cells)
}

/// A triangle's cells column by column: along the axis `w` its plane's normal leans to most,
/// the column of finest cells at `(u, v)` meets the plane only between the heights the plane
/// takes over the column's corners. A triangle much larger than the cells overlaps some
/// `area / size²` of them, against the `(extent / size)³` of its box: a dragon at cells of a
/// 2000th of its extent tested 17 times as many cells as it kept.
struct Column {
    /// The column's axes `u`, `v` and the axis `w` along it.
    axes: (usize, usize, usize),
    /// The plane `w = (d − n_u·u − n_v·v) / n_w` as `(d, n_u, n_v, n_w)`; `None` for a
    /// triangle with no area, or too little for its plane to be known (its three corners on a
    /// line to a millionth of its edges), whose every cell of the box is tested.
    plane: Option<(f64, f64, f64, f64)>,
    lower: [f64; 3],
    size: f64,
}

impl Column {
    fn new(tri: &[[f64; 3]; 3], lower: [f64; 3], size: f64) -> Self {
        let e: [[f64; 3]; 2] = [1, 2].map(|k| std::array::from_fn(|a| tri[k][a] - tri[0][a]));
        let n = [
            e[0][1] * e[1][2] - e[0][2] * e[1][1],
            e[0][2] * e[1][0] - e[0][0] * e[1][2],
            e[0][0] * e[1][1] - e[0][1] * e[1][0],
        ];
        let w = (0..3)
            .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
            .unwrap_or(2);
        let (u, v) = ((w + 1) % 3, (w + 2) % 3);
        let d = (0..3).map(|a| n[a] * tri[0][a]).sum::<f64>();
        // A plane only where the triangle's normal is known well: its rounding is a few
        // units in the last place of `|e₀|·|e₁|`, and its lean along `w` at least `|n|/√3`.
        let norm = |e: &[f64; 3]| e.iter().map(|c| c * c).sum::<f64>().sqrt();
        let plane = (n[w].abs() > 1e-6 * norm(&e[0]) * norm(&e[1]) && d.is_finite())
            .then_some((d, n[u], n[v], n[w]));
        Self {
            axes: (u, v, w),
            plane,
            lower,
            size,
        }
    }

    /// The most cells [`Column::span`] gives a column: the plane's rise across a column over
    /// the cell size, with the margins and a cell for each end's rounding (infinite without a
    /// plane).
    fn most(&self) -> f64 {
        match self.plane {
            Some((_, nu, nv, nw)) => ((nu.abs() + nv.abs()) / nw.abs() * 1.002 + 2.01).ceil() + 1.0,
            None => f64::INFINITY,
        }
    }

    /// The cells along `w` of the column `(iu, iv)` the plane crosses, with a margin of a
    /// thousandth of a cell on every side (more than the overlap test's growth and the
    /// rounding).
    fn span(&self, iu: i64, iv: i64) -> (i64, i64) {
        let Some((d, nu, nv, nw)) = self.plane else {
            return (i64::MIN, i64::MAX);
        };
        let (u, v, w) = self.axes;
        let margin = 1e-3 * self.size;
        let at = |a: usize, i: i64| self.lower[a] + i as f64 * self.size;
        let (u0, u1) = (at(u, iu) - margin, at(u, iu + 1) + margin);
        let (v0, v1) = (at(v, iv) - margin, at(v, iv + 1) + margin);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (cu, cv) in [(u0, v0), (u0, v1), (u1, v0), (u1, v1)] {
            let h = (d - nu * cu - nv * cv) / nw;
            lo = lo.min(h);
            hi = hi.max(h);
        }
        let cell = |h: f64| floor((h - self.lower[w]) / self.size);
        (cell(lo - margin), cell(hi + margin))
    }
}

/// What to change when the cells do not fit the memory budget.
pub(super) fn smaller_cells() -> Said {
    Said::from("use a larger ")
        .opt(Opt::CellSize)
        .aside(Said::from(" or ").opt(Opt::MinCellSize))
        .text(" (or fewer ")
        .opt(Opt::Cells)
        .text(")")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cells a triangle marks, column by column, are every cell of the grid its closed cell
    /// (grown as the build grows it) overlaps: large triangles at every slant, slivers,
    /// triangles without area, and triangles lying on the cells' faces.
    #[test]
    fn triangles_mark_the_cells_they_overlap_column_by_column() {
        let grid = Grid::<3> {
            origin: Vect::<3>::zeros(),
            lower: Vect::<3>::repeat(-5.0),
            size0: 0.25,
            dims0: [40, 40, 40],
            max_level: 0,
        };
        let mut seed = 7u64;
        let mut next = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut points = Vec::new();
        let mut triangles = Vec::new();
        for k in 0..700u32 {
            let mut p: [Vect<3>; 3] =
                std::array::from_fn(|_| Vect::<3>::from_fn(|_, _| -4.0 + 8.0 * next()));
            let along = p[0] + (p[1] - p[0]) * next();
            match k % 7 {
                // On the cells' corners and faces.
                0 => p = p.map(|x| x.map(|c| (c * 4.0).round() / 4.0)),
                // In a plane of cell faces.
                1 => p.iter_mut().for_each(|x| x[(k as usize / 7) % 3] = 0.5),
                // Without area: on a line.
                2 => p[2] = along,
                // Slivers, their corners off the line by a ten-thousandth, a ten-millionth
                // and a ten-billionth of a unit (their normals known well, poorly, not).
                3 => p[2] = along + Vect::<3>::new(1e-4, -2e-4, 1e-4),
                4 => p[2] = along + Vect::<3>::new(1e-7, 0.0, -1e-7),
                5 => p[2] = along + Vect::<3>::new(0.0, 1e-10, 0.0),
                _ => {}
            }
            triangles.push([3 * k, 3 * k + 1, 3 * k + 2]);
            points.extend(p);
        }
        let mut marked = triangle_cells(&grid, &points, &triangles, u64::MAX).unwrap();
        marked.sort_unstable();
        marked.dedup();
        let half = 0.5 * grid.finest_size() * (1.0 + 1e-6);
        let mut every = Vec::new();
        for t in &triangles {
            let tri: [[f64; 3]; 3] = t.map(|v| points[v as usize].into());
            // The cells of the triangle's box, closed, with a margin against rounding.
            let first = |x: f64| -floor(-((x + 5.0) / 0.25 - 1e-9)) - 1;
            let last = |x: f64| floor((x + 5.0) / 0.25 + 1e-9);
            let lo: [i64; 3] = std::array::from_fn(|a| {
                tri.iter().map(|p| first(p[a])).min().unwrap().clamp(0, 39)
            });
            let hi: [i64; 3] =
                std::array::from_fn(|a| tri.iter().map(|p| last(p[a])).max().unwrap().clamp(0, 39));
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        let coord = [x, y, z];
                        let center = grid.center(&CellKey { level: 0, coord });
                        if triangle_box_overlap(&tri, center.into(), half) {
                            every.push(morton(&coord));
                        }
                    }
                }
            }
        }
        every.sort_unstable();
        every.dedup();
        let missing = every
            .iter()
            .filter(|c| marked.binary_search(c).is_err())
            .count();
        assert_eq!(
            marked.len() + missing,
            every.len(),
            "{missing} cells the triangles overlap are not marked"
        );
        assert_eq!(marked, every);
    }
}
