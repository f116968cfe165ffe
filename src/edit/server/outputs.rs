//! Where *Save edit* and *Apply* write: one folder chosen when the editor starts
//! ([`OutputFolder`]), plain file names ([`check_name`]), and a file there that this editor did not
//! write replaced only when the page says its user confirmed it (the module docs of
//! [`super`]).

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::{Error, Result};
use crate::said::{Opt, Said};

/// The one folder the editor writes into, and the names it wrote there.
#[derive(Debug)]
pub struct OutputFolder {
    dir: PathBuf,
    input: PathBuf,
    written: Mutex<HashSet<String>>,
}

/// Why a file is not written.
#[derive(Debug)]
pub(super) enum Refusal {
    /// The file exists, this editor did not write it, and the page did not say its user
    /// confirmed replacing it.
    Exists(PathBuf),
    /// Never written (a bad name, a link, the input…).
    Error(Error),
}

impl From<Error> for Refusal {
    fn from(e: Error) -> Self {
        Self::Error(e)
    }
}

impl OutputFolder {
    /// Writes into `dir` (`None`: the folder of `input`), which must be a folder.
    pub fn new(input: &Path, dir: Option<&Path>) -> Result<Self> {
        let (dir, named) = match dir {
            Some(d) => (d.to_path_buf(), true),
            None => match input.parent() {
                Some(p) if !p.as_os_str().is_empty() => (p.to_path_buf(), false),
                _ => (PathBuf::from("."), false),
            },
        };
        let shown = if named {
            Said::new().set(Opt::OutDir, dir.display())
        } else {
            Said::from(dir.display().to_string())
        };
        let canonical = std::fs::canonicalize(&dir).map_err(|e| {
            Error::param(
                shown
                    .clone()
                    .text(format!(": not a folder to write into: {e}")),
            )
        })?;
        if !canonical.is_dir() {
            return Err(Error::param(shown.text(": not a folder to write into")));
        }
        Ok(Self {
            dir: canonical,
            input: input.to_path_buf(),
            written: Mutex::new(HashSet::new()),
        })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where `name` is written, when it may be: a plain name with one of the extensions
    /// `extensions` ([`check_name`]), not the input, not a link or anything but a regular file,
    /// and not a file this editor did not write unless `overwrite` (the user confirmed).
    pub(super) fn target(
        &self,
        name: &str,
        extensions: &[&str],
        overwrite: bool,
    ) -> Result<PathBuf, Refusal> {
        check_name(name, extensions)?;
        let path = self.dir.join(name);
        crate::io::refuse_overwrite(&self.input, &path)?;
        match std::fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_symlink() => Err(Error::param(format!(
                "{}: a symbolic link; the editor does not replace links, choose another name",
                path.display()
            ))
            .into()),
            Ok(m) if !m.is_file() => Err(Error::param(format!(
                "{}: not a regular file; choose another name",
                path.display()
            ))
            .into()),
            Ok(_) if !overwrite && !self.wrote(name) => Err(Refusal::Exists(path)),
            Ok(_) => Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(path),
            Err(e) => Err(Error::write(&path, e).into()),
        }
    }

    pub(super) fn wrote(&self, name: &str) -> bool {
        self.written
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .contains(name)
    }

    pub(super) fn record(&self, name: &str) {
        self.written
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(name.to_string());
    }
}

/// Checks that `name` is a plain file name with one of `extensions` (lowercase, compared
/// without case): not empty, at most 255 bytes, no `/` or `\\` (no folder), no leading `.`
/// (no hidden file, no `.` or `..`; the editor's temporary files start with one), no control
/// character.
pub fn check_name(name: &str, extensions: &[&str]) -> Result<()> {
    let bad = |why: &str| Err(Error::param(format!("{name:?}: {why}")));
    if name.is_empty() {
        return Err(Error::param("a file name is needed"));
    }
    if name.len() > 255 {
        return bad("a file name of at most 255 bytes is needed");
    }
    if name.contains(['/', '\\']) {
        return bad("a plain file name is needed, without a folder");
    }
    if name.starts_with('.') {
        return bad("a name starting with '.' is not written");
    }
    if name.chars().any(char::is_control) {
        return bad("a file name without control characters is needed");
    }
    let ext = crate::io::extension(Path::new(name));
    if !ext.is_some_and(|e| extensions.contains(&e.as_str())) {
        let list: Vec<String> = extensions.iter().map(|e| format!(".{e}")).collect();
        return bad(&format!("the file must be {}", list.join(" or ")));
    }
    Ok(())
}
