//! The streaming interface between files and the pipeline.
//!
//! A [`Source`] hands out the samples of a file in file order, a chunk at a time: decoded world
//! coordinates (f64), per-sample normals and LAS classes where the format has them, and the raw
//! records for sinks that copy them through. A [`Sink`] made by the source takes the chunks back,
//! in the same order, with the moved coordinates and normals, and writes a file that differs from
//! the input only there. Sinks write to a temporary file beside the target; [`Sink::finish`]
//! renames it over the target, and a sink dropped before that removes it.

use std::path::Path;

use crate::error::Result;
use crate::rigid::Vect;

pub use super::output::{OutFile, ResultSet, TempFile};

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
    /// The coordinate reference system the file declares (LAS/LAZ), if any.
    fn crs(&self) -> Option<crate::crs::Crs> {
        None
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
    /// Where a reader of the output finds the moved point `p` (world coordinates): rounded to
    /// the output's LAS frame, its single-precision floats or its decimals, as this sink writes
    /// every sample. The default writes coordinates as they are.
    fn written(&self, p: &Vect<3>) -> Vect<3> {
        *p
    }
    /// What [`Sink::written`] rounds to, in words for a table's caption (`"the output's scale
    /// 0.01"`); `None` where it writes coordinates as they are.
    fn rounding(&self) -> Option<String> {
        None
    }
    /// Completes the file and hands it to `set`, which renames it over the target with the
    /// run's other outputs; returns notes for the user.
    fn finish(self: Box<Self>, set: &ResultSet) -> Result<Vec<String>>;
}
