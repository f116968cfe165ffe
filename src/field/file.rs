//! Deformation fields as files (`deform --save-field`, `apply`).
//!
//! Little-endian binary, exact f64 bits, so that applying a saved field reproduces `deform`'s
//! output bit for bit:
//!
//! ```text
//! "RCFIELD\0"  u32 version (1)  u32 D
//! f64[D] origin                                  world position of the local frame
//! u64 n, then n × (f64[D] center, f64 half, f64[D·D] rotation (row-major), f64[D] position)
//! u8 has_rbf, then if 1: f64[D] shift, f64 inv_scale, f64[D] constant, f64[D·D] linear,
//!                        f64[D·n] weights (component by component)
//! ```
//!
//! The RBF coefficients are stored rather than recomputed, because a parallel dense
//! factorization need not give the same last bits on another machine or thread count.

use std::io::Read;
use std::path::Path;

use super::{Deformer, Field, Rbf, Transfer};
use crate::error::{Error, Result};
use crate::rigid::{Mat, Motion, Vect};

const MAGIC: &[u8; 8] = b"RCFIELD\0";
const VERSION: u32 = 1;

/// A field with the RBF coefficients it was saved with, if any.
pub struct SavedField<const D: usize> {
    /// The cells and motions.
    pub field: Field<D>,
    rbf: Option<Rbf<D>>,
}

impl<const D: usize> SavedField<D> {
    /// Wraps a field and, optionally, its RBF transfer.
    pub fn new(field: Field<D>, rbf: Option<Rbf<D>>) -> Self {
        Self { field, rbf }
    }

    /// The transfer for `transfer`: the saved RBF coefficients (evaluated through the far
    /// field within `rbf_tolerance`, when given), or a new blend.
    pub fn deformer(self, transfer: Transfer, rbf_tolerance: Option<f64>) -> Result<Deformer<D>> {
        match (transfer, self.rbf) {
            (Transfer::Rbf, Some(r)) => Deformer::Rbf(r),
            (t, _) => Deformer::new(&self.field, t)?,
        }
        .with_rbf_tolerance(rbf_tolerance)
    }

    /// Writes the field to `path` atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let f = &self.field;
        let mut out = Vec::new();
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(D as u32).to_le_bytes());
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
        match &self.rbf {
            None => out.push(0),
            Some(rbf) => {
                out.push(1);
                let (shift, inv_scale, constant, linear, weights) = rbf.parts();
                shift.iter().for_each(|&v| put(&mut out, v));
                put(&mut out, inv_scale);
                constant.iter().for_each(|&v| put(&mut out, v));
                linear.iter().flatten().for_each(|&v| put(&mut out, v));
                weights.iter().flatten().for_each(|&v| put(&mut out, v));
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
        if version != VERSION {
            return Err(Error::format(
                path,
                format!("field format version {version}; this rigidcells reads {VERSION}"),
            ));
        }
        let dim = r.u32()?;
        if dim as usize != D {
            return Err(Error::format(
                path,
                format!("a {dim}D field cannot deform {D}D samples"),
            ));
        }
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
        let field = Field {
            origin,
            centers,
            halves,
            motions,
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
                Some(Rbf::from_parts(
                    &field, shift, inv_scale, constant, linear, weights,
                )?)
            }
        };
        if r.at != bytes.len() {
            return Err(Error::format(path, "trailing bytes after the field"));
        }
        Ok(Self { field, rbf })
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
