//! XYZ text point clouds: one point per line, `x y z` first (spaces, tabs or commas between),
//! anything after them (colors, normals, intensities) kept verbatim, as are blank lines and
//! comment lines starting with `#` or `//`.

use std::path::{Path, PathBuf};

use super::text::{Span, check_count, edits3, splice};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// An XYZ file held in memory with the locations of its coordinates.
#[derive(Debug)]
pub struct XyzFile {
    path: PathBuf,
    text: String,
    /// Byte spans of the three coordinate tokens of every point.
    spans: Vec<[Span; 3]>,
    positions: Vec<Vect<3>>,
}

impl XyzFile {
    /// Reads and indexes `path`.
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let text = String::from_utf8(bytes)
            .map_err(|_| Error::format(path, "not a text file (invalid UTF-8)"))?;
        let mut spans = Vec::new();
        let mut positions = Vec::new();
        let mut offset = 0;
        for (number, line) in text.split_inclusive('\n').enumerate() {
            let start = offset;
            offset += line.len();
            let t = line.trim();
            if t.is_empty() || t.starts_with('#') || t.starts_with("//") {
                continue;
            }
            let mut tokens = token_spans(line).map(|(a, b)| (start + a, start + b));
            let mut s = [Span::default(); 3];
            let mut p = [0.0; 3];
            for k in 0..3 {
                let Some(span) = tokens.next() else {
                    return Err(Error::format(
                        path,
                        format!("line {}: fewer than 3 coordinates", number + 1),
                    ));
                };
                let tok = &text[span.0..span.1];
                p[k] = tok
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        Error::format(
                            path,
                            format!("line {}: `{tok}` is not a finite number", number + 1),
                        )
                    })?;
                s[k] = Span {
                    start: span.0,
                    end: span.1,
                };
            }
            spans.push(s);
            positions.push(Vect::<3>::from(p));
        }
        Ok(Self {
            path: path.to_path_buf(),
            text,
            spans,
            positions,
        })
    }

    /// Point positions.
    pub fn positions(&self) -> &[Vect<3>] {
        &self.positions
    }

    /// The file's text with the points replaced by `positions`.
    pub fn encode(&self, positions: &[Vect<3>]) -> Result<Vec<u8>> {
        check_count(&self.path, positions.len(), self.spans.len())?;
        let edits = self
            .spans
            .iter()
            .zip(positions)
            .flat_map(|(s, p)| edits3(s, p, [false; 3]))
            .collect();
        Ok(splice(self.text.as_bytes(), edits))
    }
}

fn token_spans(line: &str) -> impl Iterator<Item = (usize, usize)> + '_ {
    let b = line.as_bytes();
    let sep = |c: u8| c.is_ascii_whitespace() || c == b',';
    let mut i = 0;
    std::iter::from_fn(move || {
        while i < b.len() && sep(b[i]) {
            i += 1;
        }
        if i >= b.len() {
            return None;
        }
        let start = i;
        while i < b.len() && !sep(b[i]) {
            i += 1;
        }
        Some((start, i))
    })
}
