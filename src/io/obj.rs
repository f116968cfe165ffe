//! Wavefront OBJ: `v` lines moved, `vn` lines transformed, every other byte kept.
//!
//! Positions are the `v` lines in order; faces (`f`, any number of corners, `v/vt/vn` forms,
//! negative relative indices) are fan-triangulated for the cells. A normal `vn k` is transformed
//! at the vertex of its first face corner; normals no face refers to are kept as they are.
//! Writing replaces the number tokens of `v` and `vn` lines (with the precision of their columns
//! in the input, [`super::text`]) and copies everything else.
//!
//! An OBJ file is read whole ([`ObjFile`]: its faces refer to vertices anywhere in the file,
//! and its normals are found through them) and served in chunks by [`ObjSource`], whose sink
//! collects the moved samples and writes the file at the end.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::stream::{Accepted, Bounds, Chunk, ResultSet, Sink, Source};
use super::text::{Edit, Precision, Span, check_count, edits3, splice};
use super::{Opening, require_extension};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// An OBJ file held in memory with the locations of its coordinates.
#[derive(Debug)]
pub struct ObjFile {
    path: PathBuf,
    bytes: Vec<u8>,
    coords: Vec<[Span; 3]>,
    positions: Vec<Vect<3>>,
    normal_spans: Vec<[Span; 3]>,
    normals: Vec<Vect<3>>,
    /// For each normal, the vertex of its first face corner.
    normal_vertex: Vec<Option<u32>>,
    triangles: Vec<[u32; 3]>,
    /// The precision of the `v` and `vn` columns.
    precision: Precision,
}

/// The three number tokens after the keyword of `line` (starting at byte `at` of the file).
fn three(bytes: &[u8], line: Span, skip: usize) -> Option<([Span; 3], [f64; 3])> {
    let mut spans = [Span { start: 0, end: 0 }; 3];
    let mut values = [0.0; 3];
    let mut pos = line.start + skip;
    for k in 0..3 {
        while pos < line.end && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < line.end && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let text = std::str::from_utf8(&bytes[start..pos]).ok()?;
        values[k] = text.parse().ok()?;
        spans[k] = Span { start, end: pos };
    }
    Some((spans, values))
}

impl ObjFile {
    /// Reads and indexes `path`.
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let err = |line: usize, m: String| Error::format(path, format!("line {line}: {m}"));
        let (mut coords, mut positions) = (Vec::new(), Vec::new());
        let (mut normal_spans, mut normals) = (Vec::new(), Vec::new());
        let mut normal_vertex: Vec<Option<u32>> = Vec::new();
        let mut precision = Precision::default();
        // (line, corners (vertex, normal), vertices and normals defined before the face)
        type Face = (usize, Vec<(i64, Option<i64>)>, usize, usize);
        let mut faces: Vec<Face> = Vec::new();
        let mut start = 0;
        for (number, raw) in bytes.split(|&b| b == b'\n').enumerate() {
            let line = Span {
                start,
                end: start + raw.len(),
            };
            start = line.end + 1;
            let trimmed = raw.trim_ascii_start();
            let lead = raw.len() - trimmed.len();
            let keyword = trimmed
                .split(|b| b.is_ascii_whitespace())
                .next()
                .unwrap_or(&[]);
            match keyword {
                b"v" => {
                    let (s, v) = three(&bytes, line, lead + 1)
                        .ok_or_else(|| err(number + 1, "a `v` line needs three numbers".into()))?;
                    if !v.iter().all(|x| x.is_finite()) {
                        return Err(err(number + 1, "a coordinate is not finite".into()));
                    }
                    precision.see3(0, &bytes, &s);
                    coords.push(s);
                    positions.push(Vect::<3>::from(v));
                }
                b"vn" => {
                    let (s, v) = three(&bytes, line, lead + 2)
                        .ok_or_else(|| err(number + 1, "a `vn` line needs three numbers".into()))?;
                    precision.see3(3, &bytes, &s);
                    normal_spans.push(s);
                    normals.push(Vect::<3>::from(v));
                    normal_vertex.push(None);
                }
                b"f" => {
                    let text = String::from_utf8_lossy(&trimmed[1..]);
                    let mut corners = Vec::new();
                    for token in text.split_ascii_whitespace() {
                        let mut parts = token.split('/');
                        let v = parts
                            .next()
                            .and_then(|p| p.parse::<i64>().ok())
                            .ok_or_else(|| {
                                err(
                                    number + 1,
                                    format!("face corner `{token}` has no vertex index"),
                                )
                            })?;
                        let vn = parts.nth(1).and_then(|p| p.parse::<i64>().ok());
                        corners.push((v, vn));
                    }
                    faces.push((number + 1, corners, positions.len(), normals.len()));
                }
                _ => {}
            }
        }
        let mut triangles = Vec::new();
        for (line, corners, nv, nn) in faces {
            // Indices are 1-based; negative ones count back from the last defined element.
            let resolve = |i: i64, n: usize, what: &str| -> Result<u32> {
                let k = if i > 0 { i - 1 } else { n as i64 + i };
                if i == 0 || k < 0 || k >= n as i64 {
                    return Err(err(
                        line,
                        format!("{what} index {i} is out of range (there are {n})"),
                    ));
                }
                Ok(k as u32)
            };
            let mut vs = Vec::with_capacity(corners.len());
            for (v, vn) in corners {
                let v = resolve(v, nv, "vertex")?;
                if let Some(vn) = vn {
                    let k = resolve(vn, nn, "normal")? as usize;
                    normal_vertex[k].get_or_insert(v);
                }
                vs.push(v);
            }
            for k in 2..vs.len() {
                triangles.push([vs[0], vs[k - 1], vs[k]]);
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            bytes,
            coords,
            positions,
            normal_spans,
            normals,
            normal_vertex,
            triangles,
            precision,
        })
    }

    /// Vertex positions.
    pub fn positions(&self) -> &[Vect<3>] {
        &self.positions
    }

    /// Triangles of the faces.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The normals some face refers to, each with the position it is transformed at.
    pub fn loose_normals(&self) -> Vec<(Vect<3>, Vect<3>)> {
        self.normals
            .iter()
            .zip(&self.normal_vertex)
            .filter_map(|(n, v)| v.map(|v| (self.positions[v as usize], *n)))
            .collect()
    }

    /// The file with positions and the referenced normals (in the order of
    /// [`ObjFile::loose_normals`]) replaced.
    pub fn encode(&self, positions: &[Vect<3>], normals: &[Vect<3>]) -> Result<Vec<u8>> {
        check_count(&self.path, positions.len(), self.positions.len())?;
        let mut edits: Vec<Edit> = Vec::with_capacity(3 * positions.len());
        for ((spans, p), old) in self.coords.iter().zip(positions).zip(&self.positions) {
            edits.extend(edits3(spans, p, old, [false; 3], 0));
        }
        let referenced = self
            .normal_spans
            .iter()
            .zip(&self.normals)
            .zip(&self.normal_vertex)
            .filter(|(_, v)| v.is_some());
        for (((spans, old), _), n) in referenced.zip(normals) {
            edits.extend(edits3(spans, n, old, [false; 3], 3));
        }
        Ok(splice(&self.bytes, edits, &self.precision))
    }
}

/// An OBJ file read whole ([`ObjFile`]), served as a [`Source`].
pub struct ObjSource {
    path: PathBuf,
    file: Arc<ObjFile>,
    next: usize,
}

impl ObjSource {
    /// Reads `path` for streaming; a file without vertices is refused.
    pub fn open(path: &Path) -> Result<Self> {
        Self::open_as(path, Opening::Stream)
    }

    /// Reads `path`, checking what `opening` asks.
    pub(super) fn open_as(path: &Path, opening: Opening) -> Result<Self> {
        let file = ObjFile::read(path)?;
        if opening == Opening::Stream && file.positions.is_empty() {
            return Err(Error::format(path, "the file holds no vertices or points"));
        }
        Ok(Self {
            path: path.to_path_buf(),
            file: Arc::new(file),
            next: 0,
        })
    }
}

impl Source for ObjSource {
    fn path(&self) -> &Path {
        &self.path
    }

    fn len(&self) -> u64 {
        self.file.positions.len() as u64
    }

    fn triangles(&self) -> &[[u32; 3]] {
        &self.file.triangles
    }

    fn loose_normals(&self) -> Vec<(Vect<3>, Vect<3>)> {
        self.file.loose_normals()
    }

    fn rewind(&mut self) -> Result<()> {
        self.next = 0;
        Ok(())
    }

    fn read(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        let all = &self.file.positions;
        let end = self.next.saturating_add(max).min(all.len());
        chunk.clear(self.next as u64);
        chunk.positions.extend_from_slice(&all[self.next..end]);
        let n = end - self.next;
        self.next = end;
        Ok(n)
    }

    fn sink(&self, output: &Path, _bounds: Option<Bounds>) -> Result<Box<dyn Sink>> {
        require_extension(output, "obj")?;
        Ok(Box::new(ObjSink {
            file: self.file.clone(),
            output: output.to_path_buf(),
            positions: Vec::with_capacity(self.file.positions.len()),
            loose: Vec::new(),
        }))
    }
}

/// Collects the moved samples of an [`ObjSource`] and writes the file at the end.
struct ObjSink {
    file: Arc<ObjFile>,
    output: PathBuf,
    positions: Vec<Vect<3>>,
    loose: Vec<Vect<3>>,
}

impl Sink for ObjSink {
    fn written(&self, p: &Vect<3>) -> Vect<3> {
        Vect::<3>::from_fn(|k, _| self.file.precision.written(k, p[k], false))
    }

    fn rounding(&self) -> Option<String> {
        Some("the output's decimals".into())
    }

    fn write(
        &mut self,
        _chunk: &Chunk,
        moved: &[Vect<3>],
        _normals: &[Vect<3>],
    ) -> Result<Accepted> {
        self.positions.extend_from_slice(moved);
        Ok(Accepted::Yes)
    }

    fn loose_normals(&mut self, normals: Vec<Vect<3>>) {
        self.loose = normals;
    }

    fn finish(self: Box<Self>, set: &ResultSet) -> Result<Vec<String>> {
        require_extension(&self.output, "obj")?;
        let bytes = self.file.encode(&self.positions, &self.loose)?;
        set.write(&self.output, &bytes)?;
        Ok(Vec::new())
    }
}
