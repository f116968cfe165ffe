//! Reading and writing shapes; the format follows the file extension.
//!
//! Every format has one reader, a streaming [`Source`] ([`open`]): LAS/LAZ and COPC, PLY
//! ([`PlyStream`] for binary files with fixed-size vertex records, [`PlyRecordStream`] for the
//! others), XYZ ([`XyzStream`]) and OBJ ([`ObjSource`], read whole and served in chunks). A
//! caller that needs every sample at once drains the source into a [`Document`].
//!
//! Every reader keeps the input's bytes and knows where the coordinates live, so the writer
//! changes the coordinates and nothing else. Output goes to a temporary file in the output's
//! folder, created new under a random name, that is renamed over the target with the run's
//! other outputs at its end ([`ResultSet`]): a failure never leaves a partial file under the
//! output's name, and the input is never opened for writing.

pub mod geotiff;
mod las;
pub(crate) mod mapped;
mod obj;
mod output;
mod ply;
mod ply_stream;
mod stream;
mod text;
mod tiles;
mod xy;
mod xyz;

pub use las::{
    Encoded, LasHeader, LasSource, SOFTWARE, VlrInfo, VlrRecord, copc, crs_of, decode_coordinates,
    encode_coordinates, frame_error,
};
pub use obj::{ObjFile, ObjSource};
pub use output::{ResultSet, TempFile, write_atomic};
pub use ply::{Colors, colors};
pub use ply_stream::{PlyRecordStream, PlyStream};
pub use stream::{Accepted, Bounds, Chunk, Sink, Source};
pub use tiles::Tiles;
pub use xy::XyFile;
pub use xyz::XyzStream;

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::rigid::Vect;

/// Opens `path` as a streaming [`Source`], choosing the format by its extension: LAS/LAZ, PLY
/// and XYZ stream from the file; OBJ is read whole and served in chunks.
pub fn open(path: &Path) -> Result<Box<dyn Source>> {
    match extension(path).as_deref() {
        Some("las") | Some("laz") => Ok(Box::new(LasSource::open(path)?)),
        Some("ply") => ply_stream::open(path),
        Some("xyz") | Some("txt") => Ok(Box::new(XyzStream::open(path)?)),
        Some("obj") => Ok(Box::new(ObjSource::open_as(path, Opening::Stream)?)),
        _ => Err(Error::UnsupportedFormat {
            path: path.to_path_buf(),
        }),
    }
}

/// Fails unless `path` has the extension `want` (`txt` standing for `xyz` too).
pub(crate) fn require_extension(path: &Path, want: &str) -> Result<()> {
    let ext = extension(path);
    if ext.as_deref() != Some(want) && !(want == "xyz" && ext.as_deref() == Some("txt")) {
        return Err(Error::param(format!(
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

/// Refuses an `output` that cannot have the format of `input` (LAS and LAZ write each other, a
/// `.xy` point set `.xy`, every other format its own), before any work: the writer would
/// refuse it only once the field is solved. An input of a format rigidcells does not read is
/// left to its reader.
pub fn check_output_format(input: &Path, output: &Path) -> Result<()> {
    let formats: &[&str] = match extension(input).as_deref() {
        Some("xy") => &["xy"],
        _ => output_extensions(input),
    };
    let ext = extension(output).unwrap_or_default();
    if formats.is_empty() || formats.contains(&ext.as_str()) {
        return Ok(());
    }
    let names: Vec<String> = formats.iter().map(|e| format!(".{e}")).collect();
    Err(Error::param(format!(
        "{}: the output must have the input's format ({})",
        output.display(),
        names.join(" or ")
    )))
}

/// Refuses outputs whose folder does not exist, before any work: the write would fail only at
/// the end, after the solve.
pub fn check_folders<'a>(outputs: impl IntoIterator<Item = &'a Path>) -> Result<()> {
    for output in outputs {
        let folder = match output.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        match std::fs::metadata(folder) {
            Ok(m) if m.is_dir() => {}
            Ok(_) => {
                let e = std::io::Error::from(std::io::ErrorKind::NotADirectory);
                return Err(Error::write(output, e));
            }
            Err(e) => return Err(Error::write(output, e)),
        }
    }
    Ok(())
}

/// What a source checks as it opens.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Opening {
    /// For passes over the samples ([`open`]): a file without samples is refused, and what a
    /// chunk decodes (a binary PLY's fixed-size records, an XYZ's numbers) is checked when the
    /// chunk is read.
    Stream,
    /// For reading a file whole ([`Document::read`]): every record is decoded and checked as
    /// the source opens, in file order, so the first defect of the file is the one reported;
    /// a file without samples is a document without samples.
    Whole,
}

/// A shape read whole: the samples of a PLY, XYZ or OBJ file, drained from its [`Source`]
/// into memory, for the callers that need them all at once (pictures, the editor's proxy,
/// tools and tests). Writing goes through the source's sink.
#[derive(Debug, Clone, Default)]
pub struct Document {
    positions: Vec<Vect<3>>,
    normals: Option<Vec<Vect<3>>>,
    triangles: Vec<[u32; 3]>,
}

impl Document {
    /// Reads `path`, choosing the format by its extension: PLY, XYZ (`.txt` too) or OBJ; other
    /// formats are [`Error::UnsupportedFormat`] (stream them through [`open`]).
    pub fn read(path: &Path) -> Result<Self> {
        let mut source: Box<dyn Source> = match extension(path).as_deref() {
            Some("ply") => {
                refuse_folder(path)?;
                Box::new(PlyRecordStream::open_as(path, Opening::Whole)?)
            }
            Some("xyz") | Some("txt") => {
                refuse_folder(path)?;
                Box::new(XyzStream::open_as(path, Opening::Whole)?)
            }
            Some("obj") => Box::new(ObjSource::open_as(path, Opening::Whole)?),
            _ => {
                return Err(Error::UnsupportedFormat {
                    path: path.to_path_buf(),
                });
            }
        };
        Self::drain(source.as_mut())
    }

    /// All the samples of `source` from its first, with its triangles.
    pub fn drain(source: &mut dyn Source) -> Result<Self> {
        source.rewind()?;
        let mut doc = Self {
            triangles: source.triangles().to_vec(),
            ..Self::default()
        };
        let mut chunk = Chunk::default();
        while source.read_samples(DRAIN_CHUNK, &mut chunk)? > 0 {
            doc.positions.extend_from_slice(&chunk.positions);
            if !chunk.normals.is_empty() {
                doc.normals
                    .get_or_insert_with(Vec::new)
                    .extend_from_slice(&chunk.normals);
            }
        }
        Ok(doc)
    }

    /// The sample positions (input coordinates).
    pub fn positions(&self) -> &[Vect<3>] {
        &self.positions
    }

    /// Per-vertex normals, when the file has them (PLY `nx ny nz`).
    pub fn normals(&self) -> Option<&[Vect<3>]> {
        self.normals.as_deref()
    }

    /// Triangles over the positions (empty for point clouds).
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
}

/// Samples per chunk when a source is drained into a [`Document`].
const DRAIN_CHUNK: usize = 1 << 16;

/// Fails as reading a folder fails ("Is a directory") where it would be mapped: mapping a
/// folder fails with the less telling "No such device".
fn refuse_folder(path: &Path) -> Result<()> {
    if path.is_dir() {
        std::fs::read(path).map_err(|e| Error::io(path, e))?;
    }
    Ok(())
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
        return Err(Error::param(format!(
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
            return Err(Error::param(format!(
                "{}: {first} and {option} name the same file; give each its own",
                path.display()
            )));
        }
        seen.push((option, id));
    }
    Ok(())
}

/// A short description of a file's layout for `rigidcells info`: a PLY's header lines, an
/// OBJ's counts of each kind of line.
pub fn layout(path: &Path) -> Result<String> {
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
