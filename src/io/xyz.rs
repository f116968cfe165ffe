//! XYZ text point clouds: one point per line, `x y z` first (spaces, tabs or commas between),
//! anything after them (colors, normals, intensities) kept verbatim, as are blank lines and
//! comment lines starting with `#` or `//`.
//!
//! [`XyzStream`] streams a file of any size from a memory map: a chunk carries the bytes of its
//! lines (from the end of the previous chunk through its last point's line, and to the end of
//! the file for the last one) and where its numbers lie in them, and the
//! [`SpanSink`](super::text::SpanSink) writes them back with those numbers replaced, so the
//! chunks' bytes partition the file. Lines are read through [`PointLines`].

use std::path::{Path, PathBuf};
use std::sync::Arc;

use memmap2::Mmap;

use super::Opening;
use super::mapped::map;
use super::stream::{Bounds, Chunk, Sink, Source};
use super::text::{Numbers, Precision, Span, SpanSink};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// The point lines of a text, in order: each with the spans of its first three tokens and, when
/// asked, their values. Errors name the line (counted from `first_line`).
struct PointLines<'a> {
    text: &'a [u8],
    pos: usize,
    line: usize,
    path: &'a Path,
    parse: bool,
}

/// One point line: the spans of `x y z` (absolute in the text), their values (zeros unless
/// parsed), and the end of the line (after its newline).
type PointLine = ([Span; 3], [f64; 3], usize);

impl<'a> PointLines<'a> {
    fn new(text: &'a [u8], pos: usize, first_line: usize, path: &'a Path, parse: bool) -> Self {
        Self {
            text,
            pos,
            line: first_line,
            path,
            parse,
        }
    }
}

impl Iterator for PointLines<'_> {
    type Item = Result<PointLine>;

    fn next(&mut self) -> Option<Self::Item> {
        let b = self.text;
        while self.pos < b.len() {
            let start = self.pos;
            let end = b[start..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |i| start + i + 1);
            self.pos = end;
            self.line += 1;
            let line = &b[start..end];
            let first = line.iter().position(|c| !c.is_ascii_whitespace());
            let Some(first) = first else { continue };
            if line[first..].starts_with(b"#") || line[first..].starts_with(b"//") {
                continue;
            }
            return Some(self.point(start, line, end));
        }
        None
    }
}

impl PointLines<'_> {
    fn point(&self, start: usize, line: &[u8], end: usize) -> Result<PointLine> {
        let number = self.line;
        let mut tokens = token_spans(line);
        let mut spans = [Span::default(); 3];
        let mut values = [0.0; 3];
        for k in 0..3 {
            let Some((a, b)) = tokens.next() else {
                return Err(Error::format(
                    self.path,
                    format!("line {number}: fewer than 3 coordinates"),
                ));
            };
            spans[k] = Span {
                start: start + a,
                end: start + b,
            };
            if self.parse {
                let tok = String::from_utf8_lossy(&line[a..b]);
                values[k] = tok
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        Error::format(
                            self.path,
                            format!("line {number}: `{tok}` is not a finite number"),
                        )
                    })?;
            }
        }
        Ok((spans, values, end))
    }
}

/// An XYZ file streamed from a memory map.
pub struct XyzStream {
    path: PathBuf,
    map: Arc<Mmap>,
    count: u64,
    /// The precision of the coordinate columns, gathered while counting the points.
    precision: Precision,
    /// Byte where the next chunk starts, its first line's number, and its first point's index.
    pos: usize,
    line: usize,
    next: u64,
}

impl XyzStream {
    /// Opens `path`, counting its point lines and gathering the precision of their coordinates
    /// (the numbers are parsed chunk by chunk); a file without points is refused.
    pub fn open(path: &Path) -> Result<Self> {
        Self::open_as(path, Opening::Stream)
    }

    /// Opens `path` as [`XyzStream::open`] does, checking what `opening` asks: to be read
    /// whole, every number is parsed as the lines are counted (so the first bad line is the
    /// one reported), and a file without points opens.
    pub(super) fn open_as(path: &Path, opening: Opening) -> Result<Self> {
        let map = map(path)?;
        let mut count = 0;
        let mut precision = Precision::default();
        let parse = opening == Opening::Whole;
        for point in PointLines::new(&map, 0, 0, path, parse) {
            precision.see3(0, &map, &point?.0);
            count += 1;
        }
        if count == 0 && opening == Opening::Stream {
            return Err(Error::format(path, "the file holds no points"));
        }
        Ok(Self {
            path: path.to_path_buf(),
            map: Arc::new(map),
            count,
            precision,
            pos: 0,
            line: 0,
            next: 0,
        })
    }
}

impl Source for XyzStream {
    fn path(&self) -> &Path {
        &self.path
    }

    fn len(&self) -> u64 {
        self.count
    }

    fn rewind(&mut self) -> Result<()> {
        (self.pos, self.line, self.next) = (0, 0, 0);
        Ok(())
    }

    fn read(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        chunk.clear(self.next);
        let start = self.pos;
        let mut lines = PointLines::new(&self.map, start, self.line, &self.path, true);
        let mut end = start;
        while chunk.positions.len() < max {
            let Some(point) = lines.next() else { break };
            let (spans, p, line_end) = point?;
            chunk.positions.push(Vect::<3>::from(p));
            chunk.spans.extend(spans.map(|s| s.before(start)));
            end = line_end;
        }
        let n = chunk.positions.len();
        self.next += n as u64;
        if self.next == self.count {
            // The last chunk carries the lines after the last point too.
            end = self.map.len();
        }
        self.line = lines.line;
        self.pos = end;
        chunk.raw.extend_from_slice(&self.map[start..end]);
        Ok(n)
    }

    fn sink(&self, output: &Path, _bounds: Option<Bounds>) -> Result<Box<dyn Sink>> {
        let numbers = Numbers::Text(self.precision);
        let sink = SpanSink::create(&self.path, output, "xyz", numbers, [false; 3], None)?;
        Ok(Box::new(sink))
    }
}

fn token_spans(line: &[u8]) -> impl Iterator<Item = (usize, usize)> + '_ {
    let sep = |c: u8| c.is_ascii_whitespace() || c == b',';
    let mut i = 0;
    std::iter::from_fn(move || {
        while i < line.len() && sep(line[i]) {
            i += 1;
        }
        if i >= line.len() {
            return None;
        }
        let start = i;
        while i < line.len() && !sep(line[i]) {
            i += 1;
        }
        Some((start, i))
    })
}
