//! The edit spec: which samples are fixed, which are handles and where they go, pins, soft
//! targets and stiffness regions, in TOML, in the input's own coordinates.
//!
//! ```toml
//! [[fixed]]
//! box = { min = [0.0, 0.0, 0.0], max = [0.5, 1.0, 1.0] }
//!
//! [[handle]]
//! sphere = { center = [9.75, 0.5, 0.5], radius = 0.5 }  # or box, or plane = {point, normal}
//! translate = [0.0, 0.0, 4.0]
//! rotate = { axis = [0.0, 1.0, 0.0], degrees = -90.0 }  # about `pivot` (default: the centroid)
//! # scale = 1.0, pivot = [..], or matrix = [[..],[..],[..],[..]] instead of the parts
//!
//! [[pin]]
//! point = [5.0, 0.5, 1.0]
//! to = [5.0, 0.5, 1.5]
//!
//! [[target]]
//! from = [1.0, 0.5, 1.0]
//! to = [1.0, 0.5, 1.2]
//! weight = 1.0          # or file = "gcp.csv": control points ([`read_control_points`])
//! # snap = 5.0          # move `from` to the nearest sample within 5 units first
//! # exact = true        # pin the point's cell: it lands where wanted, not only near
//!
//! [[stiffness]]
//! box = { min = [4.0, 0.0, 0.0], max = [6.0, 1.0, 1.0] }
//! scale = 0.2
//! ```
//!
//! A region is one or more of `box`, `sphere`, `plane` (the half-space behind `normal`, i.e.
//! the points `x` with `(x − point)·normal ≤ 0`), `polygon = [[x, y], ..]` or
//! `polygon_file = "area.geojson"` (a prism over x, y, with an optional height range
//! `z = [lo, hi]`; or, with `view = [[..] × 4]`, a lasso drawn on a screen: the polygon is in
//! the view's normalized device coordinates `[-1, 1]²` and the region is every point in front
//! of the camera that the 4×4 world-to-clip matrix projects into it, as the editor writes it;
//! with `visible = true` as well, only the samples whose cell the camera sees, the front
//! surface: [`crate::solve::Sight`] states the rule),
//! `indices = "file.txt"` (sample indices, whitespace or comma separated, 0-based; or the
//! list itself, `indices = [0, 5, 9]`) or `classification = [..]` (LAS classes); several in
//! one entry combine (a sample must satisfy all), and `invert = true` takes the rest. A handle's transform is
//! `A(x) = S·R·(x − pivot) + pivot + translate`, or a general affine `matrix` (row-major 4×4 in
//! 3D, 3×3 in 2D, last row `0 … 0 1`). Unknown keys are errors, so typos do not pass silently;
//! every error names the line.
//!
//! The types live in `region` (what an entry selects) and `entries` (what it does, and the
//! [`EditSpec`] that holds them); `parse` reads the TOML into them, with `geojson` for
//! `polygon_file` and `control_points` for a `[[target]]`'s `file`; `scan` checks the spec
//! against the input it edits (a GeoJSON's `crs`, polygons outside the scan's bounds).

mod control_points;
mod entries;
mod geojson;
mod parse;
mod region;
mod scan;
mod shape;
mod validate;

pub use control_points::{ControlRow, read_control_points};
pub use entries::{
    EditSpec, Entry, HEIGHT_HOLD, HORIZONTAL_SNAP, HandleMotion, Pin, Target, Trend,
};
pub use parse::{LARGEST, MAX_TURN_DEGREES, parse_poses, parse_spec, read_spec};
pub use region::{Polygon, Region};
pub use shape::Shape;
