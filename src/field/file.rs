//! Deformation fields as files (`deform --save-field`, `apply`).
//!
//! Little-endian binary, exact f64 bits, so that applying a saved field reproduces `deform`'s
//! output bit for bit:
//!
//! ```text
//! "RCFIELD\0"  u32 version (6)  u32 D
//! u8 transfer                        0 blend, 1 blend-idw, 2 rbf, 3 pu (version 2),
//!                                    + 128 when the field keeps heights (version 4),
//!                                    + 64 when a trend follows (version 4):
//!   f64[D·D] linear (row-major), f64[D] translation      the trend's affine part (local),
//!   u64 k, f64 L, k × (f64[2] center, f64[D] weight)       and its spline (k = 0: none)
//! f64[D] origin                                  world position of the local frame
//! u64 n, then n × (f64[D] center, f64 half, f64[D·D] rotation (row-major), f64[D] position)
//! u64 r, then r × (f64[D·D] linear (row-major), f64[D] translation)   prescribed maps (v2)
//!        and if r > 0: u32[n] the map of each cell (u32::MAX: none)
//! u8 has_rbf, then if 1: f64[D] shift, f64 inv_scale, f64[D] constant, f64[D·D] linear,
//!                        f64[D·n] weights (component by component)
//! u8 has_window (v3), then if 1:
//!     f64[D] leaves' grid corner, f64 smallest edge, u32 margin shift,      the Frame
//!     f64[D] bounds low, f64[D] bounds high, f64 largest half-size
//!     f64[D] patch grid corner, f64 patch edge, u64 p,                      the PU's layout
//!     p × i64[D] patch box, (p + 1) × u64 offsets into the members, u32[] members
//! u8 has_crs (v5), then if 1: the CRS of the input the field was solved on
//!     (crate::crs::Crs::to_bytes: u8 source, u32 EPSG, u32 vertical EPSG,
//!      5 × (u32 length, UTF-8): name, WKT, unit, vertical unit, where the unit was read)
//! u32 s (v6), then s × (u32 map, shape)          the regions held to their own border
//!     (super::Shape::write: u8 tag, then 0 box f64[D] min, f64[D] max; 1 sphere f64[D],
//!      f64; 2 half-space f64[D] point, f64[D] normal; 3 prism u8 has_z [f64 z0, f64 z1],
//!      u32 rings, each u32 k, k × f64[2]; 4 all / 6 any: u32 parts, the parts; 5 not: a part)
//! ```
//!
//! **Applying to a tile reads what the tile needs** (version 3, for the PU transfer). The
//! window section lets [`SavedField::load_window`] read, through a memory map, only the cells
//! of the patches whose support comes within [`Frame::reach`] of the tile's box (the LAS
//! header's bounds): the PU's patches there with every cell they fit (so each fit has the
//! whole field's bits) and every cell that locates a sample of the tile among the cells, its
//! margin and its bands. The [`Frame`] carries what those lookups take from the whole field
//! (its voxel grid, margin voxel and bounds). Memory and time then grow with the tile, not
//! with the field; a sample outside the box (a header whose bounds are wrong) is counted
//! ([`FieldMap::beyond_window`]) and `apply` starts again with the whole field. The PU
//! coefficients themselves are not stored: each patch's fit is a small dense solve of its own
//! cells on one thread, the same bits wherever it runs, and cheaper to redo than to read
//! (a patch's weights and cell list would take about three times the cells' bytes).
//!
//! The RBF coefficients are stored rather than recomputed, because a parallel dense
//! factorization need not give the same last bits on another machine or thread count.
//!
//! Version 6 added the regions a field holds exact to their own border ([`super::Prescribed::shapes`]):
//! a map with a shape is exact for the samples inside it, whatever cell holds them, and blends
//! out from the region itself. Earlier files have none: their prescribed cells are exact whole.
//!
//! Version 5 added the coordinate reference system of the input the field was solved on
//! ([`SavedField::crs`]; `apply` refuses a file in another, [`crate::crs::check`]): earlier
//! files, and fields of inputs that declare none, record none.
//!
//! Version 4 added the flag of a field that keeps every sample's height
//! ([`Field::heights_kept`]) and the control points' trend ([`Field::trend`]); earlier files
//! keep no height and have no trend.
//!
//! Version 2 added the transfer `deform` used (what `apply` uses unless told otherwise) and the
//! maps that fixed and handle cells follow exactly ([`super::FieldMap`]). Version 1 files
//! still load: their transfer is the RBF (the one they were saved for) and they prescribe no
//! cell, so their constraints are as exact as the transfer makes them.

use std::io::Read;
use std::path::Path;

use super::pu::{Layout, OVERLAP};
use super::{Field, Frame, PuRbf, Rbf, Transfer, UNPRESCRIBED};
use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::rigid::{Affine, Dim, Mat, Motion, Rigid, Vect};
use crate::solve::trend::TrendMap;
use crate::spec::LARGEST;

const MAGIC: &[u8; 8] = b"RCFIELD\0";
const VERSION: u32 = 6;

/// The transfer byte's flag of a field that keeps heights (version 4).
const HEIGHTS_KEPT: u8 = 128;
/// The transfer byte's flag of a field with a trend, which follows the byte (version 4).
const HAS_TREND: u8 = 64;

/// A field with its transfer and the RBF coefficients it was saved with, if any.
pub struct SavedField<const D: usize> {
    /// The cells and motions.
    pub field: Field<D>,
    /// The transfer the field was made for.
    pub transfer: Transfer,
    pub(super) rbf: Option<Rbf<D>>,
    /// For a window of the file's cells ([`SavedField::load_window`]): the whole field's
    /// frame, the PU's patches over the window's cells, and the samples' box (local).
    pub(super) window: Option<Window<D>>,
    /// The coordinate reference system of the input the field was solved on, when it declared
    /// one (version 5).
    pub crs: Option<Crs>,
}

/// What [`SavedField::load_window`] keeps besides the window's cells.
pub(super) struct Window<const D: usize> {
    pub(super) frame: Frame<D>,
    pub(super) layout: Layout<D>,
    pub(super) samples: (Vect<D>, Vect<D>),
}

impl<const D: usize> SavedField<D>
where
    Dim<D>: Rigid<D>,
{
    /// Wraps a field, the transfer it is for and, optionally, its RBF transfer.
    pub fn new(field: Field<D>, transfer: Transfer, rbf: Option<Rbf<D>>) -> Self {
        Self {
            field,
            transfer,
            rbf,
            window: None,
            crs: None,
        }
    }

    /// The same field, recording `crs` as the system of the input it was solved on.
    pub fn with_crs(self, crs: Option<Crs>) -> Self {
        Self { crs, ..self }
    }

    /// Whether only a window of the file's cells was read ([`SavedField::load_window`]).
    pub fn is_window(&self) -> bool {
        self.window.is_some()
    }

    /// Whether the file holds the RBF's coefficients.
    pub fn has_rbf(&self) -> bool {
        self.rbf.is_some()
    }

    /// Writes the field to `path` atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::io::write_atomic(path, &self.to_bytes()?)
    }

    /// The bytes [`SavedField::save`] writes.
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        let f = &self.field;
        let mut out = Vec::new();
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(D as u32).to_le_bytes());
        let transfer = match self.transfer {
            Transfer::Blend => 0,
            Transfer::BlendIdw => 1,
            Transfer::Rbf => 2,
            Transfer::Pu => 3,
        };
        let trend = &f.trend;
        let trended = !trend.is_identity();
        out.push(
            transfer
                | if f.heights_kept { HEIGHTS_KEPT } else { 0 }
                | if trended { HAS_TREND } else { 0 },
        );
        let put = |out: &mut Vec<u8>, v: f64| out.extend_from_slice(&v.to_le_bytes());
        if trended {
            for r in 0..D {
                for k in 0..D {
                    put(&mut out, trend.affine.linear[(r, k)]);
                }
            }
            trend
                .affine
                .translation
                .iter()
                .for_each(|&v| put(&mut out, v));
            out.extend_from_slice(&(trend.centers.len() as u64).to_le_bytes());
            put(&mut out, trend.scale);
            for (c, w) in trend.centers.iter().zip(&trend.weights) {
                c.iter().chain(w.iter()).for_each(|&v| put(&mut out, v));
            }
        }
        f.origin.iter().for_each(|&v| put(&mut out, v));
        out.extend_from_slice(&(f.centers.len() as u64).to_le_bytes());
        for ((c, h), m) in f.centers.iter().zip(&f.halves).zip(&f.motions) {
            c.iter()
                .chain(std::iter::once(h))
                .for_each(|&v| put(&mut out, v));
            for r in 0..D {
                for k in 0..D {
                    put(&mut out, m.rot[(r, k)]);
                }
            }
            m.pos.iter().for_each(|&v| put(&mut out, v));
        }
        let prescribed = &f.prescribed;
        out.extend_from_slice(&(prescribed.maps.len() as u64).to_le_bytes());
        for m in &prescribed.maps {
            for r in 0..D {
                for k in 0..D {
                    put(&mut out, m.linear[(r, k)]);
                }
            }
            m.translation.iter().for_each(|&v| put(&mut out, v));
        }
        if !prescribed.maps.is_empty() {
            for c in 0..f.centers.len() {
                let m = prescribed.cells.get(c).copied().unwrap_or(UNPRESCRIBED);
                out.extend_from_slice(&m.to_le_bytes());
            }
        }
        match &self.rbf {
            None => out.push(0),
            Some(rbf) => {
                out.push(1);
                let (shift, inv_scale, constant, linear, weights) = rbf.parts();
                shift.iter().for_each(|&v| put(&mut out, v));
                put(&mut out, inv_scale);
                constant.iter().for_each(|&v| put(&mut out, v));
                linear.iter().flatten().for_each(|&v| put(&mut out, v));
                weights
                    .iter()
                    .flat_map(|w| w.iter())
                    .for_each(|&v| put(&mut out, v));
            }
        }
        if self.transfer == Transfer::Pu && self.window.is_none() {
            out.push(1);
            let frame = super::domain::frame_of(f)?;
            frame.lower.iter().for_each(|&v| put(&mut out, v));
            put(&mut out, frame.edge);
            out.extend_from_slice(&frame.margin_shift.to_le_bytes());
            frame.bounds.0.iter().for_each(|&v| put(&mut out, v));
            frame.bounds.1.iter().for_each(|&v| put(&mut out, v));
            put(&mut out, frame.largest_half);
            let layout = PuRbf::layout_of(f)?;
            layout.lower.iter().for_each(|&v| put(&mut out, v));
            put(&mut out, layout.edge);
            out.extend_from_slice(&(layout.patches.len() as u64).to_le_bytes());
            for (k, _) in &layout.patches {
                k.iter()
                    .for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
            }
            let mut offset = 0u64;
            out.extend_from_slice(&offset.to_le_bytes());
            for (_, m) in &layout.patches {
                offset += m.len() as u64;
                out.extend_from_slice(&offset.to_le_bytes());
            }
            for (_, m) in &layout.patches {
                m.iter()
                    .for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
            }
        } else {
            out.push(0);
        }
        match &self.crs {
            None => out.push(0),
            Some(crs) => {
                out.push(1);
                out.extend_from_slice(&crs.to_bytes());
            }
        }
        out.extend_from_slice(&(prescribed.shapes.len() as u32).to_le_bytes());
        for (m, shape) in &prescribed.shapes {
            out.extend_from_slice(&m.to_le_bytes());
            shape.write(&mut out);
        }
        Ok(out)
    }

    /// Reads a field saved by [`SavedField::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .and_then(|mut f| f.read_to_end(&mut bytes))
            .map_err(|e| Error::io(path, e))?;
        Self::parse(&bytes, path, None)
    }

    /// The field of bytes [`SavedField::to_bytes`] made; `name` names them in errors.
    pub fn from_bytes(bytes: &[u8], name: &Path) -> Result<Self> {
        Self::parse(bytes, name, None)
    }

    /// Reads the part of the field saved in `path` that samples in the box `samples` (world
    /// coordinates) need, for the PU transfer (see the module docs): a window when the file has
    /// the section for one (version 3, saved for the PU) and a patch of the field reaches the
    /// box, else the whole field.
    pub fn load_window(path: &Path, samples: (Vect<D>, Vect<D>)) -> Result<Self> {
        let map = crate::io::mapped::map(path)?;
        Self::parse(&map, path, Some(samples))
    }

    fn parse(bytes: &[u8], path: &Path, samples: Option<(Vect<D>, Vect<D>)>) -> Result<Self> {
        let mut r = Cursor { bytes, at: 0, path };
        if r.take(8)? != MAGIC {
            return Err(Error::format(path, "not a rigidcells field (bad magic)"));
        }
        let version = r.u32()?;
        if !(1..=VERSION).contains(&version) {
            return Err(Error::format(
                path,
                format!("field format version {version}; this rigidcells reads 1 to {VERSION}"),
            ));
        }
        let dim = r.u32()?;
        if dim as usize != D {
            return Err(Error::format(
                path,
                format!("a {dim}D field cannot deform {D}D samples"),
            ));
        }
        let (byte, heights_kept, trended) = match version {
            1 => (2, false, false),
            2 | 3 => (r.take(1)?[0], false, false),
            _ => {
                let byte = r.take(1)?[0];
                (
                    byte & !(HEIGHTS_KEPT | HAS_TREND),
                    byte & HEIGHTS_KEPT != 0,
                    byte & HAS_TREND != 0,
                )
            }
        };
        let mut trend = TrendMap::default();
        if trended {
            for row in 0..D {
                for k in 0..D {
                    trend.affine.linear[(row, k)] = r.f64()?;
                }
            }
            trend.affine.translation = r.vect::<D>()?;
            let k = r.u64()? as usize;
            trend.scale = r.f64()?;
            if k > bytes.len() / (8 * (2 + D)) {
                return Err(Error::format(
                    path,
                    format!("spline center count {k} is wrong"),
                ));
            }
            for _ in 0..k {
                let (x, y) = (r.f64()?, r.f64()?);
                trend.centers.push([x, y]);
                trend.weights.push(r.vect::<D>()?);
            }
            let numbers = trend
                .affine
                .linear
                .iter()
                .chain(trend.affine.translation.iter());
            let spline = trend
                .centers
                .iter()
                .flatten()
                .chain(trend.weights.iter().flatten());
            let usable = numbers.chain(spline).all(|v| in_range(*v))
                && trend.scale > 0.0
                && in_range(trend.scale)
                && trend.affine.inverse().is_some();
            if !usable {
                return Err(Error::format(
                    path,
                    "the trend is not a finite invertible map",
                ));
            }
        }
        let transfer = match version {
            1 => Transfer::Rbf,
            _ => match byte {
                0 => Transfer::Blend,
                1 => Transfer::BlendIdw,
                2 => Transfer::Rbf,
                3 => Transfer::Pu,
                t => return Err(Error::format(path, format!("unknown transfer {t}"))),
            },
        };
        let origin = r.vect::<D>()?;
        if !origin.iter().all(|v| in_range(*v)) {
            return Err(Error::format(
                path,
                format!(
                    "the origin {:?} is not finite or beyond {LARGEST:e}",
                    origin.as_slice()
                ),
            ));
        }
        let n = r.u64()? as usize;
        let record = 8 * (D + 1 + D * D + D);
        if n == 0 || n > bytes.len() / record {
            return Err(Error::format(path, format!("cell count {n} is wrong")));
        }
        let cells_at = r.at;
        r.take(n * record)?;
        let mut maps = Vec::new();
        let mut maps_at = None;
        if version >= 2 {
            let count = r.u64()? as usize;
            if count > n {
                return Err(Error::format(path, format!("map count {count} is wrong")));
            }
            for _ in 0..count {
                let mut linear = Mat::<D>::zeros();
                for row in 0..D {
                    for k in 0..D {
                        linear[(row, k)] = r.f64()?;
                    }
                }
                let translation = r.vect::<D>()?;
                if !(linear.iter().all(|v| in_range(*v))
                    && translation.iter().all(|v| in_range(*v)))
                {
                    return Err(Error::format(
                        path,
                        format!("a prescribed map is not finite or beyond {LARGEST:e}"),
                    ));
                }
                maps.push(Affine {
                    linear,
                    translation,
                });
            }
            if count > 0 {
                maps_at = Some(r.at);
                r.take(4 * n)?;
            }
        }
        let rbf_at = r.at;
        if r.take(1)?[0] != 0 {
            r.take(8 * (D + 1 + D + D * D + D * n))?;
        }
        let window_at = r.at;
        let has_window = version >= 3 && r.take(1)?[0] != 0;
        let section = if has_window {
            Some(Section::read(&mut r)?)
        } else {
            None
        };
        let crs = match version {
            ..=4 => None,
            _ => match r.take(1)?[0] {
                0 => None,
                1 => {
                    let (crs, used) =
                        Crs::from_bytes(&bytes[r.at..]).map_err(|m| Error::format(path, m))?;
                    r.at += used;
                    Some(crs)
                }
                b => return Err(Error::format(path, format!("the CRS flag is {b}"))),
            },
        };
        let mut shapes = Vec::new();
        if version >= 6 {
            let count = r.u32()? as usize;
            for _ in 0..count {
                let m = r.u32()?;
                let shape = super::Shape::read(bytes, &mut r.at)
                    .filter(|_| (m as usize) < maps.len())
                    .ok_or_else(|| Error::format(path, "a region's border is damaged"))?;
                shapes.push((m, shape));
            }
        }
        if r.at != bytes.len() {
            return Err(Error::format(path, "trailing bytes after the field"));
        }
        let cell = |i: usize| -> Result<(Vect<D>, f64, Motion<D>)> {
            let mut c = Cursor {
                bytes,
                at: cells_at + i * record,
                path,
            };
            let center = c.vect::<D>()?;
            let half = c.f64()?;
            let mut rot = Mat::<D>::zeros();
            for row in 0..D {
                for k in 0..D {
                    rot[(row, k)] = c.f64()?;
                }
            }
            let pos = c.vect::<D>()?;
            check_cell(i, &center, half, &rot, &pos).map_err(|m| Error::format(path, m))?;
            Ok((center, half, Motion { rot, pos }))
        };
        let map_of = |i: usize| -> Result<Option<u32>> {
            let Some(at) = maps_at else { return Ok(None) };
            let m = u32::from_le_bytes(bytes[at + 4 * i..at + 4 * i + 4].try_into().expect("4"));
            if m != UNPRESCRIBED && m as usize >= maps.len() {
                return Err(Error::format(path, format!("map index {m} is wrong")));
            }
            Ok(Some(m))
        };
        // The cells a window needs, in ascending order, when one is asked for and possible.
        // (A window that holds no patch, of samples far from every cell, is the whole field:
        // the samples are refused or kept, and the message names the whole field's margin.)
        let window = match (samples, &section) {
            (Some(box_), Some(sec)) if transfer == Transfer::Pu => {
                let center = |i: usize| {
                    if i >= n {
                        return Err(Error::format(
                            path,
                            "the window section's members are wrong",
                        ));
                    }
                    Cursor {
                        bytes,
                        at: cells_at + i * record,
                        path,
                    }
                    .vect::<D>()
                };
                Some(sec.window(bytes, path, box_, origin, center)?)
                    .filter(|(_, layout, _)| !layout.patches.is_empty())
            }
            _ => None,
        };
        let chosen: Box<dyn Iterator<Item = usize>> = match &window {
            Some((cells, _, _)) => Box::new(cells.clone().into_iter()),
            None => Box::new(0..n),
        };
        let mut field = Field {
            origin,
            centers: Vec::new(),
            halves: Vec::new(),
            motions: Vec::new(),
            prescribed: Default::default(),
            heights_kept,
            trend,
        };
        field.prescribed.maps = maps.clone();
        field.prescribed.shapes = shapes;
        for i in chosen {
            let (c, h, m) = cell(i)?;
            field.centers.push(c);
            field.halves.push(h);
            field.motions.push(m);
            if let Some(m) = map_of(i)? {
                field.prescribed.cells.push(m);
            }
        }
        if let Some((_, layout, box_)) = window {
            let frame = section.expect("a window has its section").frame;
            super::leaves::check_window_cells(&field, frame.lower, frame.edge)
                .map_err(|e| Error::format(path, e))?;
            return Ok(Self {
                field,
                transfer,
                rbf: None,
                window: Some(Window {
                    frame,
                    layout,
                    samples: box_,
                }),
                crs,
            });
        }
        let mut r = Cursor {
            bytes,
            at: rbf_at,
            path,
        };
        let rbf = match r.take(1)?[0] {
            0 => None,
            _ => {
                let shift = r.vect::<D>()?;
                let inv_scale = r.f64()?;
                let constant = r.vect::<D>()?;
                let mut linear = [[0.0; D]; D];
                for row in &mut linear {
                    for v in row.iter_mut() {
                        *v = r.f64()?;
                    }
                }
                let mut weights: [Vec<f64>; D] = std::array::from_fn(|_| Vec::new());
                for w in &mut weights {
                    for _ in 0..n {
                        w.push(r.f64()?);
                    }
                }
                let finite = shift.iter().chain(constant.iter()).all(|v| in_range(*v))
                    && linear.iter().flatten().all(|v| in_range(*v))
                    && weights.iter().flatten().all(|v| in_range(*v));
                if !finite {
                    return Err(Error::format(
                        path,
                        format!("the RBF coefficients are not finite or beyond {LARGEST:e}"),
                    ));
                }
                // The frame is the cells' own (their box's center and half extent): one that
                // is not (a fuzzed 1/scale of 5e-324) made every sample NaN.
                if Rbf::frame_of(&field).ok() != Some((shift, inv_scale)) {
                    return Err(Error::format(
                        path,
                        "the RBF's frame does not match the cells' centers",
                    ));
                }
                Some(Rbf::from_parts(
                    &field, shift, inv_scale, constant, linear, weights,
                )?)
            }
        };
        debug_assert!(r.at <= window_at);
        // Every field that `deform` saves has the leaves of an octree for cells: a damaged file
        // is a format error here, not a failure later.
        super::leaves::check_cells(&field).map_err(|e| Error::format(path, e))?;
        Ok(Self {
            field,
            transfer,
            rbf,
            window: None,
            crs,
        })
    }
}

/// Whether a number of a field file is one `deform` could have written: finite and at most
/// [`LARGEST`] in magnitude, the bound of the edit spec's motions and of cell sizes (a fuzzed
/// position of −1.8e308 made the RBF's system singular, a solver failure instead of a
/// format error).
fn in_range(v: f64) -> bool {
    v.is_finite() && v.abs() <= LARGEST
}

/// Why cell `i` of a field file cannot be trusted, if it cannot: a coordinate that is not
/// finite or beyond [`LARGEST`], a half-size that is not positive, a rotation that is not
/// orthonormal (to 1e-6).
fn check_cell<const D: usize>(
    i: usize,
    center: &Vect<D>,
    half: f64,
    rot: &Mat<D>,
    pos: &Vect<D>,
) -> std::result::Result<(), String> {
    let finite = center
        .iter()
        .chain(rot.iter())
        .chain(pos.iter())
        .all(|v| in_range(*v));
    if !finite {
        return Err(format!(
            "cell {i} has a number that is not finite or beyond {LARGEST:e}"
        ));
    }
    if !(half > 0.0 && in_range(half)) {
        return Err(format!("cell {i} has a half-size of {half}"));
    }
    let off = (rot.transpose() * rot - Mat::<D>::identity()).abs().max();
    if off > 1e-6 || super::determinant(rot) <= 0.0 {
        return Err(format!("cell {i}'s rotation is not a rotation"));
    }
    Ok(())
}

/// The window section of a version-3 file: the frame, the PU's grid, and where the patches'
/// boxes, member offsets and members lie in the file.
struct Section<const D: usize> {
    frame: Frame<D>,
    lower: Vect<D>,
    edge: f64,
    patches: usize,
    keys_at: usize,
    offsets_at: usize,
    members_at: usize,
}

impl<const D: usize> Section<D> {
    fn read(r: &mut Cursor<'_>) -> Result<Self> {
        let frame = Frame {
            lower: r.vect::<D>()?,
            edge: r.f64()?,
            margin_shift: r.u32()?,
            bounds: (r.vect::<D>()?, r.vect::<D>()?),
            largest_half: r.f64()?,
        };
        let lower = r.vect::<D>()?;
        let edge = r.f64()?;
        let patches = r.u64()? as usize;
        let path = r.path;
        let bad = |what: &str| Error::format(path, format!("the window section's {what} is wrong"));
        let sizes_ok = [frame.edge, frame.largest_half, edge]
            .iter()
            .all(|v| *v > 0.0 && v.is_finite())
            && [frame.lower, frame.bounds.0, frame.bounds.1, lower]
                .iter()
                .all(|v| v.iter().all(|x| x.is_finite()))
            && frame.margin_shift <= 60
            && patches <= r.bytes.len() / (8 * D + 8);
        if !sizes_ok {
            return Err(bad("grid"));
        }
        let keys_at = r.at;
        r.take(8 * D * patches)?;
        let offsets_at = r.at;
        r.take(8 * (patches + 1))?;
        let offset = |i: usize| {
            u64::from_le_bytes(
                r.bytes[offsets_at + 8 * i..offsets_at + 8 * i + 8]
                    .try_into()
                    .expect("8"),
            ) as usize
        };
        let total = offset(patches);
        if offset(0) != 0 || total > r.bytes.len() / 4 {
            return Err(bad("member count"));
        }
        let members_at = r.at;
        r.take(4 * total)?;
        Ok(Self {
            frame,
            lower,
            edge,
            patches,
            keys_at,
            offsets_at,
            members_at,
        })
    }

    /// The cells (ascending) that samples in `samples` (world) need, the PU layout over them,
    /// and the samples' box in the local frame of `origin` (`center`: cell `i`'s center).
    #[allow(clippy::type_complexity)]
    fn window(
        &self,
        bytes: &[u8],
        path: &Path,
        samples: (Vect<D>, Vect<D>),
        origin: Vect<D>,
        center: impl Fn(usize) -> Result<Vect<D>>,
    ) -> Result<(Vec<usize>, Layout<D>, (Vect<D>, Vect<D>))> {
        let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8"));
        let slack = |a: usize| 1e-9 * (samples.1[a] - samples.0[a]).abs().max(1.0);
        let lo = Vect::<D>::from_fn(|a, _| samples.0[a] - origin[a] - slack(a));
        let hi = Vect::<D>::from_fn(|a, _| samples.1[a] - origin[a] + slack(a));
        let reach = self.frame.reach();
        let support = OVERLAP * self.edge;
        let mut chosen = Vec::new();
        let mut cells = Vec::new();
        for p in 0..self.patches {
            let key: [i64; D] =
                std::array::from_fn(|a| u64_at(self.keys_at + 8 * (D * p + a)) as i64);
            let meets = |pad: f64, reach: f64| {
                (0..D).all(|a| {
                    let from = self.lower[a] + key[a] as f64 * self.edge - pad;
                    let to = self.lower[a] + (key[a] + 1) as f64 * self.edge + pad;
                    to >= lo[a] - reach && from <= hi[a] + reach
                })
            };
            // A patch whose support meets the samples' box is fitted (with all its cells);
            // the cells of one whose box comes within the reach locate samples.
            let fitted = meets(support, 0.0);
            if !fitted && !meets(0.0, reach) {
                continue;
            }
            let (from, to) = (
                u64_at(self.offsets_at + 8 * p) as usize,
                u64_at(self.offsets_at + 8 * (p + 1)) as usize,
            );
            if from > to || to > (bytes.len() - self.members_at) / 4 {
                return Err(Error::format(
                    path,
                    "the window section's members are wrong",
                ));
            }
            let members: Vec<u32> = (from..to)
                .map(|i| {
                    let at = self.members_at + 4 * i;
                    u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4"))
                })
                .collect();
            if fitted {
                cells.extend(members.iter().map(|&i| i as usize));
                chosen.push((key, members));
            } else {
                for &i in &members {
                    let c = center(i as usize)?;
                    if (0..D).all(|a| c[a] >= lo[a] - reach && c[a] <= hi[a] + reach) {
                        cells.push(i as usize);
                    }
                }
            }
        }
        cells.sort_unstable();
        cells.dedup();
        // The members as indices into the window's cells (the order kept).
        for (_, members) in &mut chosen {
            for m in members.iter_mut() {
                *m = cells
                    .binary_search(&(*m as usize))
                    .map_err(|_| Error::format(path, "the window section's members are wrong"))?
                    as u32;
            }
        }
        let layout = Layout {
            lower: self.lower,
            edge: self.edge,
            patches: chosen,
        };
        Ok((cells, layout, (lo, hi)))
    }
}

struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
    path: &'a Path,
}

impl Cursor<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8]> {
        let s = self
            .bytes
            .get(self.at..self.at + n)
            .ok_or_else(|| Error::format(self.path, "the field file is truncated"))?;
        self.at += n;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().expect("4")))
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().expect("8")))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(self.take(8)?.try_into().expect("8")))
    }
    fn vect<const D: usize>(&mut self) -> Result<Vect<D>> {
        let mut v = Vect::<D>::zeros();
        for a in 0..D {
            v[a] = self.f64()?;
        }
        Ok(v)
    }
}

#[cfg(test)]
#[path = "file_tests.rs"]
mod tests;
