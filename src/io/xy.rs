//! 2D point sets as text (`.xy`): one point per line, `x y` then anything (kept verbatim);
//! blank lines and lines starting with `#` are kept as they are. Read whole: 2D sets are small
//! next to the scans the streaming readers are for.

use std::path::Path;

use crate::error::{Error, Result};
use crate::rigid::Vect;

/// A `.xy` file: its lines and the points on them.
#[derive(Debug, Clone)]
pub struct XyFile {
    lines: Vec<String>,
    /// For each point, its line and the byte where the text after `x y` starts.
    at: Vec<(usize, usize)>,
    points: Vec<Vect<2>>,
}

impl XyFile {
    /// Reads `path`; a line whose first two fields are not finite numbers is an error naming
    /// the file and the line.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let mut file = Self {
            lines: Vec::new(),
            at: Vec::new(),
            points: Vec::new(),
        };
        for (n, line) in text.lines().enumerate() {
            let trimmed = line.trim_start();
            if !(trimmed.is_empty() || trimmed.starts_with('#')) {
                let mut fields = line.split_whitespace();
                let mut number = || -> Option<f64> {
                    fields.next()?.parse::<f64>().ok().filter(|v| v.is_finite())
                };
                let (Some(x), Some(y)) = (number(), number()) else {
                    return Err(Error::Format {
                        path: path.to_path_buf(),
                        message: format!("line {}: expected `x y`, got {line:?}", n + 1),
                    });
                };
                // The rest of the line starts after the second field.
                let mut rest = line;
                for _ in 0..2 {
                    rest = rest.trim_start();
                    rest = &rest[rest.find(char::is_whitespace).unwrap_or(rest.len())..];
                }
                file.at.push((n, line.len() - rest.len()));
                file.points.push(Vect::<2>::new(x, y));
            }
            file.lines.push(line.to_string());
        }
        if file.points.is_empty() {
            return Err(Error::Format {
                path: path.to_path_buf(),
                message: "no points".into(),
            });
        }
        Ok(file)
    }

    /// The points.
    pub fn points(&self) -> &[Vect<2>] {
        &self.points
    }

    /// Writes the file with the points replaced by `moved` (shortest round-trip numbers),
    /// every other byte as read, atomically. A point that did not move keeps its line.
    pub fn write(&self, path: &Path, moved: &[Vect<2>]) -> Result<()> {
        let mut lines = self.lines.clone();
        for ((&(n, rest), p), old) in self.at.iter().zip(moved).zip(&self.points) {
            if p.map(f64::to_bits) != old.map(f64::to_bits) {
                lines[n] = format!("{} {}{}", p.x, p.y, &self.lines[n][rest..]);
            }
        }
        let mut text = lines.join("\n");
        text.push('\n');
        super::write_atomic(path, text.as_bytes())
    }
}
