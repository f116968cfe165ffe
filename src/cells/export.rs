//! The cell complex as a PLY file of boxes, for inspection in any mesh viewer.
//!
//! Every cell is 8 vertices and 6 quads, in world coordinates (double). Faces carry the cell's
//! properties: `level`, `kind` (0 boundary, 1 interior), `role` (0 free, 1 fixed, 2 handle,
//! 3 pin, 4 rest, 5 carried along), `strain` and a color: after a solve, the boxes are drawn in their solved pose
//! (each cell moved by its own rigid motion, as in the paper's Fig. 5) and colored blue → red by
//! strain relative to the largest; without one, boundary cells are orange and interior cells
//! blue-gray.

use std::io::Write;
use std::path::Path;

use super::{CellComplex, CellKind};
use crate::error::Result;
use crate::io::write_atomic;
use crate::rigid::{Motion, Vect};

/// A solved pose of a complex, for [`write_cells_ply`]: per cell its rigid motion, its role
/// code (0 free, 1 fixed, 2 handle, 3 pin, 4 rest, 5 carried along) and its strain.
/// [`crate::pipeline::write_cells`] makes one from a solution; the export does not depend on
/// the solver.
#[derive(Debug, Clone, Copy)]
pub struct Pose<'a> {
    /// One motion per cell (local frame).
    pub motions: &'a [Motion<3>],
    /// One role code per cell.
    pub roles: &'a [u8],
    /// One strain per cell.
    pub strain: &'a [f64],
}

/// The faces of a box as quads of its corners, outward, corners numbered by bits (x = 1,
/// y = 2, z = 4).
pub(crate) const BOX_QUADS: [[u32; 4]; 6] = [
    [0, 4, 6, 2],
    [1, 3, 7, 5],
    [0, 1, 5, 4],
    [2, 6, 7, 3],
    [0, 2, 3, 1],
    [4, 5, 7, 6],
];

/// Writes `complex` (in `pose` when given: its cells moved, colored by strain) to `path` as a
/// binary little-endian PLY; its header names the vertical axis `up` (0 x, 1 y, 2 z: the
/// input's, so that `render` shows the cells as it shows the input).
pub fn write_cells_ply(
    path: &Path,
    complex: &CellComplex<3>,
    pose: Option<Pose<'_>>,
    up: usize,
) -> Result<()> {
    let strain = pose.map(|p| p.strain);
    let top = strain.map_or(0.0, |s| s.iter().cloned().fold(0.0, f64::max));
    let n = complex.len();
    let mut out = Vec::with_capacity(n * (8 * 24 + 6 * 28) + 512);
    let _ = write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment rigidcells cell complex: {n} cells\n\
         comment up {}\n\
         element vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
         element face {}\nproperty list uchar int vertex_indices\nproperty uchar level\n\
         property uchar kind\nproperty uchar role\nproperty float strain\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        ["x", "y", "z"][up.min(2)],
        8 * n,
        6 * n
    );
    let origin = complex.grid.origin;
    for (i, cell) in complex.cells.iter().enumerate() {
        let motion = pose.map_or(Motion::rest(&cell.center), |p| p.motions[i]);
        for corner in 0..8 {
            let offset = Vect::<3>::from_fn(|a, _| {
                if corner >> a & 1 == 1 {
                    cell.half
                } else {
                    -cell.half
                }
            });
            let p = motion.apply(&cell.center, &(cell.center + offset)) + origin;
            for v in p.iter() {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    for (i, cell) in complex.cells.iter().enumerate() {
        let role = pose.map_or(0u8, |p| p.roles[i]);
        let s = strain.map_or(0.0, |s| s[i]);
        let color = match (&strain, cell.kind) {
            (Some(_), _) => {
                let t = if top > 0.0 {
                    (s / top).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                [
                    (255.0 * t) as u8,
                    (80.0 * (1.0 - t)) as u8,
                    (255.0 * (1.0 - t)) as u8,
                ]
            }
            (None, CellKind::Boundary) => [240, 150, 40],
            (None, CellKind::Interior) => [110, 130, 170],
        };
        let kind = u8::from(cell.kind == CellKind::Interior);
        for quad in BOX_QUADS {
            out.push(4);
            for c in quad {
                out.extend_from_slice(&(8 * i as u32 + c).to_le_bytes());
            }
            out.extend_from_slice(&[cell.key.level, kind, role]);
            out.extend_from_slice(&(s as f32).to_le_bytes());
            out.extend_from_slice(&color);
        }
    }
    write_atomic(path, &out)
}
