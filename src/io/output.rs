//! Outputs written so that nobody else can choose where they go, and so that a run's outputs
//! appear together at its end or not at all.
//!
//! Every output is first written to a [`TempFile`] beside its target: created new with
//! `O_EXCL` under a random name (the `tempfile` crate), so a link planted beside the target
//! is never followed and no two writers, in this process or another, share a temporary. A
//! finished temporary is handed to the run's [`ResultSet`], which syncs it; when the run has
//! written everything, [`ResultSet::commit`] renames every temporary over its target, one after
//! another. A run that fails, is dropped, or is killed (SIGKILL, out of memory) before that
//! leaves none of its outputs under their final names: only temporaries, which a failure or
//! an interrupt removes ([`crate::interrupt`]) and a kill leaves as hidden `.NAME.*.tmp` files.
//! Each run has its own set, so concurrent runs (threads of one process) never touch each
//! other's outputs.

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::{Error, Result};

/// A file being written that hands each [`WRITEBACK`] bytes written to the disk as it goes
/// (Linux: `sync_file_range`, which starts the writing and does not wait for it), so that the
/// sync before the output is renamed into place waits for the last window only: the output's
/// gigabyte reaches the disk while later chunks are still computed, instead of after them.
/// Scratch files ([`TempFile::scratch`]), read back and removed, are left to the system.
#[derive(Debug)]
pub struct OutFile {
    file: File,
    /// Where the next write goes.
    at: u64,
    /// Everything before this was handed to the disk.
    handed: u64,
    /// Whether to hand windows to the disk at all.
    write_back: bool,
}

/// The window [`OutFile`] hands to the disk at once.
const WRITEBACK: u64 = 32 << 20;

impl OutFile {
    fn new(file: File, write_back: bool) -> Self {
        Self {
            file,
            at: 0,
            handed: 0,
            write_back,
        }
    }

    /// Starts writing bytes `handed..at` to the disk once they are a window (a gap left by a
    /// seek forward goes with it, harmlessly).
    fn hand_over(&mut self) {
        if !self.write_back || self.at < self.handed + WRITEBACK {
            return;
        }
        start_writeback(&self.file, self.handed, self.at - self.handed);
        self.handed = self.at;
    }
}

/// Starts writing `len` bytes of `file` from `from` to the disk, without waiting for it. A
/// failure costs only the early start, so it is not reported.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn start_writeback(file: &File, from: u64, len: u64) {
    use std::os::fd::AsRawFd;
    // SAFETY: a system call on a descriptor `file` owns while borrowed; it reads no memory of
    // this process.
    unsafe {
        libc::sync_file_range(
            file.as_raw_fd(),
            from as libc::off64_t,
            len as libc::off64_t,
            libc::SYNC_FILE_RANGE_WRITE,
        );
    }
}

/// Elsewhere the system writes the file back on its own schedule.
#[cfg(not(target_os = "linux"))]
fn start_writeback(_file: &File, _from: u64, _len: u64) {}

impl Write for OutFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(buf)?;
        self.at += n as u64;
        self.hand_over();
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Seek for OutFile {
    /// A write behind the windows handed over (a header rewritten) waits for the sync; the
    /// LAZ writer's position queries (`SeekFrom::Current(0)`, once a chunk) move nothing.
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        self.at = self.file.seek(to)?;
        Ok(self.at)
    }
}

/// The most bytes of a target's name that its temporary's name repeats.
const NAME_MOST: usize = 200;

/// A temporary file beside a target: created new under a random name in the target's folder,
/// renamed over the target by [`ResultSet::commit`] (or [`TempFile::commit`], an output alone)
/// and removed when dropped before. A target that is a regular file keeps its permission bits:
/// the temporary file takes them before the rename (a private file stays private); a new
/// target gets the permissions a newly created file gets.
#[derive(Debug)]
pub struct TempFile {
    tmp: PathBuf,
    target: PathBuf,
    /// A handle on the file created: synced and given its permissions through it, never
    /// through its path, which someone with write access to the folder could swap for a link.
    file: File,
    committed: bool,
}

impl TempFile {
    /// Creates the temporary file for `target`, handed to the disk as it is written.
    pub fn create(target: &Path) -> Result<(Self, BufWriter<OutFile>)> {
        Self::open(target, true)
    }

    /// Creates a scratch file named after `target`, read back and removed before the output is
    /// complete: left to the system's own write-back.
    pub fn scratch(target: &Path) -> Result<(Self, BufWriter<OutFile>)> {
        Self::open(target, false)
    }

    fn open(target: &Path, write_back: bool) -> Result<(Self, BufWriter<OutFile>)> {
        let dir = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = target
            .file_name()
            .ok_or_else(|| Error::param(format!("{}: not a file name", target.display())))?;
        // The target's name, cut on a character boundary so that the temporary's name (with
        // its dots and random part, 18 bytes more) fits where the target's fits (255 bytes).
        let name = name.to_string_lossy();
        let mut cut = name.len().min(NAME_MOST);
        while !name.is_char_boundary(cut) {
            cut -= 1;
        }
        let prefix = format!(".{}.", &name[..cut]);
        let (file, tmp) = crate::interrupt::create_registered(|| {
            // `.NAME.` and 12 random characters: opened with O_CREAT | O_EXCL, so it is a new
            // file (never through a link or a file already there), under a name nobody can
            // guess; `tempfile` draws another name when one is taken.
            let mut builder = tempfile::Builder::new();
            builder.prefix(&prefix).suffix(".tmp").rand_bytes(12);
            #[cfg(unix)]
            {
                use std::os::unix::fs::PermissionsExt;
                // The mode a new output gets: 0666 less the umask.
                builder.permissions(std::fs::Permissions::from_mode(0o666));
            }
            let named = builder.tempfile_in(&dir)?;
            named.keep().map_err(|e| e.error)
        })
        .map_err(|e| Error::write(target, e))?;
        let handle = file.try_clone().map_err(|e| Error::write(target, e))?;
        Ok((
            Self {
                tmp,
                target: target.to_path_buf(),
                file: handle,
                committed: false,
            },
            BufWriter::with_capacity(1 << 20, OutFile::new(file, write_back)),
        ))
    }

    /// The temporary path.
    pub fn path(&self) -> &Path {
        &self.tmp
    }

    /// The target path.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Another handle on the file created (sharing its position with the writer's), to
    /// read or rewrite what was written without opening the path again.
    pub fn handle(&self) -> Result<File> {
        self.file
            .try_clone()
            .map_err(|e| Error::write(&self.target, e))
    }

    /// Flushes `out` (the writer [`TempFile::create`] gave).
    fn flush(&self, out: BufWriter<OutFile>) -> Result<()> {
        out.into_inner()
            .map_err(|e| Error::write(&self.target, e.into_error()))?;
        Ok(())
    }

    /// Syncs the temporary file to the disk and gives it the target's permission bits when
    /// the target is a regular file already: ready to be renamed.
    fn complete(&self) -> Result<()> {
        let sync = self.file.sync_all();
        let mode = match std::fs::symlink_metadata(&self.target) {
            Ok(m) if m.is_file() => Some(m.permissions()),
            _ => None,
        };
        sync.and_then(|_| match mode {
            Some(p) => self.file.set_permissions(p),
            None => Ok(()),
        })
        .map_err(|e| Error::write(&self.target, e))
    }

    /// Flushes `out` (the writer [`TempFile::create`] gave), then commits: an output alone.
    pub fn commit_writer(self, out: BufWriter<OutFile>) -> Result<()> {
        self.flush(out)?;
        self.commit()
    }

    /// Syncs the temporary file and renames it over the target: an output alone (a run of
    /// several hands each to its [`ResultSet`]).
    pub fn commit(self) -> Result<()> {
        let set = ResultSet::new();
        set.stage(self)?;
        set.commit()
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.tmp);
            crate::interrupt::forget(&self.tmp);
        }
    }
}

/// The outputs of one run — its output, saved field, report, preview — there only together.
/// Writers hand their finished temporaries to the set ([`ResultSet::stage`]); the run's end
/// renames them all into place ([`ResultSet::commit`]). A set dropped uncommitted (an error on
/// the way) removes its temporaries, so a run leaves all of its files or none. Each run makes
/// its own; it is `Sync`, so the writers of one run may stage from several threads.
#[derive(Debug, Default)]
pub struct ResultSet {
    staged: Mutex<Vec<TempFile>>,
    /// The output renamed after every other ([`ResultSet::last`]).
    last: Mutex<Option<PathBuf>>,
    /// Whether the commit refuses to replace existing files ([`ResultSet::keep_existing`]).
    keep: std::sync::atomic::AtomicBool,
}

impl ResultSet {
    /// An empty set for one run.
    pub fn new() -> Self {
        Self::default()
    }

    /// Renames the output `target` after every other at the commit: the run's main output,
    /// whose presence then says that its field, report and preview are in place too, should
    /// the process be killed between two renames.
    pub fn last(&self, target: &Path) {
        *self.last.lock().unwrap_or_else(|e| e.into_inner()) = Some(target.to_path_buf());
    }

    /// Replaces no existing file at the commit: an output whose name was taken meanwhile fails
    /// the commit (as a rename that fails does), and the file under that name is left as it is.
    pub fn keep_existing(&self) {
        self.keep.store(true, std::sync::atomic::Ordering::SeqCst);
    }

    /// Takes `tmp`, complete: synced now, renamed over its target by [`ResultSet::commit`].
    /// Two outputs of one set may not share a target.
    pub fn stage(&self, tmp: TempFile) -> Result<()> {
        tmp.complete()?;
        let mut staged = self.staged.lock().unwrap_or_else(|e| e.into_inner());
        if staged.iter().any(|t| t.target == tmp.target) {
            return Err(Error::param(format!(
                "{}: two outputs of one run name this file; give each its own",
                tmp.target.display()
            )));
        }
        staged.push(tmp);
        Ok(())
    }

    /// Flushes `out` (the writer [`TempFile::create`] gave `tmp`) and stages `tmp`.
    pub fn stage_writer(&self, tmp: TempFile, out: BufWriter<OutFile>) -> Result<()> {
        tmp.flush(out)?;
        self.stage(tmp)
    }

    /// Writes `bytes` to a temporary file for `path` and stages it.
    pub fn write(&self, path: &Path, bytes: &[u8]) -> Result<()> {
        let (tmp, mut out) = TempFile::create(path)?;
        out.write_all(bytes).map_err(|e| Error::write(path, e))?;
        self.stage_writer(tmp, out)
    }

    /// Renames every staged output over its target, in the order they were staged (the one
    /// named by [`ResultSet::last`] last), with no interrupt between the renames
    /// (`interrupt::commit_registered`). Should a rename fail (renames within a
    /// folder fail only when the folder changed under the run), the outputs already renamed
    /// are removed again, files they replaced included, and the error names the output that
    /// failed: the run leaves none of its outputs.
    pub fn commit(self) -> Result<()> {
        let mut staged = self.staged.into_inner().unwrap_or_else(|e| e.into_inner());
        if let Some(last) = self.last.into_inner().unwrap_or_else(|e| e.into_inner()) {
            staged.sort_by_key(|t| t.target == last);
        }
        let pairs: Vec<(&Path, &Path)> = staged
            .iter()
            .map(|t| (t.tmp.as_path(), t.target.as_path()))
            .collect();
        let keep = self.keep.load(std::sync::atomic::Ordering::SeqCst);
        let renamed = crate::interrupt::commit_registered(&pairs, keep);
        let done = match &renamed {
            Ok(()) => staged.len(),
            Err((done, _)) => *done,
        };
        for t in &mut staged[..done] {
            t.committed = true;
        }
        match renamed {
            Ok(()) => Ok(()),
            Err((done, e)) => {
                for t in &staged[..done] {
                    let _ = std::fs::remove_file(&t.target);
                }
                Err(Error::write(&staged[done].target, e))
            }
        }
    }
}

/// Writes `bytes` to a temporary file beside `path` and renames it over `path`: an output
/// alone.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let set = ResultSet::new();
    set.write(path, bytes)?;
    set.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Windows are handed over as they fill, through the position queries a LAZ writer makes
    /// between chunks; a scratch file hands nothing over; the bytes are all there.
    #[test]
    fn written_windows_are_handed_to_the_disk() {
        let dir = tempfile::tempdir().unwrap();
        let piece = vec![7u8; 1 << 20];
        for (name, write_back) in [("out.bin", true), ("scratch.bin", false)] {
            let target = dir.path().join(name);
            let (tmp, out) = TempFile::open(&target, write_back).unwrap();
            let mut file = out.into_inner().unwrap();
            for _ in 0..40 {
                file.write_all(&piece).unwrap();
                assert_eq!(file.stream_position().unwrap(), file.at);
            }
            let handed = file.handed;
            assert_eq!(handed >= WRITEBACK, write_back, "{name}: {handed}");
            assert!(handed <= 40 << 20);
            drop(file);
            tmp.commit().unwrap();
            assert_eq!(std::fs::metadata(&target).unwrap().len(), 40 << 20);
        }
    }
}
