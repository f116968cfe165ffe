//! Reading and writing shapes; the format follows the file extension.
//!
//! Every reader keeps the input's bytes and knows where the coordinates live, so the writer
//! changes the coordinates and nothing else (DESIGN §7). Output goes to a temporary file in the
//! output's folder that is renamed over the target at the end: a failure never leaves a partial
//! file under the output's name, and the input is never opened for writing.

mod ply;
mod xyz;

pub use ply::PlyFile;
pub use xyz::XyzFile;

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::rigid::Vect;

/// A shape read from a file.
#[derive(Debug)]
pub enum Document {
    /// A PLY mesh or point cloud.
    Ply(PlyFile),
    /// A text point cloud.
    Xyz(XyzFile),
}

impl Document {
    /// Reads `path`, choosing the format by its extension.
    pub fn read(path: &Path) -> Result<Self> {
        match extension(path).as_deref() {
            Some("ply") => Ok(Self::Ply(PlyFile::read(path)?)),
            Some("xyz") | Some("txt") => Ok(Self::Xyz(XyzFile::read(path)?)),
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
        }
    }

    /// Triangles over the positions (empty for point clouds).
    pub fn triangles(&self) -> &[[u32; 3]] {
        match self {
            Self::Ply(p) => p.triangles(),
            Self::Xyz(_) => &[],
        }
    }

    /// Writes the document with its positions replaced by `positions` to `path`, atomically.
    /// The output format must be the input's.
    pub fn write(&self, positions: &[Vect<3>], path: &Path) -> Result<()> {
        let (want, bytes) = match self {
            Self::Ply(p) => ("ply", p.encode(positions)?),
            Self::Xyz(x) => ("xyz", x.encode(positions)?),
        };
        let ext = extension(path);
        if ext.as_deref() != Some(want) && !(want == "xyz" && ext.as_deref() == Some("txt")) {
            return Err(Error::Param(format!(
                "{}: the output must have the input's format (.{want})",
                path.display()
            )));
        }
        write_atomic(path, &bytes)
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
}

/// Fails when `output` names the same file as `input` (through links or `..` too).
pub fn refuse_overwrite(input: &Path, output: &Path) -> Result<()> {
    let canon_in = std::fs::canonicalize(input).map_err(|e| Error::io(input, e))?;
    let parent = match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let canon_out = std::fs::canonicalize(&parent)
        .map_err(|e| Error::io(&parent, e))?
        .join(output.file_name().unwrap_or_default());
    let same = canon_out == canon_in || std::fs::canonicalize(output).is_ok_and(|o| o == canon_in);
    if same {
        return Err(Error::Param(format!(
            "{}: the output would overwrite the input; choose another output name",
            output.display()
        )));
    }
    Ok(())
}

/// Writes `bytes` to a temporary file beside `path` and renames it over `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| Error::Param(format!("{}: not a file name", path.display())))?;
    let tmp = dir.join(format!(
        ".{}.{}.tmp",
        name.to_string_lossy(),
        std::process::id()
    ));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io(path, e));
    }
    Ok(())
}
