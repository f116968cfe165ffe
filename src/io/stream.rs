//! The streaming interface between files and the pipeline.
//!
//! A [`Source`] hands out the samples of a file in file order, a chunk at a time: decoded world
//! coordinates (f64), per-sample normals and LAS classes where the format has them, and the raw
//! records for sinks that copy them through. A [`Sink`] made by the source takes the chunks back,
//! in the same order, with the moved coordinates and normals, and writes a file that differs from
//! the input only there. Sinks write to a temporary file beside the target; [`Sink::finish`]
//! renames it over the target, and a sink dropped before that removes it.

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::rigid::Vect;

/// Where a token lives in a file: bytes `start..end`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Span {
    pub start: usize,
    pub end: usize,
}

impl Span {
    /// The span `by` bytes earlier (relative to a slice starting at `by`).
    pub(crate) fn before(self, by: usize) -> Self {
        Self {
            start: self.start - by,
            end: self.end - by,
        }
    }
}

/// A batch of consecutive samples.
#[derive(Debug, Default, Clone)]
pub struct Chunk {
    /// Index of the first sample in the file.
    pub first: u64,
    /// World coordinates.
    pub positions: Vec<Vect<3>>,
    /// Per-sample normals (empty when the format has none).
    pub normals: Vec<Vect<3>>,
    /// Per-sample LAS classes (empty when the format has none).
    pub classes: Vec<u8>,
    /// Raw records (LAS), `record_len` bytes each; empty for other formats.
    pub raw: Vec<u8>,
    /// Length of one raw record.
    pub record_len: usize,
    /// Text formats: where each sample's `x y z` (then `nx ny nz`, when the chunk has normals)
    /// lie in `raw`, so that the sink splices new numbers without walking the text again.
    pub(crate) spans: Vec<Span>,
}

impl Chunk {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the chunk holds no sample.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    pub(crate) fn clear(&mut self, first: u64) {
        self.first = first;
        self.positions.clear();
        self.normals.clear();
        self.classes.clear();
        self.raw.clear();
        self.spans.clear();
    }
}

/// An axis-aligned box in world coordinates.
pub type Bounds = (Vect<3>, Vect<3>);

/// The samples of an input file, in file order.
pub trait Source {
    /// The file.
    fn path(&self) -> &Path;
    /// Number of samples.
    fn len(&self) -> u64;
    /// Whether the file holds no sample.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The bounds the file's header declares, if it declares any (LAS); a hint that the
    /// pipeline checks against the samples.
    fn bounds_hint(&self) -> Option<Bounds> {
        None
    }
    /// Whether chunks carry LAS classes.
    fn has_classes(&self) -> bool {
        false
    }
    /// Triangles over the samples (empty for point sets).
    fn triangles(&self) -> &[[u32; 3]] {
        &[]
    }
    /// Normals not attached to one sample (OBJ `vn`): each with the world point where it is
    /// transformed.
    fn loose_normals(&self) -> Vec<(Vect<3>, Vect<3>)> {
        Vec::new()
    }
    /// Starts over at the first sample.
    fn rewind(&mut self) -> Result<()>;
    /// Fills `chunk` with up to `max` next samples; returns how many (0 at the end).
    fn read(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize>;
    /// As [`Source::read`], but `chunk.raw` may be left empty: for passes that only look at
    /// coordinates, normals and classes (pass 1), so that sources need not copy their records.
    fn read_samples(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        self.read(max, chunk)
    }
    /// A sink writing `output` in the format its extension names. `bounds`: the moved samples'
    /// bounds when known (after a first attempt overflowed the output's coordinate range).
    fn sink(&self, output: &Path, bounds: Option<Bounds>) -> Result<Box<dyn Sink>>;
}

/// What a [`Sink`] made of a chunk. The two refusals are not errors: the output is made again
/// by a sink chosen for what the refused chunk showed, and the user sees a note.
#[must_use]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accepted {
    /// Written (or buffered for writing).
    Yes,
    /// A moved coordinate does not fit the output's integer encoding (a LAS scale and offset):
    /// the pass goes on without writing to learn the moved bounds, and a sink framed for them
    /// ([`Source::sink`] with `bounds`) writes the output again.
    Overflow,
    /// The header already written cannot describe the records (return numbers 6 and 7 under a
    /// legacy LAS header, in a file whose first pass the caller skipped): a sink made now, by
    /// a source that has seen them, writes the output again.
    Restart,
}

/// The output of a [`Source`]'s samples after deformation.
pub trait Sink: Send {
    /// Writes the next chunk with its moved samples and normals (empty when the chunk has
    /// none), or says why this sink cannot ([`Accepted`]); the caller then makes a new one.
    fn write(&mut self, chunk: &Chunk, moved: &[Vect<3>], normals: &[Vect<3>]) -> Result<Accepted>;
    /// Whether [`Sink::write`] needs the chunks' raw records; a sink that reads them from the
    /// input itself (a memory-mapped LAS) lets the source skip copying them
    /// ([`Source::read_samples`]).
    fn needs_raw(&self) -> bool {
        true
    }
    /// The moved [`Source::loose_normals`], after every chunk.
    fn loose_normals(&mut self, _normals: Vec<Vect<3>>) {}
    /// Completes the file and renames it over the target; returns notes for the user.
    fn finish(self: Box<Self>) -> Result<Vec<String>>;
}

/// A file being written that hands each [`WRITEBACK`] bytes written to the disk as it goes
/// (Linux: `sync_file_range`, which starts the writing and does not wait for it), so that the
/// sync before [`TempFile::commit`]'s rename waits for the last window only: the output's
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

/// A temporary file beside a target, renamed over it by [`TempFile::commit`] and removed when
/// dropped uncommitted. A target that is a regular file keeps its permission bits: the
/// temporary file takes them before the rename (a private file stays private).
#[derive(Debug)]
pub struct TempFile {
    tmp: PathBuf,
    target: PathBuf,
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
            .ok_or_else(|| Error::Param(format!("{}: not a file name", target.display())))?;
        let tmp = dir.join(format!(
            ".{}.{}.tmp",
            name.to_string_lossy(),
            std::process::id()
        ));
        let file = crate::interrupt::create_registered(&tmp, || File::create(&tmp))
            .map_err(|e| Error::write(target, e))?;
        Ok((
            Self {
                tmp,
                target: target.to_path_buf(),
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

    /// Flushes `out` (the writer [`TempFile::create`] gave), then commits.
    pub fn commit_writer(self, out: BufWriter<OutFile>) -> Result<()> {
        out.into_inner()
            .map_err(|e| Error::write(&self.target, e.into_error()))?;
        self.commit()
    }

    /// Syncs the temporary file and renames it over the target, with the target's permission
    /// bits when it is a regular file already.
    pub fn commit(mut self) -> Result<()> {
        let sync = File::open(&self.tmp).and_then(|f| f.sync_all());
        let mode = match std::fs::symlink_metadata(&self.target) {
            Ok(m) if m.is_file() => Some(m.permissions()),
            _ => None,
        };
        sync.and_then(|_| match mode {
            Some(p) => std::fs::set_permissions(&self.tmp, p),
            None => Ok(()),
        })
        .and_then(|_| {
            crate::interrupt::commit_registered(&self.tmp, &self.target, || {
                std::fs::rename(&self.tmp, &self.target)
            })
        })
        .map_err(|e| Error::write(&self.target, e))?;
        self.committed = true;
        Ok(())
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
