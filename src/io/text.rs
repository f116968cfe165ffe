//! Replacing numbers inside a file's bytes: the one writer of every text format (PLY ASCII,
//! OBJ, XYZ) and of binary PLY whose vertex records are walked rather than mapped (list
//! properties on vertices), so that everything between the numbers is copied as it was.
//!
//! **Precision of text numbers.** A number that did not change keeps its text. A moved one is
//! written with the precision its column (x, y, z, and nx, ny, nz where normals are rewritten)
//! has in the input, gathered by the reader in the pass that already reads every token
//! ([`Precision`]): in plain notation with the most digits after the point among the column's
//! plain numbers (`12.3456` and `7.5` make 4). Numbers in exponent notation (`1.5e-3`) give
//! significant digits instead (the most among them: `1.50e-3` has 3): a moved number is
//! written in exponent notation with that many where the column's decimals would keep fewer
//! of its digits (a small number), or where the column has no plain number with a point. A
//! column whose numbers are all integers (`0`, `-1`) shows no precision: its moved numbers are
//! written as the shortest text that reads back as the computed value, as are numbers whose
//! column has more than 17 decimals, past which a double holds no digit.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::require_extension;
use super::stream::{Accepted, Chunk, OutFile, ResultSet, Sink, TempFile};
// The readers of text formats take `Span` from here, with the `Edit`s made of it.
pub(crate) use super::stream::Span;
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// A number to write over a [`Span`]: as f64 or, for single-precision properties, as f32; in
/// text, with the precision of its column ([`Precision`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Edit {
    pub span: Span,
    pub value: f64,
    pub single: bool,
    /// The column: 0–2 for x, y, z, 3–5 for nx, ny, nz.
    pub column: usize,
}

/// Coordinate columns whose text precision is tracked: x, y, z, nx, ny, nz.
const COLUMNS: usize = 6;

/// The digits after the point past which a double holds no digit of its value.
const DOUBLE_DECIMALS: usize = 17;

/// The precision of a text file's coordinate columns (see the module docs), gathered from its
/// tokens as the reader walks them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Precision {
    /// Per column, the most digits after the point among its tokens in plain notation (`None`:
    /// no token with a point).
    decimals: [Option<u16>; COLUMNS],
    /// Per column, the most significant digits among its tokens in exponent notation.
    digits: [Option<u16>; COLUMNS],
}

impl Precision {
    /// Takes the number `token` of `column` into account.
    pub(crate) fn see(&mut self, column: usize, token: &[u8]) {
        let token = token
            .strip_prefix(b"-")
            .or(token.strip_prefix(b"+"))
            .unwrap_or(token);
        let digits = |b: &[u8]| b.iter().take_while(|c| c.is_ascii_digit()).count();
        let most = |slot: &mut Option<u16>, n: usize| {
            let n = n.min(u16::MAX as usize) as u16;
            *slot = Some(slot.map_or(n, |m| m.max(n)));
        };
        if let Some(e) = token.iter().position(|c| matches!(c, b'e' | b'E')) {
            let mantissa: Vec<u8> = token[..e].iter().copied().filter(|&c| c != b'.').collect();
            let significant = &mantissa[mantissa.iter().take_while(|&&c| c == b'0').count()..];
            most(&mut self.digits[column], digits(significant).max(1));
        } else if let Some(point) = token.iter().position(|&c| c == b'.') {
            most(&mut self.decimals[column], digits(&token[point + 1..]));
        }
    }

    /// Takes the three tokens at `spans` of `bytes` into account, as columns `first..first + 3`.
    pub(crate) fn see3(&mut self, first: usize, bytes: &[u8], spans: &[Span; 3]) {
        for (k, s) in spans.iter().enumerate() {
            self.see(first + k, &bytes[s.start..s.end]);
        }
    }

    /// The number a reader finds where [`Precision::write`] wrote `value`.
    pub(crate) fn written(&self, column: usize, value: f64, single: bool) -> f64 {
        let mut text = Vec::new();
        self.write(&mut text, column, value, single);
        std::str::from_utf8(&text)
            .ok()
            .and_then(|t| t.parse::<f64>().ok())
            .unwrap_or(value)
    }

    /// Writes `value`, a moved number of `column` (`single`: a float property).
    fn write(&self, out: &mut Vec<u8>, column: usize, value: f64, single: bool) {
        let decimals = self.decimals[column].map(usize::from);
        let digits = self.digits[column].map(usize::from);
        // The significant digits that `decimals` keep of `value`.
        let kept = |decimals: usize| {
            (value != 0.0 && value.is_finite())
                .then(|| value.abs().log10().floor() as i64 + 1 + decimals as i64)
        };
        let exponent = match (decimals, digits) {
            (None, Some(_)) => true,
            (Some(d), Some(s)) => kept(d).is_some_and(|k| k < s as i64),
            _ => false,
        };
        // Writing into a Vec cannot fail.
        let _ = match (decimals, digits) {
            (_, Some(s)) if exponent => {
                let after = s.clamp(1, DOUBLE_DECIMALS) - 1;
                write!(out, "{value:.after$e}")
            }
            (Some(d), _) => {
                let shortest = shortest(value, single);
                let point = shortest.find('.').map_or(0, |p| shortest.len() - p - 1);
                if d > DOUBLE_DECIMALS && point <= d {
                    write!(out, "{shortest}")
                } else {
                    write!(out, "{value:.d$}")
                }
            }
            _ => write!(out, "{}", shortest(value, single)),
        };
    }
}

/// The shortest text that reads back as `value` (as f32 for a `single`).
fn shortest(value: f64, single: bool) -> String {
    if single {
        format!("{}", value as f32)
    } else {
        format!("{value}")
    }
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

/// Fails unless `given` new values match the `expected` count of a file's samples.
pub(crate) fn check_count(path: &Path, given: usize, expected: usize) -> Result<()> {
    if given == expected {
        return Ok(());
    }
    Err(Error::param(format!(
        "{}: {given} new values for {expected} samples",
        path.display()
    )))
}

/// The edits writing the components of `v` that differ from the file's `old` ones over
/// `spans` (`single`: as f32), as columns `first..first + 3`.
pub(crate) fn edits3(
    spans: &[Span; 3],
    v: &Vect<3>,
    old: &Vect<3>,
    single: [bool; 3],
    first: usize,
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
            column: first + k,
        })
}

/// How the numbers of a file are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Numbers {
    /// As text, in the span of the old token (which may change length), with the precision of
    /// the input's columns.
    Text(Precision),
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
        Numbers::Text(precision) => return splice(bytes, edits, &precision),
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

/// `bytes` with each edit's span replaced by its number, written with the `precision` of its
/// column; spans must not overlap.
pub(crate) fn splice(bytes: &[u8], mut edits: Vec<Edit>, precision: &Precision) -> Vec<u8> {
    edits.sort_unstable_by_key(|e| e.span.start);
    let mut out = Vec::with_capacity(bytes.len() + bytes.len() / 4);
    let mut last = 0;
    for e in edits {
        out.extend_from_slice(&bytes[last..e.span.start]);
        precision.write(&mut out, e.column, e.value, e.single);
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
    out: BufWriter<OutFile>,
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
    fn written(&self, p: &Vect<3>) -> Vect<3> {
        Vect::<3>::from_fn(|k, _| match self.numbers {
            Numbers::Text(precision) => precision.written(k, p[k], self.singles[k]),
            Numbers::Binary { .. } if self.singles[k] => p[k] as f32 as f64,
            Numbers::Binary { .. } => p[k],
        })
    }

    fn rounding(&self) -> Option<String> {
        match self.numbers {
            Numbers::Text(_) => Some("the output's decimals".into()),
            Numbers::Binary { .. } if self.singles.contains(&true) => {
                Some("the output's single-precision floats".into())
            }
            Numbers::Binary { .. } => None,
        }
    }

    fn write(&mut self, chunk: &Chunk, moved: &[Vect<3>], normals: &[Vect<3>]) -> Result<Accepted> {
        let with_normals = !chunk.normals.is_empty();
        let stride = if with_normals { 6 } else { 3 };
        check_count(&self.input, chunk.spans.len(), stride * moved.len())?;
        let mut edits = Vec::with_capacity(chunk.spans.len());
        let unknown = Vect::<3>::repeat(f64::NAN);
        for (i, (spans, p)) in chunk.spans.chunks_exact(stride).zip(moved).enumerate() {
            let xyz: &[Span; 3] = spans[..3].try_into().expect("3 spans");
            let old = chunk.positions.get(i).unwrap_or(&unknown);
            edits.extend(edits3(xyz, p, old, self.singles, 0));
            if let (Some(singles), Some(n)) = (self.normal_singles, normals.get(i)) {
                let nxyz: &[Span; 3] = spans[3..].try_into().expect("3 normal spans");
                let old = chunk.normals.get(i).unwrap_or(&unknown);
                edits.extend(edits3(nxyz, &fit_singles(n, singles), old, singles, 3));
            }
        }
        self.out
            .write_all(&rewrite(&chunk.raw, edits, self.numbers))
            .map_err(|e| Error::write(self.file.target(), e))?;
        Ok(Accepted::Yes)
    }

    fn finish(self: Box<Self>, set: &ResultSet) -> Result<Vec<String>> {
        let Self { file, out, .. } = *self;
        set.stage_writer(file, out)?;
        Ok(Vec::new())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splice_replaces_only_the_spans() {
        let text = b"v 1 2 3 # keep\nvn 0.5 x\n";
        let at = |start, end, value, single, column| Edit {
            span: Span { start, end },
            value,
            single,
            column,
        };
        let out = splice(
            text,
            vec![
                at(18, 21, 0.25, true, 3),
                at(2, 3, -1.5, false, 0),
                at(6, 7, 1e-3, false, 2),
            ],
            &Precision::default(),
        );
        assert_eq!(out, b"v -1.5 2 0.001 # keep\nvn 0.25 x\n");
    }

    /// Moved numbers are written with their column's decimals, or its significant digits in
    /// exponent notation where the decimals keep fewer (or the column has no decimals); a
    /// column of integers, or of more decimals than a double holds, gets the shortest text that
    /// reads back exactly.
    #[test]
    fn moved_numbers_keep_their_columns_precision() {
        let mut p = Precision::default();
        for (column, token) in [
            (0, "1.25"),
            (0, "-3.5"),
            (0, "2.125e1"),
            (0, "-0.00150E-2"),
            (1, "7"),
            (1, "-12"),
            (2, "0.1234567890123456789"),
            (3, "1e-3"),
            (5, "0.5"),
        ] {
            p.see(column, token.as_bytes());
        }
        let text = |column, value, single| {
            let mut out = Vec::new();
            p.write(&mut out, column, value, single);
            String::from_utf8(out).unwrap()
        };
        // Column 0: 2 decimals; `2.125e1` has 4 significant digits, `-0.00150E-2` 3.
        assert_eq!(text(0, 123.456789, false), "123.46");
        assert_eq!(text(0, 12.3456, true), "12.35");
        assert_eq!(text(0, 0.1 + 0.2, false), "3.000e-1");
        assert_eq!(text(0, -0.000123456, false), "-1.235e-4");
        assert_eq!(text(0, 0.0, false), "0.00");
        assert_eq!(text(1, 2.0 / 3.0, false), "0.6666666666666666");
        assert_eq!(text(1, 2.0 / 3.0, true), "0.6666667");
        assert_eq!(text(2, 2.0 / 3.0, false), "0.6666666666666666");
        assert_eq!(text(2, 1e-25, false), "0.0000000000000000000");
        assert_eq!(text(3, 0.0123, false), "1e-2");
        assert_eq!(text(4, 0.1, false), "0.1");
        assert_eq!(text(5, 2.0 / 3.0, false), "0.7");
        assert_eq!(text(5, 1e-9, false), "0.0");
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
