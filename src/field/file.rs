//! Deformation fields as files (`deform --save-field`, `apply`).
//!
//! Little-endian binary, exact f64 bits, so that applying a saved field reproduces `deform`'s
//! output bit for bit:
//!
//! ```text
//! "RCFIELD\0"  u32 version (2)  u32 D
//! u8 transfer                        0 blend, 1 blend-idw, 2 rbf, 3 pu (version 2)
//! f64[D] origin                                  world position of the local frame
//! u64 n, then n × (f64[D] center, f64 half, f64[D·D] rotation (row-major), f64[D] position)
//! u64 r, then r × (f64[D·D] linear (row-major), f64[D] translation)   prescribed maps (v2)
//!        and if r > 0: u32[n] the map of each cell (u32::MAX: none)
//! u8 has_rbf, then if 1: f64[D] shift, f64 inv_scale, f64[D] constant, f64[D·D] linear,
//!                        f64[D·n] weights (component by component)
//! ```
//!
//! The RBF coefficients are stored rather than recomputed, because a parallel dense
//! factorization need not give the same last bits on another machine or thread count.
//!
//! Version 2 added the transfer `deform` used (what `apply` uses unless told otherwise) and the
//! maps that fixed and handle cells follow exactly ([`super::Constrained`]). Version 1 files
//! still load: their transfer is the RBF (the one they were saved for) and they prescribe no
//! cell, so their constraints are as exact as the transfer makes them.

use std::io::Read;
use std::path::Path;

use super::{Constrained, Deformer, FREE, Field, Outside, Rbf, Transfer};
use crate::error::{Error, Result};
use crate::rigid::{Affine, Dim, Mat, Motion, Rigid, Vect};

const MAGIC: &[u8; 8] = b"RCFIELD\0";
const VERSION: u32 = 2;

/// A field with its transfer and the RBF coefficients it was saved with, if any.
pub struct SavedField<const D: usize> {
    /// The cells and motions.
    pub field: Field<D>,
    /// The transfer the field was made for.
    pub transfer: Transfer,
    rbf: Option<Rbf<D>>,
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
        }
    }

    /// Whether the file holds the RBF's coefficients.
    pub fn has_rbf(&self) -> bool {
        self.rbf.is_some()
    }

    /// The map of space for `transfer` (`None`: the field's own): the saved RBF coefficients
    /// (evaluated through the far field within `rbf_tolerance`, when given) or a new blend or
    /// RBF, with the prescribed cells exact and samples beyond the margin handled by `outside`.
    pub fn deformer(
        self,
        transfer: Option<Transfer>,
        rbf_tolerance: Option<f64>,
        outside: Outside,
    ) -> Result<Constrained<D>> {
        self.deformer_with(transfer, rbf_tolerance, outside, Deformer::new)
    }

    /// As [`SavedField::deformer`], but the PU transfer fits its patches only where samples
    /// reach ([`Deformer::on_demand`]): applying a large field to one tile fits the patches
    /// around the tile, with the same bits.
    pub fn tile_deformer(
        self,
        transfer: Option<Transfer>,
        rbf_tolerance: Option<f64>,
        outside: Outside,
    ) -> Result<Constrained<D>> {
        self.deformer_with(transfer, rbf_tolerance, outside, Deformer::on_demand)
    }

    fn deformer_with(
        self,
        transfer: Option<Transfer>,
        rbf_tolerance: Option<f64>,
        outside: Outside,
        make: fn(&Field<D>, Transfer) -> Result<Deformer<D>>,
    ) -> Result<Constrained<D>> {
        let inner = match (transfer.unwrap_or(self.transfer), self.rbf) {
            (Transfer::Rbf, Some(r)) => Deformer::Rbf(r),
            (t, _) => make(&self.field, t)?,
        }
        .with_rbf_tolerance(rbf_tolerance)?;
        Constrained::new(&self.field, inner, outside)
    }

    /// Writes the field to `path` atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let f = &self.field;
        let mut out = Vec::new();
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(D as u32).to_le_bytes());
        out.push(match self.transfer {
            Transfer::Blend => 0,
            Transfer::BlendIdw => 1,
            Transfer::Rbf => 2,
            Transfer::Pu => 3,
        });
        let put = |out: &mut Vec<u8>, v: f64| out.extend_from_slice(&v.to_le_bytes());
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
                let m = prescribed.cells.get(c).copied().unwrap_or(FREE);
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
        crate::io::write_atomic(path, &out)
    }

    /// Reads a field saved by [`SavedField::save`].
    pub fn load(path: &Path) -> Result<Self> {
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .and_then(|mut f| f.read_to_end(&mut bytes))
            .map_err(|e| Error::io(path, e))?;
        let mut r = Cursor {
            bytes: &bytes,
            at: 0,
            path,
        };
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
        let transfer = match version {
            1 => Transfer::Rbf,
            _ => match r.take(1)?[0] {
                0 => Transfer::Blend,
                1 => Transfer::BlendIdw,
                2 => Transfer::Rbf,
                3 => Transfer::Pu,
                t => return Err(Error::format(path, format!("unknown transfer {t}"))),
            },
        };
        let origin = r.vect::<D>()?;
        let n = r.u64()? as usize;
        if n == 0 || n > bytes.len() {
            return Err(Error::format(path, format!("cell count {n} is wrong")));
        }
        let (mut centers, mut halves, mut motions) = (vec![], vec![], vec![]);
        for _ in 0..n {
            centers.push(r.vect::<D>()?);
            halves.push(r.f64()?);
            let mut rot = Mat::<D>::zeros();
            for row in 0..D {
                for k in 0..D {
                    rot[(row, k)] = r.f64()?;
                }
            }
            motions.push(Motion {
                rot,
                pos: r.vect::<D>()?,
            });
        }
        let mut field = Field {
            origin,
            centers,
            halves,
            motions,
            prescribed: Default::default(),
        };
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
                field.prescribed.maps.push(Affine {
                    linear,
                    translation,
                });
            }
            if count > 0 {
                for _ in 0..n {
                    let m = r.u32()?;
                    if m != FREE && m as usize >= count {
                        return Err(Error::format(path, format!("map index {m} is wrong")));
                    }
                    field.prescribed.cells.push(m);
                }
            }
        }
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
                Some(Rbf::from_parts(
                    &field, shift, inv_scale, constant, linear, weights,
                )?)
            }
        };
        if r.at != bytes.len() {
            return Err(Error::format(path, "trailing bytes after the field"));
        }
        // Every field that `deform` saves has the leaves of an octree for cells: a damaged file
        // is a format error here, not a failure later.
        super::leaves::check_cells(&field).map_err(|e| Error::format(path, e))?;
        Ok(Self {
            field,
            transfer,
            rbf,
        })
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
mod tests {
    use super::*;

    /// Eight unit cells around the origin, each moved a little, the first fixed.
    fn field() -> Field<3> {
        let centers: Vec<Vect<3>> = (0..8)
            .map(|k| Vect::<3>::from_fn(|a, _| if k >> a & 1 == 1 { 0.5 } else { -0.5 }))
            .collect();
        let motions = centers
            .iter()
            .map(|c| Motion {
                rot: Mat::<3>::identity(),
                pos: c + Vect::<3>::new(0.0, 0.0, 0.1 * c.x),
            })
            .collect();
        let mut prescribed = super::super::Prescribed::default();
        prescribed.set(0, 8, Affine::identity());
        Field {
            origin: Vect::<3>::new(1e6, 2e6, 0.0),
            halves: vec![0.5; 8],
            centers,
            motions,
            prescribed,
        }
    }

    #[test]
    fn saves_and_loads_the_transfer_and_the_prescribed_maps() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.field");
        let f = field();
        SavedField::new(f.clone(), Transfer::BlendIdw, None)
            .save(&path)
            .unwrap();
        let back = SavedField::<3>::load(&path).unwrap();
        assert_eq!(back.transfer, Transfer::BlendIdw);
        assert_eq!(back.field, f);
        assert!(back.rbf.is_none());
    }

    /// A version-1 file (no transfer, no maps) still loads, as a field for the RBF.
    #[test]
    fn loads_version_1_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v2.field");
        let mut f = field();
        f.prescribed = Default::default();
        let rbf = Rbf::new(&f).unwrap();
        SavedField::new(f.clone(), Transfer::Rbf, Some(rbf))
            .save(&path)
            .unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[8..12].copy_from_slice(&1u32.to_le_bytes());
        let cells = 16 + 1 + 3 * 8 + 8 + 8 * (3 + 1 + 9 + 3) * 8;
        assert_eq!(bytes[cells..cells + 8], 0u64.to_le_bytes(), "no maps");
        bytes.drain(cells..cells + 8);
        bytes.remove(16);
        let v1 = dir.path().join("v1.field");
        std::fs::write(&v1, &bytes).unwrap();
        let back = SavedField::<3>::load(&v1).unwrap();
        assert_eq!(back.transfer, Transfer::Rbf);
        assert_eq!(back.field, f);
        assert!(back.rbf.is_some());
        bytes[8..12].copy_from_slice(&3u32.to_le_bytes());
        std::fs::write(&v1, &bytes).unwrap();
        let e = SavedField::<3>::load(&v1).err().unwrap().to_string();
        assert!(e.contains("version 3"), "{e}");
    }
}
