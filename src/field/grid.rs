//! A field sampled on a regular grid of east, north and up offsets, for tools that apply a
//! correction grid without rigidcells (PROJ's `+proj=gridshift`, and through it GDAL, PDAL and
//! QGIS; the file is written by `crate::io::geotiff`).
//!
//! **The nodes.** A grid of `columns × rows` nodes `spacing` apart, at whole multiples of the
//! spacing, that covers the extent asked for (default: the field's cells' footprint,
//! [`crate::field::Field::domain`]). Node `(i, j)` — column `i` from the west, row `j` from the north, as a
//! picture's rows run — lies at `(west + i·s, north − j·s)`.
//!
//! **The offsets.** At each node the field's map `F` (the transfer with its exact regions and
//! its trend, as `apply` evaluates it) gives `F(p) − p`, the offset a tool adds to a point of
//! the scan to move it where `apply` moves it. The field is of space, so the offset depends on
//! the height too, and a grid holds one height per node:
//!
//! - `height: Some(z)`: every node at `z`;
//! - `height: None` (the default): each node at the center of the lowest cell over it —
//!   on a scan, its ground, where control points lie. Nodes over no cell (beyond a scan's
//!   edge) take the height of the nearest node that has one.
//!
//! A point far above or below its node's height moves as the field moves it there only
//! where the field's offsets do not change with height (a field without tilts).
//!
//! **No value.** A node beyond the field's margin, where the field is not defined and `apply`
//! refuses samples, has no offset ([`OffsetGrid::offsets`] holds NaN; the file, its no-data
//! value), and a tool reports the points near it as outside the grid.
//!
//! **The deviation.** A tool interpolates the nodes bilinearly (PROJ's default and the
//! grid's `interpolation_method`). [`GridInfo`] holds how far that interpolation, of the offsets
//! as stored (`f32`), comes from the field itself between the nodes: at the middle of every
//! grid cell and of every edge between two nodes, at the heights interpolated likewise — the
//! points farthest from the nodes, where a smooth field's interpolation errs most. A finer
//! spacing shrinks it (by about four for half the spacing).

use rayon::prelude::*;

use super::exact::Class;
use super::{Outside, SavedField, Warp};
use crate::error::{Error, Result};
pub use crate::io::geotiff::OffsetGrid;
use crate::memory::Budget;
use crate::rigid::Vect;
use crate::said::{Opt, Said};

/// Bytes per node while a grid is made: the offsets (`f32`, three), the node's height (`f64`),
/// the file's samples (`f32`, three) and the heights' fill.
pub(crate) const BYTES_PER_NODE: f64 = 48.0;

/// Parameters of [`sample`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GridParams {
    /// The distance between nodes, in the field's units (default: the finest cells' edge).
    pub spacing: Option<f64>,
    /// The area to cover, `[min x, min y, max x, max y]` in world coordinates (default: the
    /// cells' footprint).
    pub extent: Option<[f64; 4]>,
    /// The height the field is sampled at (default: each node's ground; see the module docs).
    pub height: Option<f64>,
    /// The memory budget.
    pub memory: Budget,
}

/// The largest deviation of the grid's interpolation from the field, and where.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Deviation {
    /// The length of the difference (horizontal: of its east and north parts).
    pub value: f64,
    /// Where (world x and y).
    pub at: [f64; 2],
}

/// What [`sample`] made.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GridInfo {
    /// Nodes per row.
    pub columns: usize,
    /// Rows of nodes.
    pub rows: usize,
    /// The distance between nodes.
    pub spacing: f64,
    /// The south-west node (world).
    pub south_west: [f64; 2],
    /// The north-east node (world).
    pub north_east: [f64; 2],
    /// Nodes without a value (beyond the field's margin).
    pub no_value: usize,
    /// The largest horizontal offset of a node.
    pub largest_horizontal: f64,
    /// The largest vertical offset of a node (by magnitude).
    pub largest_vertical: f64,
    /// The largest horizontal deviation between nodes.
    pub horizontal: Deviation,
    /// The largest vertical deviation between nodes.
    pub vertical: Deviation,
    /// The field's finest cells' edge (the step lengths are printed to).
    pub cell: f64,
}

/// Samples `saved` on the grid `params` asks for (module docs): the offsets and what they are.
/// Refuses a spacing or an extent that is not a positive length or a box, a height that is not
/// a number, a grid over the memory budget, and an extent where no node lies within the field.
pub fn sample(saved: SavedField<3>, params: &GridParams) -> Result<(OffsetGrid, GridInfo)> {
    let field = &saved.field;
    let (lo, hi) = field
        .domain()
        .ok_or_else(|| Error::param("the field has no cells"))?;
    let cell = 2.0 * field.halves.iter().cloned().fold(f64::INFINITY, f64::min);
    let spacing = params.spacing.unwrap_or(cell);
    if !(spacing.is_finite() && spacing > 0.0) {
        return Err(Error::param(
            Said::new()
                .set(Opt::Spacing, spacing)
                .text(": expected a positive length"),
        ));
    }
    let [x0, y0, x1, y1] = params.extent.unwrap_or([lo[0], lo[1], hi[0], hi[1]]);
    if !([x0, y0, x1, y1].iter().all(|v| v.is_finite()) && x0 < x1 && y0 < y1) {
        return Err(Error::param(
            Said::new()
                .set(Opt::Extent, format!("{x0},{y0},{x1},{y1}"))
                .text(": expected min x, min y, max x, max y with min < max"),
        ));
    }
    if params.height.is_some_and(|z| !z.is_finite()) {
        return Err(Error::param(
            Said::new().opt(Opt::Height).text(": expected a number"),
        ));
    }
    let west = (x0 / spacing).floor() * spacing;
    let south = (y0 / spacing).floor() * spacing;
    let columns = ((x1 - west) / spacing).ceil() + 1.0;
    let rows = ((y1 - south) / spacing).ceil() + 1.0;
    let nodes = columns * rows;
    params.memory.check(
        format!("a grid of {columns} × {rows} nodes"),
        nodes * BYTES_PER_NODE,
        Said::from("a larger ")
            .opt(Opt::Spacing)
            .text(" or a smaller ")
            .opt(Opt::Extent),
    )?;
    if nodes * 12.0 > f64::from(u32::MAX) - 65536.0 {
        return Err(Error::param(
            Said::from(format!(
                "a grid of {columns} × {rows} nodes is past a TIFF's 4 GiB; choose a larger "
            ))
            .opt(Opt::Spacing),
        ));
    }
    let (columns, rows) = (columns as usize, rows as usize);
    let north = south + (rows - 1) as f64 * spacing;
    let origin = field.origin;
    let at = |i: usize, j: usize| [west + i as f64 * spacing, north - j as f64 * spacing];
    let heights = match params.height {
        Some(z) => vec![z; columns * rows],
        None => ground(
            field,
            (west, north, spacing),
            (columns, rows),
            (lo[2] + hi[2]) / 2.0,
        ),
    };
    let map = saved.deformer(None, None, Outside::Keep)?;
    let offset = |x: f64, y: f64, z: f64| -> Option<Vect<3>> {
        let p = Vect::<3>::new(x, y, z) - origin;
        match map.class_of(&p) {
            Class::Outside => None,
            _ => Some(map.warp(&p) - p),
        }
    };
    let offsets: Vec<[f32; 3]> = (0..columns * rows)
        .into_par_iter()
        .map(|k| {
            let [x, y] = at(k % columns, k / columns);
            match offset(x, y, heights[k]) {
                Some(d) => [d[0] as f32, d[1] as f32, d[2] as f32],
                None => [f32::NAN; 3],
            }
        })
        .collect();
    let no_value = offsets.iter().filter(|o| o[0].is_nan()).count();
    if no_value == offsets.len() {
        let said = Said::from(format!(
            "no node of the grid lies within the field's margin ({}); choose an ",
            crate::human::length(map.margin(), cell),
        ))
        .opt(Opt::Extent)
        .text(" over the field");
        return Err(Error::param(match params.height {
            Some(_) => said
                .text(" or a ")
                .opt(Opt::Height)
                .text(" among its cells"),
            None => said,
        }));
    }
    let grid = OffsetGrid {
        west,
        north,
        spacing,
        columns,
        rows,
        offsets,
    };
    let (horizontal, vertical) = deviation(&grid, &heights, &offset);
    let (mut largest_horizontal, mut largest_vertical) = (0.0f64, 0.0f64);
    for o in grid.offsets.iter().filter(|o| !o[0].is_nan()) {
        largest_horizontal = largest_horizontal.max(f64::from(o[0]).hypot(f64::from(o[1])));
        largest_vertical = largest_vertical.max(f64::from(o[2]).abs());
    }
    let info = GridInfo {
        columns,
        rows,
        spacing,
        south_west: [west, south],
        north_east: [west + (columns - 1) as f64 * spacing, north],
        no_value,
        largest_horizontal,
        largest_vertical,
        horizontal,
        vertical,
        cell,
    };
    Ok((grid, info))
}

/// The height of each node (module docs): the center of the lowest cell whose footprint holds
/// it, or the nearest such node's (breadth first over the grid), or `middle` when no node
/// lies under a cell.
fn ground(
    field: &super::Field<3>,
    (west, north, spacing): (f64, f64, f64),
    (columns, rows): (usize, usize),
    middle: f64,
) -> Vec<f64> {
    let mut heights = vec![f64::INFINITY; columns * rows];
    for (c, &h) in field.centers.iter().zip(&field.halves) {
        let w = field.origin + c;
        let i0 = ((w[0] - h - west) / spacing).ceil().max(0.0) as usize;
        let i1 = ((w[0] + h - west) / spacing)
            .floor()
            .min(columns as f64 - 1.0);
        let j0 = ((north - (w[1] + h)) / spacing).ceil().max(0.0) as usize;
        let j1 = ((north - (w[1] - h)) / spacing)
            .floor()
            .min(rows as f64 - 1.0);
        if i1 < 0.0 || j1 < 0.0 {
            continue;
        }
        for j in j0..=j1 as usize {
            for i in i0..=i1 as usize {
                let z = &mut heights[j * columns + i];
                *z = z.min(w[2]);
            }
        }
    }
    let mut queue: std::collections::VecDeque<usize> = (0..heights.len())
        .filter(|&k| heights[k].is_finite())
        .collect();
    if queue.is_empty() {
        return vec![middle; heights.len()];
    }
    while let Some(k) = queue.pop_front() {
        let (i, j) = (k % columns, k / columns);
        let near = [
            (i > 0).then(|| k - 1),
            (i + 1 < columns).then_some(k + 1),
            (j > 0).then(|| k - columns),
            (j + 1 < rows).then_some(k + columns),
        ];
        for n in near.into_iter().flatten() {
            if heights[n].is_infinite() {
                heights[n] = heights[k];
                queue.push_back(n);
            }
        }
    }
    heights
}

/// The largest horizontal and vertical deviations of the grid's bilinear interpolation from
/// the field (`offset`: `None` beyond the margin), at the middles of the grid's cells and
/// edges whose nodes all have values (module docs).
fn deviation(
    grid: &OffsetGrid,
    heights: &[f64],
    offset: &(impl Fn(f64, f64, f64) -> Option<Vect<3>> + Sync),
) -> (Deviation, Deviation) {
    let (columns, rows, s) = (grid.columns, grid.rows, grid.spacing);
    // The middles of the cell east and south of node (i, j): (1, 0) east, (0, 1) south, (1, 1)
    // the cell's own, in halves of the spacing.
    let worst = |a: (f64, [f64; 2]), b: (f64, [f64; 2])| if b.0 > a.0 { b } else { a };
    let none = (0.0, [0.0; 2]);
    let (h, v) = (0..columns * rows)
        .into_par_iter()
        .map(|k| {
            let (i, j) = (k % columns, k / columns);
            let (mut h, mut v) = (none, none);
            for (di, dj) in [(1usize, 0usize), (0, 1), (1, 1)] {
                if i + di >= columns || j + dj >= rows {
                    continue;
                }
                let corners = [k, k + di, k + dj * columns, k + di + dj * columns];
                if corners.iter().any(|&c| grid.offsets[c][0].is_nan()) {
                    continue;
                }
                let mean =
                    |f: &dyn Fn(usize) -> f64| corners.iter().map(|&c| f(c)).sum::<f64>() / 4.0;
                let x = grid.west + (i as f64 + di as f64 / 2.0) * s;
                let y = grid.north - (j as f64 + dj as f64 / 2.0) * s;
                let Some(d) = offset(x, y, mean(&|c| heights[c])) else {
                    continue;
                };
                let g = |a: usize| mean(&|c| f64::from(grid.offsets[c][a]));
                h = worst(h, ((g(0) - d[0]).hypot(g(1) - d[1]), [x, y]));
                v = worst(v, ((g(2) - d[2]).abs(), [x, y]));
            }
            (h, v)
        })
        .reduce(|| (none, none), |a, b| (worst(a.0, b.0), worst(a.1, b.1)));
    let dev = |(value, at): (f64, [f64; 2])| Deviation { value, at };
    (dev(h), dev(v))
}
