//! What a camera sees of the cells ([`Sight`]).

use crate::cells::CellComplex;
use crate::rigid::Vect;

/// What a camera sees of the cells: the rule behind a screen selection with `visible = true`
/// (the editor's box and lasso unless x-ray is on).
///
/// A sample on the screen polygon is selected when the camera sees its cell. The cell `c` is
/// seen when the line of points that the view projects to the screen point of `c`'s center,
/// walked from that center toward the camera (the way the depth `z/w` decreases) up to the
/// camera (`w = 0`) or out of the grid, enters no cell of the complex that does not touch `c`
/// (share a face, an edge or a corner with it). The cells that touch `c` are the surface around
/// it, which a line at a slant crosses; so a surface is selected through about one cell of
/// depth, and a cell with another cell at least one cell-width in front of it is hidden. The
/// complex holds the shape's boundary cells and, for a closed surface, the interior cells: the
/// far side of a solid is hidden by its inside as well as by its near side.
///
/// The rule depends on the cells and the view only, never on how many samples there are: the
/// editor's proxy and the CLI's whole file select the same cells when their cells are the same,
/// and the samples of a seen cell that lie on the polygon are selected, all of them.
pub struct Sight<'a, const D: usize> {
    complex: &'a CellComplex<D>,
    /// The view's rows in the complex's local frame.
    rows: [[f64; 4]; 4],
}

impl<'a, const D: usize> Sight<'a, D> {
    /// The sight of the cells of `complex` from the camera `view` (a row-major world-to-clip
    /// matrix in input coordinates, as the spec's `view`).
    pub fn new(complex: &'a CellComplex<D>, view: &[[f64; 4]; 4]) -> Self {
        let origin = complex.grid.origin;
        // clip = V (x_local + origin): the last column takes V·origin.
        let rows = view.map(|r| {
            let shift: f64 = (0..D.min(3)).map(|a| r[a] * origin[a]).sum();
            [r[0], r[1], r[2], r[3] + shift]
        });
        Self { complex, rows }
    }

    /// Whether the camera sees cell `c`.
    pub fn sees(&self, c: usize) -> bool {
        if D != 3 {
            return true;
        }
        let complex = self.complex;
        let cell = &complex.cells[c];
        let p = [cell.center[0], cell.center[1], cell.center[2]];
        let lin = |r: &[f64; 4]| [r[0], r[1], r[2]];
        let row = |r: &[f64; 4], x: &[f64; 3]| dot(&lin(r), x) + r[3];
        let [rx, ry, rz, rw] = &self.rows;
        let w = row(rw, &p);
        // Behind the camera (or no number): nothing in front of it to hide it.
        if w.is_nan() || w <= 0.0 {
            return true;
        }
        let (sx, sy) = (row(rx, &p) / w, row(ry, &p) / w);
        // The points projecting to (sx, sy): x − sx·w = 0 and y − sy·w = 0, a line along d.
        let (a, b) = (
            sub(&lin(rx), &scale(&lin(rw), sx)),
            sub(&lin(ry), &scale(&lin(rw), sy)),
        );
        let d = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let norm = dot(&d, &d).sqrt();
        if norm == 0.0 || !norm.is_finite() {
            return true;
        }
        let mut u = scale(&d, 1.0 / norm);
        // The depth z/w along u: its derivative's sign is that of z'·w − z·w'.
        let slope = dot(&lin(rz), &u) * w - row(rz, &p) * dot(&lin(rw), &u);
        if slope == 0.0 || !slope.is_finite() {
            return true;
        }
        if slope > 0.0 {
            u = scale(&u, -1.0);
        }
        // Up to the camera: w falls to 0 there.
        let dw = dot(&lin(rw), &u);
        let mut end = if dw < 0.0 { w / -dw } else { f64::INFINITY };
        let grid = &complex.grid;
        let level = grid.max_level;
        let s = grid.cell_size(level);
        let dims = grid.dims(level);
        let mut voxel = [0i64; 3];
        let (mut next, mut delta, mut step) = ([f64::INFINITY; 3], [f64::INFINITY; 3], [0i64; 3]);
        for k in 0..3 {
            let t = (p[k] - grid.lower[k]) / s;
            voxel[k] = (t.floor() as i64).clamp(0, dims[k] - 1);
            if u[k] != 0.0 {
                step[k] = if u[k] > 0.0 { 1 } else { -1 };
                let face = grid.lower[k] + (voxel[k] + i64::from(u[k] > 0.0)) as f64 * s;
                next[k] = (face - p[k]) / u[k];
                delta[k] = s / u[k].abs();
                // Out of the grid along this axis.
                let wall = grid.lower[k] + if u[k] > 0.0 { dims[k] as f64 * s } else { 0.0 };
                end = end.min((wall - p[k]) / u[k]);
            }
        }
        loop {
            let k = (0..3)
                .min_by(|&i, &j| next[i].total_cmp(&next[j]))
                .expect("three axes");
            if next[k] > end {
                return true;
            }
            voxel[k] += step[k];
            next[k] += delta[k];
            if voxel[k] < 0 || voxel[k] >= dims[k] {
                return true;
            }
            let center = Vect::<D>::from_fn(|a, _| grid.lower[a] + (voxel[a] as f64 + 0.5) * s);
            if let Some(j) = complex.locate(&center)
                && !touches(complex, c, j)
            {
                return false;
            }
        }
    }
}

/// Whether cells `i` and `j` share a face, an edge or a corner (or are one cell).
fn touches<const D: usize>(complex: &CellComplex<D>, i: usize, j: usize) -> bool {
    let (a, b) = (&complex.cells[i], &complex.cells[j]);
    let slack = 1e-9 * complex.grid.finest_size();
    (0..D).all(|k| (a.center[k] - b.center[k]).abs() <= a.half + b.half + slack)
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn scale(a: &[f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Per cell of `complex`, whether it holds one of the finest grid cells `coords` and the camera
/// `view` sees it ([`Sight`]).
pub(super) fn seen_cells<'a, const D: usize>(
    complex: &CellComplex<D>,
    view: &[[f64; 4]; 4],
    coords: impl Iterator<Item = &'a [i64; D]>,
) -> Vec<bool> {
    let mut cells: Vec<usize> = coords.filter_map(|k| complex.finest_cell(k)).collect();
    cells.sort_unstable();
    cells.dedup();
    seen(complex, view, &cells)
}

/// Per cell of `complex`, whether the camera `view` sees it, for the `cells` given (the others
/// are false): [`Sight`] over several cells at once.
pub fn seen<const D: usize>(
    complex: &CellComplex<D>,
    view: &[[f64; 4]; 4],
    cells: &[usize],
) -> Vec<bool> {
    use rayon::prelude::*;
    let sight = Sight::new(complex, view);
    let mut out = vec![false; complex.len()];
    let seen: Vec<bool> = cells.par_iter().map(|&c| sight.sees(c)).collect();
    for (&c, s) in cells.iter().zip(seen) {
        out[c] = s;
    }
    out
}
