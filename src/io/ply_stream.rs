//! The sources of PLY files, streamed from a memory map: the one reader of PLY, for files of
//! any size.
//!
//! [`PlyStream`]: when the body is binary and every property of the vertex element is a scalar, all vertex
//! records have one size and record `i` starts at `start + i · record`. The header is parsed by
//! `ply-rs-bw` (with the tolerance of [`super::ply`]); the other elements, before and after the
//! vertices, are walked once to collect the triangles of faces and strips and to find where the
//! vertex records begin. Chunks are then decoded straight from the map, and the sink copies the
//! input's bytes through, patching `x y z` (and `nx ny nz`) of each record in place. Nothing of
//! the body is held in memory but the chunk in flight (and, for meshes, the triangles).
//!
//! `tools/src/bin/ply.rs` measures this against reading the same file with `ply-rs-bw`.
//!
//! [`PlyRecordStream`] walks the vertex records one by one: ASCII PLY, binary PLY whose
//! vertices have list properties, and any PLY read whole ([`super::Document::read`]), whose
//! every record it checks, in file order, as it opens.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use memmap2::Mmap;
use ply_rs_bw::ply::{ElementDef, Encoding, Header, PropertyType};

use super::mapped::map;
use super::ply::numbers;
use super::ply::{
    VertexFields, Walker, check_triangles, parse_header, scalar_size, vertex_layout, walk_element,
};
use super::stream::{Accepted, Bounds, Chunk, OutFile, ResultSet, Sink, Source, TempFile};
use super::text::{Precision, SpanSink, fit_singles};
use super::{Opening, require_extension};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// Where one floating-point property lies in a vertex record.
#[derive(Debug, Clone, Copy)]
struct Slot {
    offset: usize,
    double: bool,
}

/// The fixed layout of the vertex records.
#[derive(Debug, Clone, Copy)]
struct Layout {
    big: bool,
    /// Byte offset of the first vertex record.
    start: usize,
    /// Bytes per record.
    record: usize,
    count: usize,
    xyz: [Slot; 3],
    normals: Option<[Slot; 3]>,
}

impl Layout {
    #[inline]
    fn get(&self, rec: &[u8], s: Slot) -> f64 {
        let b = &rec[s.offset..];
        match (s.double, self.big) {
            (true, false) => f64::from_le_bytes(b[..8].try_into().expect("8 bytes")),
            (true, true) => f64::from_be_bytes(b[..8].try_into().expect("8 bytes")),
            (false, false) => f32::from_le_bytes(b[..4].try_into().expect("4 bytes")) as f64,
            (false, true) => f32::from_be_bytes(b[..4].try_into().expect("4 bytes")) as f64,
        }
    }

    #[inline]
    fn put(&self, rec: &mut [u8], s: Slot, v: f64) {
        let b = &mut rec[s.offset..];
        match (s.double, self.big) {
            (true, false) => b[..8].copy_from_slice(&v.to_le_bytes()),
            (true, true) => b[..8].copy_from_slice(&v.to_be_bytes()),
            (false, false) => b[..4].copy_from_slice(&(v as f32).to_le_bytes()),
            (false, true) => b[..4].copy_from_slice(&(v as f32).to_be_bytes()),
        }
    }

    fn vector(&self, rec: &[u8], s: &[Slot; 3]) -> Vect<3> {
        Vect::<3>::new(
            self.get(rec, s[0]),
            self.get(rec, s[1]),
            self.get(rec, s[2]),
        )
    }

    /// Byte range of records `first..first + n`.
    fn span(&self, first: usize, n: usize) -> std::ops::Range<usize> {
        self.start + first * self.record..self.start + (first + n) * self.record
    }
}

/// A PLY file mapped, its header parsed, and the types of its vertex coordinates.
struct Opened {
    map: Mmap,
    header: Header,
    /// Offset of the body.
    body: usize,
    doubles: [bool; 3],
    normal_doubles: Option<[bool; 3]>,
}

impl Opened {
    fn new(path: &Path) -> Result<Self> {
        let map = map(path)?;
        let err = |m: String| Error::format(path, m);
        if !map.starts_with(b"ply") {
            return Err(err("not a PLY file (no `ply` magic line)".into()));
        }
        let (header, body) = parse_header(&map).map_err(err)?;
        let (doubles, normal_doubles) = vertex_layout(&header).map_err(err)?;
        Ok(Self {
            map,
            header,
            body,
            doubles,
            normal_doubles,
        })
    }
}

/// Opens the PLY file `path` as a [`Source`]: binary files with fixed-size vertex records as a
/// [`PlyStream`], the others (ASCII, or vertices with list properties) as a
/// [`PlyRecordStream`].
pub(super) fn open(path: &Path) -> Result<Box<dyn Source>> {
    let opened = Opened::new(path)?;
    if mapped_vertices(&opened.header) {
        Ok(Box::new(PlyStream::from_opened(path, opened)?))
    } else {
        Ok(Box::new(PlyRecordStream::from_opened(
            path,
            opened,
            Opening::Stream,
        )?))
    }
}

/// Whether the vertex records can be patched in place in the map ([`PlyStream`]): a binary body
/// whose vertex properties are all scalars, so that every vertex record has one size.
fn mapped_vertices(header: &Header) -> bool {
    header.encoding != Encoding::Ascii
        && header.elements["vertex"]
            .properties
            .values()
            .all(|p| matches!(p.data_type, PropertyType::Scalar(_)))
}

/// A binary PLY file with fixed-size vertex records, streamed from a memory map.
pub struct PlyStream {
    path: PathBuf,
    map: Arc<Mmap>,
    layout: Layout,
    triangles: Vec<[u32; 3]>,
    next: usize,
}

impl PlyStream {
    /// Opens `path` for streaming; `None` when it is ASCII or its vertices have list properties
    /// (then it streams through [`PlyRecordStream`]).
    pub fn open(path: &Path) -> Result<Option<Self>> {
        let opened = Opened::new(path)?;
        if !mapped_vertices(&opened.header) {
            return Ok(None);
        }
        Self::from_opened(path, opened).map(Some)
    }

    /// A stream over `opened`, whose vertex records must be [`mapped_vertices`].
    fn from_opened(path: &Path, opened: Opened) -> Result<Self> {
        let Opened {
            map,
            header,
            body,
            doubles,
            normal_doubles,
        } = opened;
        let err = |m: String| Error::format(path, m);
        let big = header.encoding == Encoding::BinaryBigEndian;
        let vertex = &header.elements["vertex"];
        let mut offsets = std::collections::HashMap::new();
        let mut record = 0;
        for (name, p) in vertex.properties.iter() {
            if let PropertyType::Scalar(t) = &p.data_type {
                offsets.insert(name.as_str(), record);
                record += scalar_size(t);
            }
        }
        let slots = |names: [&str; 3], doubles: [bool; 3]| -> [Slot; 3] {
            std::array::from_fn(|k| Slot {
                offset: offsets[names[k]],
                double: doubles[k],
            })
        };
        let mut walker = Walker::new(&map, body, header.encoding, path);
        let mut triangles = Vec::new();
        let mut start = None;
        for (name, element) in header.elements.iter() {
            if name == "vertex" {
                let end = element
                    .count
                    .checked_mul(record)
                    .and_then(|n| n.checked_add(walker.pos))
                    .filter(|&end| end <= map.len())
                    .ok_or_else(|| {
                        err(format!(
                            "the body ends within the {} vertices (truncated file, or a header \
                             count that is too large)",
                            element.count
                        ))
                    })?;
                start = Some(walker.pos);
                walker.pos = end;
            } else {
                let records = 0..element.count;
                walk_element(&mut walker, name, element, records, &mut triangles, |_| {
                    Ok(())
                })?;
            }
        }
        let count = vertex.count;
        if count == 0 {
            return Err(err("the file holds no vertices or points".into()));
        }
        check_triangles(path, &triangles, count)?;
        let layout = Layout {
            big,
            start: start.expect("the header has a vertex element"),
            record,
            count,
            xyz: slots(["x", "y", "z"], doubles),
            normals: normal_doubles.map(|d| slots(["nx", "ny", "nz"], d)),
        };
        Ok(Self {
            path: path.to_path_buf(),
            map: Arc::new(map),
            layout,
            triangles,
            next: 0,
        })
    }
}

impl Source for PlyStream {
    fn path(&self) -> &Path {
        &self.path
    }

    fn len(&self) -> u64 {
        self.layout.count as u64
    }

    fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    fn rewind(&mut self) -> Result<()> {
        self.next = 0;
        Ok(())
    }

    fn read(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        let l = &self.layout;
        let n = max.min(l.count - self.next);
        chunk.clear(self.next as u64);
        for rec in self.map[l.span(self.next, n)].chunks_exact(l.record) {
            chunk.positions.push(l.vector(rec, &l.xyz));
            if let Some(s) = &l.normals {
                chunk.normals.push(l.vector(rec, s));
            }
        }
        self.next += n;
        Ok(n)
    }

    fn sink(&self, output: &Path, _bounds: Option<Bounds>) -> Result<Box<dyn Sink>> {
        require_extension(output, "ply")?;
        let (file, out) = TempFile::create(output)?;
        Ok(Box::new(PlySink {
            map: self.map.clone(),
            layout: self.layout,
            file,
            out,
            buf: Vec::new(),
            next: 0,
        }))
    }
}

/// Copies a [`PlyStream`]'s bytes with the vertex records patched.
struct PlySink {
    map: Arc<Mmap>,
    layout: Layout,
    file: TempFile,
    out: BufWriter<OutFile>,
    buf: Vec<u8>,
    /// Records written so far.
    next: usize,
}

impl PlySink {
    fn put(&mut self, bytes: &[u8]) -> Result<()> {
        self.out
            .write_all(bytes)
            .map_err(|e| Error::write(self.file.target(), e))
    }
}

impl Sink for PlySink {
    fn written(&self, p: &Vect<3>) -> Vect<3> {
        Vect::<3>::from_fn(|k, _| match self.layout.xyz[k].double {
            true => p[k],
            false => p[k] as f32 as f64,
        })
    }

    fn rounding(&self) -> Option<String> {
        (!self.layout.xyz.iter().all(|s| s.double))
            .then(|| "the output's single-precision floats".into())
    }

    fn write(&mut self, chunk: &Chunk, moved: &[Vect<3>], normals: &[Vect<3>]) -> Result<Accepted> {
        let map = self.map.clone();
        let l = self.layout;
        if chunk.first as usize != self.next || self.next + moved.len() > l.count {
            return Err(Error::solver(format!(
                "{}: chunks out of order (at {}, expected {})",
                self.file.target().display(),
                chunk.first,
                self.next
            )));
        }
        if self.next == 0 {
            self.put(&map[..l.start])?;
        }
        let mut buf = std::mem::take(&mut self.buf);
        buf.clear();
        buf.extend_from_slice(&map[l.span(self.next, moved.len())]);
        for (i, (rec, p)) in buf.chunks_exact_mut(l.record).zip(moved).enumerate() {
            for k in 0..3 {
                l.put(rec, l.xyz[k], p[k]);
            }
            if let (Some(s), Some(n)) = (&l.normals, normals.get(i)) {
                let n = fit_singles(n, s.map(|s| !s.double));
                for k in 0..3 {
                    l.put(rec, s[k], n[k]);
                }
            }
        }
        self.put(&buf)?;
        self.buf = buf;
        self.next += moved.len();
        Ok(Accepted::Yes)
    }

    fn finish(mut self: Box<Self>, set: &ResultSet) -> Result<Vec<String>> {
        let l = self.layout;
        if self.next != l.count {
            return Err(Error::solver(format!(
                "{}: {} of {} vertices written",
                self.file.target().display(),
                self.next,
                l.count
            )));
        }
        let map = self.map.clone();
        self.put(&map[l.span(0, l.count).end..])?;
        let Self { file, out, .. } = *self;
        set.stage_writer(file, out)?;
        Ok(Vec::new())
    }
}

/// A PLY file whose vertex records are walked one by one, streamed from a memory map: ASCII, or
/// binary with list properties on its vertices (records of varying size); and any PLY read
/// whole ([`super::Document::read`]). `open` walks the whole body once to validate it (every
/// record, in file order) and to collect faces; a chunk then walks its vertex records from where the previous one stopped and carries
/// the bytes from there through its last record (from the file's start for the first chunk, to
/// its end for the last) with the spans of their numbers, so the chunks' bytes partition the
/// file and the `SpanSink` writes the new numbers over them (as text,
/// or as floats in the file's byte order).
pub struct PlyRecordStream {
    path: PathBuf,
    map: Arc<Mmap>,
    encoding: Encoding,
    vertex: ElementDef,
    /// Byte offset of the first vertex record.
    start: usize,
    /// Whether `x y z` (and `nx ny nz`) are written as single precision.
    singles: [bool; 3],
    normal_singles: Option<[bool; 3]>,
    triangles: Vec<[u32; 3]>,
    /// The precision of the coordinate and normal columns of an ASCII body, gathered while
    /// the body is validated.
    precision: Precision,
    /// Where the next chunk's records begin, and its first vertex.
    pos: usize,
    next: usize,
}

impl PlyRecordStream {
    /// Opens `path` for streaming, whatever its encoding (binary files with fixed-size vertex
    /// records stream faster through [`PlyStream`]).
    pub fn open(path: &Path) -> Result<Self> {
        Self::open_as(path, Opening::Stream)
    }

    /// Opens `path` as [`PlyRecordStream::open`] does; to be read whole (`opening`), a file
    /// without vertices opens.
    pub(super) fn open_as(path: &Path, opening: Opening) -> Result<Self> {
        Self::from_opened(path, Opened::new(path)?, opening)
    }

    fn from_opened(path: &Path, opened: Opened, opening: Opening) -> Result<Self> {
        let Opened {
            map,
            header,
            body,
            doubles,
            normal_doubles,
        } = opened;
        let err = |m: String| Error::format(path, m);
        let mut walker = Walker::new(&map, body, header.encoding, path);
        let mut triangles = Vec::new();
        let mut start = body;
        let mut precision = Precision::default();
        let ascii = header.encoding == Encoding::Ascii;
        let with_normals = normal_doubles.is_some();
        for (name, element) in header.elements.iter() {
            let records = 0..element.count;
            if name != "vertex" {
                walk_element(&mut walker, name, element, records, &mut triangles, |_| {
                    Ok(())
                })?;
                continue;
            }
            start = walker.pos;
            let mut fields = VertexFields::default();
            walk_element(
                &mut walker,
                name,
                element,
                records,
                &mut triangles,
                |visit| {
                    let Some(record) = fields.take(visit) else {
                        return Ok(());
                    };
                    let (spans, _, nspans, _) = fields.checked(path, record)?;
                    if ascii {
                        precision.see3(0, &map, &spans);
                        if with_normals {
                            precision.see3(3, &map, &nspans);
                        }
                    }
                    Ok(())
                },
            )?;
        }
        if header.encoding == Encoding::Ascii
            && map[walker.pos..].iter().any(|b| !b.is_ascii_whitespace())
        {
            return Err(err(
                "data after the last element: the header's counts are smaller than the body".into(),
            ));
        }
        let vertex = header.elements["vertex"].clone();
        if vertex.count == 0 && opening == Opening::Stream {
            return Err(err("the file holds no vertices or points".into()));
        }
        check_triangles(path, &triangles, vertex.count)?;
        Ok(Self {
            path: path.to_path_buf(),
            map: Arc::new(map),
            encoding: header.encoding,
            vertex,
            start,
            singles: doubles.map(|d| !d),
            normal_singles: normal_doubles.map(|d| d.map(|d| !d)),
            triangles,
            precision,
            pos: start,
            next: 0,
        })
    }
}

impl Source for PlyRecordStream {
    fn path(&self) -> &Path {
        &self.path
    }

    fn len(&self) -> u64 {
        self.vertex.count as u64
    }

    fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    fn rewind(&mut self) -> Result<()> {
        (self.pos, self.next) = (self.start, 0);
        Ok(())
    }

    fn read(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        let n = max.min(self.vertex.count - self.next);
        chunk.clear(self.next as u64);
        let from = if self.next == 0 { 0 } else { self.pos };
        let mut walker = Walker::new(&self.map, self.pos, self.encoding, &self.path);
        let mut fields = VertexFields::default();
        let has_normals = self.normal_singles.is_some();
        let records = self.next..self.next + n;
        walk_element(
            &mut walker,
            "vertex",
            &self.vertex,
            records,
            &mut Vec::new(),
            |visit| {
                if let Some(record) = fields.take(visit) {
                    let (spans, p, nspans, normal) = fields.checked(&self.path, record)?;
                    chunk.positions.push(p);
                    chunk.spans.extend(spans.map(|s| s.before(from)));
                    if has_normals {
                        chunk.normals.push(normal);
                        chunk.spans.extend(nspans.map(|s| s.before(from)));
                    }
                }
                Ok(())
            },
        )?;
        self.next += n;
        let to = if self.next == self.vertex.count {
            self.map.len()
        } else {
            walker.pos
        };
        self.pos = walker.pos;
        chunk.raw.extend_from_slice(&self.map[from..to]);
        Ok(n)
    }

    fn sink(&self, output: &Path, _bounds: Option<Bounds>) -> Result<Box<dyn Sink>> {
        let sink = SpanSink::create(
            &self.path,
            output,
            "ply",
            numbers(self.encoding, self.precision),
            self.singles,
            self.normal_singles,
        )?;
        Ok(Box::new(sink))
    }
}
