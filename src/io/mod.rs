//! Reading and writing shapes; the format follows the file extension.
//!
//! Every reader keeps the input's bytes and knows where the coordinates live, so the writer
//! changes the coordinates and nothing else. Output goes to a temporary file in the
//! output's folder that is renamed over the target at the end: a failure never leaves a partial
//! file under the output's name, and the input is never opened for writing.

mod las;
pub(crate) mod mapped;
mod obj;
mod ply;
mod ply_stream;
mod stream;
mod text;
mod tiles;
mod xy;
mod xyz;

pub use las::{
    Encoded, LasHeader, LasSource, SOFTWARE, VlrInfo, VlrRecord, copc, decode_coordinates,
    encode_coordinates, frame_error,
};
pub use obj::ObjFile;
pub use ply::{Colors, PlyFile, colors};
pub use ply_stream::{PlyRecordStream, PlyStream};
pub use stream::{Accepted, Bounds, Chunk, Sink, Source, TempFile};
pub use tiles::Tiles;
pub use xy::XyFile;
pub use xyz::{XyzFile, XyzStream};

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Opens `path` as a streaming [`Source`], choosing the format by its extension: LAS/LAZ, PLY
/// and XYZ stream from the file; OBJ is read whole and served in chunks.
pub fn open(path: &Path) -> Result<Box<dyn Source>> {
    match extension(path).as_deref() {
        Some("las") | Some("laz") => Ok(Box::new(LasSource::open(path)?)),
        Some("ply") => ply_stream::open(path),
        Some("xyz") | Some("txt") => Ok(Box::new(XyzStream::open(path)?)),
        _ => Ok(Box::new(DocumentSource::new(path, Document::read(path)?)?)),
    }
}

/// Fails unless `path` has the extension `want` (`txt` standing for `xyz` too).
pub(crate) fn require_extension(path: &Path, want: &str) -> Result<()> {
    let ext = extension(path);
    if ext.as_deref() != Some(want) && !(want == "xyz" && ext.as_deref() == Some("txt")) {
        return Err(Error::Param(format!(
            "{}: the output must have the input's format (.{want})",
            path.display()
        )));
    }
    Ok(())
}

/// The extensions of the outputs `deform` writes for `input` (as its sinks take them): LAS and
/// LAZ into each other, PLY, OBJ and XYZ (`.txt` too) into their own; none for other formats.
pub fn output_extensions(input: &Path) -> &'static [&'static str] {
    match extension(input).as_deref() {
        Some("las") | Some("laz") => &["las", "laz"],
        Some("ply") => &["ply"],
        Some("obj") => &["obj"],
        Some("xyz") | Some("txt") => &["xyz", "txt"],
        _ => &[],
    }
}

/// A [`Document`] held in memory, served as a [`Source`].
pub struct DocumentSource {
    path: PathBuf,
    doc: Arc<Document>,
    next: usize,
}

impl DocumentSource {
    /// Serves `doc`, read from `path`.
    pub fn new(path: &Path, doc: Document) -> Result<Self> {
        if doc.positions().is_empty() {
            return Err(Error::format(path, "the file holds no vertices or points"));
        }
        Ok(Self {
            path: path.to_path_buf(),
            doc: Arc::new(doc),
            next: 0,
        })
    }
}

impl Source for DocumentSource {
    fn path(&self) -> &Path {
        &self.path
    }

    fn len(&self) -> u64 {
        self.doc.positions().len() as u64
    }

    fn triangles(&self) -> &[[u32; 3]] {
        self.doc.triangles()
    }

    fn loose_normals(&self) -> Vec<(Vect<3>, Vect<3>)> {
        match &*self.doc {
            Document::Obj(o) => o.loose_normals(),
            _ => Vec::new(),
        }
    }

    fn rewind(&mut self) -> Result<()> {
        self.next = 0;
        Ok(())
    }

    fn read(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        let all = self.doc.positions();
        let end = self.next.saturating_add(max).min(all.len());
        chunk.clear(self.next as u64);
        chunk.positions.extend_from_slice(&all[self.next..end]);
        if let Some(normals) = self.doc.normals() {
            chunk.normals.extend_from_slice(&normals[self.next..end]);
        }
        let n = end - self.next;
        self.next = end;
        Ok(n)
    }

    fn sink(&self, output: &Path, _bounds: Option<Bounds>) -> Result<Box<dyn Sink>> {
        self.doc.check_output(output)?;
        Ok(Box::new(DocumentSink {
            doc: self.doc.clone(),
            output: output.to_path_buf(),
            positions: Vec::with_capacity(self.doc.positions().len()),
            normals: Vec::new(),
            loose: Vec::new(),
        }))
    }
}

/// Collects the moved samples of a [`DocumentSource`] and writes the document at the end.
struct DocumentSink {
    doc: Arc<Document>,
    output: PathBuf,
    positions: Vec<Vect<3>>,
    normals: Vec<Vect<3>>,
    loose: Vec<Vect<3>>,
}

impl Sink for DocumentSink {
    fn write(
        &mut self,
        _chunk: &Chunk,
        moved: &[Vect<3>],
        normals: &[Vect<3>],
    ) -> Result<Accepted> {
        self.positions.extend_from_slice(moved);
        self.normals.extend_from_slice(normals);
        Ok(Accepted::Yes)
    }

    fn loose_normals(&mut self, normals: Vec<Vect<3>>) {
        self.loose = normals;
    }

    fn finish(self: Box<Self>) -> Result<Vec<String>> {
        let normals = (!self.normals.is_empty()).then_some(&self.normals[..]);
        self.doc
            .write(&self.positions, normals, &self.loose, &self.output)?;
        Ok(Vec::new())
    }
}

use crate::error::{Error, Result};
use crate::rigid::Vect;

/// A shape read from a file.
#[derive(Debug)]
pub enum Document {
    /// A PLY mesh or point cloud.
    Ply(PlyFile),
    /// A text point cloud.
    Xyz(XyzFile),
    /// A Wavefront OBJ mesh.
    Obj(ObjFile),
}

impl Document {
    /// Reads `path`, choosing the format by its extension.
    pub fn read(path: &Path) -> Result<Self> {
        match extension(path).as_deref() {
            Some("ply") => Ok(Self::Ply(PlyFile::read(path)?)),
            Some("xyz") | Some("txt") => Ok(Self::Xyz(XyzFile::read(path)?)),
            Some("obj") => Ok(Self::Obj(ObjFile::read(path)?)),
            _ => Err(Error::UnsupportedFormat {
                path: path.to_path_buf(),
            }),
        }
    }

    /// The sample positions (input coordinates).
    pub fn positions(&self) -> &[Vect<3>] {
        match self {
            Self::Ply(p) => p.positions(),
            Self::Xyz(x) => x.positions(),
            Self::Obj(o) => o.positions(),
        }
    }

    /// Per-vertex normals, when the file has them.
    pub fn normals(&self) -> Option<&[Vect<3>]> {
        match self {
            Self::Ply(p) => p.normals(),
            Self::Xyz(_) | Self::Obj(_) => None,
        }
    }

    /// Fails unless `path` names this document's format.
    pub fn check_output(&self, path: &Path) -> Result<()> {
        let want = match self {
            Self::Ply(_) => "ply",
            Self::Xyz(_) => "xyz",
            Self::Obj(_) => "obj",
        };
        require_extension(path, want)
    }

    /// Triangles over the positions (empty for point clouds).
    pub fn triangles(&self) -> &[[u32; 3]] {
        match self {
            Self::Ply(p) => p.triangles(),
            Self::Xyz(_) => &[],
            Self::Obj(o) => o.triangles(),
        }
    }

    /// Writes the document with its positions (and normals, when given) replaced to `path`,
    /// atomically. The output format must be the input's.
    pub fn write(
        &self,
        positions: &[Vect<3>],
        normals: Option<&[Vect<3>]>,
        loose_normals: &[Vect<3>],
        path: &Path,
    ) -> Result<()> {
        self.check_output(path)?;
        let bytes = match self {
            Self::Ply(p) => p.encode(positions, normals)?,
            Self::Xyz(x) => x.encode(positions)?,
            Self::Obj(o) => o.encode(positions, loose_normals)?,
        };
        write_atomic(path, &bytes)
    }
}

/// The lowercase extension of `path` (`None` without one).
pub fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
}

/// Fails when `output` names the same file as `input` (through links or `..` too).
pub fn refuse_overwrite(input: &Path, output: &Path) -> Result<()> {
    let canon_in = std::fs::canonicalize(input).map_err(|e| Error::io(input, e))?;
    let canon_out = output_identity(output)?;
    let same = canon_out == canon_in || std::fs::canonicalize(output).is_ok_and(|o| o == canon_in);
    if same {
        return Err(Error::Param(format!(
            "{}: the output would overwrite the input; choose another output name",
            output.display()
        )));
    }
    Ok(())
}

/// The file `output` names, for comparing outputs that may not exist yet: its folder resolved
/// (links and `..`), then its name.
fn output_identity(output: &Path) -> Result<PathBuf> {
    let parent = match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok(std::fs::canonicalize(&parent)
        .map_err(|e| Error::write(output, e))?
        .join(output.file_name().unwrap_or_default()))
}

/// Refuses two of the `outputs` (each with the option that names it) that name the same file,
/// before any work: one would silently replace the other.
pub fn refuse_same_outputs(outputs: &[(&str, &Path)]) -> Result<()> {
    let mut seen: Vec<(&str, PathBuf)> = Vec::new();
    for &(option, path) in outputs {
        let id = output_identity(path)?;
        if let Some((first, _)) = seen.iter().find(|(_, other)| *other == id) {
            return Err(Error::Param(format!(
                "{}: {first} and {option} name the same file; give each its own",
                path.display()
            )));
        }
        seen.push((option, id));
    }
    Ok(())
}

/// Writes `bytes` to a temporary file beside `path` and renames it over `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let (tmp, mut out) = TempFile::create(path)?;
    out.write_all(bytes)
        .and_then(|_| out.flush())
        .map_err(|e| Error::write(path, e))?;
    drop(out);
    tmp.commit()
}

/// A short description of a file's layout for `rigidcells info`: a PLY's header lines, an
/// OBJ's counts of each kind of line.
pub fn describe(path: &Path) -> Result<String> {
    let bytes = mapped::map(path)?;
    match extension(path).as_deref() {
        Some("ply") => {
            let end = bytes
                .windows(10)
                .position(|w| w == b"end_header")
                .ok_or_else(|| Error::format(path, "no `end_header` line"))?;
            Ok(String::from_utf8_lossy(&bytes[..end])
                .lines()
                .filter(|l| !l.trim().is_empty())
                .collect::<Vec<_>>()
                .join("\n  "))
        }
        Some("obj") => {
            let mut counts = std::collections::BTreeMap::<String, usize>::new();
            for line in bytes.split(|&b| b == b'\n') {
                let key = line
                    .split(|b| b.is_ascii_whitespace())
                    .find(|t| !t.is_empty())
                    .map(|t| String::from_utf8_lossy(t).into_owned());
                if let Some(k) = key.filter(|k| !k.starts_with('#')) {
                    *counts.entry(k).or_default() += 1;
                }
            }
            Ok(counts
                .iter()
                .map(|(k, n)| format!("{k}: {n}"))
                .collect::<Vec<_>>()
                .join(", "))
        }
        _ => Ok(String::new()),
    }
}
