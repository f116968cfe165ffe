//! Replacing numbers inside a file's bytes: the one writer of every text format (PLY ASCII,
//! OBJ, XYZ) and of binary PLY whose vertex records are walked rather than mapped (list
//! properties on vertices), so that everything between the numbers is copied as it was.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::require_extension;
use super::stream::{Accepted, Chunk, Sink, TempFile};
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

/// A number to write over a [`Span`]: as f64 (shortest text that reads back exactly) or, for
/// single-precision properties, as f32.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Edit {
    pub span: Span,
    pub value: f64,
    pub single: bool,
}

/// Fails unless `given` new values match the `expected` count of a file's samples.
pub(crate) fn check_count(path: &Path, given: usize, expected: usize) -> Result<()> {
    if given == expected {
        return Ok(());
    }
    Err(Error::Param(format!(
        "{}: {given} new values for {expected} samples",
        path.display()
    )))
}

/// `n`, a normal to be written, scaled down where a component of it stored in single precision
/// (`singles`) lies past the largest float, until each fits: a huge normal keeps its direction
/// and stays finite instead of becoming infinite.
pub(crate) fn fit_singles(n: &Vect<3>, singles: [bool; 3]) -> Vect<3> {
    let max = f32::MAX as f64;
    let largest = (0..3)
        .filter(|&k| singles[k])
        .map(|k| n[k].abs())
        .fold(0.0, f64::max);
    if largest <= max || !largest.is_finite() {
        return *n;
    }
    let scaled = n * (max / largest);
    Vect::<3>::from_fn(|k, _| {
        if singles[k] {
            scaled[k].clamp(-max, max)
        } else {
            scaled[k]
        }
    })
}

/// The edits writing the components of `v` that differ from the file's `old` ones over
/// `spans` (`single`: as f32).
pub(crate) fn edits3(
    spans: &[Span; 3],
    v: &Vect<3>,
    old: &Vect<3>,
    single: [bool; 3],
) -> impl Iterator<Item = Edit> + use<> {
    // A number that did not change keeps its text (a fixed sample keeps its bytes, not only
    // its value).
    let (spans, v, old) = (*spans, *v, *old);
    (0..3)
        .filter(move |&k| v[k].to_bits() != old[k].to_bits())
        .map(move |k| Edit {
            span: spans[k],
            value: v[k],
            single: single[k],
        })
}

/// How the numbers of a file are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Numbers {
    /// As text, in the span of the old token (which may change length).
    Text,
    /// As IEEE floats of the span's size, big- or little-endian.
    Binary {
        /// Big-endian.
        big: bool,
    },
}

/// `bytes` with each edit's number written over its span in the file's `numbers` format;
/// spans must not overlap.
pub(crate) fn rewrite(bytes: &[u8], edits: Vec<Edit>, numbers: Numbers) -> Vec<u8> {
    let big = match numbers {
        Numbers::Text => return splice(bytes, edits),
        Numbers::Binary { big } => big,
    };
    let mut out = bytes.to_vec();
    for e in edits {
        let (v, dst) = (e.value, &mut out[e.span.start..e.span.end]);
        match (e.single, big) {
            (false, false) => dst.copy_from_slice(&v.to_le_bytes()),
            (false, true) => dst.copy_from_slice(&v.to_be_bytes()),
            (true, false) => dst.copy_from_slice(&(v as f32).to_le_bytes()),
            (true, true) => dst.copy_from_slice(&(v as f32).to_be_bytes()),
        }
    }
    out
}

/// `bytes` with each edit's span replaced by its number; spans must not overlap.
pub(crate) fn splice(bytes: &[u8], mut edits: Vec<Edit>) -> Vec<u8> {
    edits.sort_unstable_by_key(|e| e.span.start);
    let mut out = Vec::with_capacity(bytes.len() + bytes.len() / 4);
    let mut last = 0;
    for e in edits {
        out.extend_from_slice(&bytes[last..e.span.start]);
        // Writing into a Vec cannot fail.
        let _ = if e.single {
            write!(out, "{}", e.value as f32)
        } else {
            write!(out, "{}", e.value)
        };
        last = e.span.end;
    }
    out.extend_from_slice(&bytes[last..]);
    out
}

/// The sink of the streams that carry their records' bytes (XYZ, ASCII PLY, binary PLY with
/// walked vertex records): each chunk's bytes written with the numbers at its [`Chunk::spans`]
/// replaced; `singles` marks the components written as f32.
pub(crate) struct SpanSink {
    input: PathBuf,
    file: TempFile,
    out: BufWriter<File>,
    numbers: Numbers,
    singles: [bool; 3],
    normal_singles: Option<[bool; 3]>,
}

impl SpanSink {
    /// A sink for `output`, which must have the extension `ext`; `input` names errors.
    pub(crate) fn create(
        input: &Path,
        output: &Path,
        ext: &str,
        numbers: Numbers,
        singles: [bool; 3],
        normal_singles: Option<[bool; 3]>,
    ) -> Result<Self> {
        require_extension(output, ext)?;
        let (file, out) = TempFile::create(output)?;
        Ok(Self {
            input: input.to_path_buf(),
            file,
            out,
            numbers,
            singles,
            normal_singles,
        })
    }
}

impl Sink for SpanSink {
    fn write(&mut self, chunk: &Chunk, moved: &[Vect<3>], normals: &[Vect<3>]) -> Result<Accepted> {
        let with_normals = !chunk.normals.is_empty();
        let stride = if with_normals { 6 } else { 3 };
        check_count(&self.input, chunk.spans.len(), stride * moved.len())?;
        let mut edits = Vec::with_capacity(chunk.spans.len());
        let unknown = Vect::<3>::repeat(f64::NAN);
        for (i, (spans, p)) in chunk.spans.chunks_exact(stride).zip(moved).enumerate() {
            let xyz: &[Span; 3] = spans[..3].try_into().expect("3 spans");
            let old = chunk.positions.get(i).unwrap_or(&unknown);
            edits.extend(edits3(xyz, p, old, self.singles));
            if let (Some(singles), Some(n)) = (self.normal_singles, normals.get(i)) {
                let nxyz: &[Span; 3] = spans[3..].try_into().expect("3 normal spans");
                let old = chunk.normals.get(i).unwrap_or(&unknown);
                edits.extend(edits3(nxyz, &fit_singles(n, singles), old, singles));
            }
        }
        self.out
            .write_all(&rewrite(&chunk.raw, edits, self.numbers))
            .map_err(|e| Error::write(self.file.target(), e))?;
        Ok(Accepted::Yes)
    }

    fn finish(self: Box<Self>) -> Result<Vec<String>> {
        let Self { file, out, .. } = *self;
        file.commit_writer(out)?;
        Ok(Vec::new())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splice_replaces_only_the_spans() {
        let text = b"v 1 2 3 # keep\nvn 0.5 x\n";
        let at = |start, end, value, single| Edit {
            span: Span { start, end },
            value,
            single,
        };
        let out = splice(
            text,
            vec![
                at(18, 21, 0.25, true),
                at(2, 3, -1.5, false),
                at(6, 7, 1e-3, false),
            ],
        );
        assert_eq!(out, b"v -1.5 2 0.001 # keep\nvn 0.25 x\n");
    }

    /// A normal of floats past the largest float is scaled down to fit, keeping its direction;
    /// doubles and normals that fit are kept.
    #[test]
    fn huge_single_normals_fit_their_floats() {
        let n = Vect::<3>::new(3e38, -3e38, 1.0);
        let fit = fit_singles(&n, [true; 3]);
        assert!(fit.iter().all(|v| (*v as f32).is_finite()), "{fit:?}");
        assert!((fit.normalize() - n.normalize()).norm() < 1e-12);
        assert_eq!(fit_singles(&n, [false; 3]), n);
        let small = Vect::<3>::new(1e37, 1e37, 1e37);
        assert_eq!(fit_singles(&small, [true; 3]), small);
    }
}
