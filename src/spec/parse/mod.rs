//! The edit spec's TOML read into [`EditSpec`]: the sections and their keys checked (unknown
//! keys are errors), every value validated, and every error naming the line of the value at
//! fault — in an array written over many lines (a `polygon`'s points, a `matrix`'s or `view`'s
//! rows, `indices`, `classification`), the line of the element, found by the spans that
//! `toml::de::DeTable` keeps, read only on the way to an error. The entry's parts are read by
//! the children: `region` (what it selects), `motion` (a handle's transform) and `target` (soft
//! targets and control-point files).

mod motion;
mod region;
mod target;

use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use super::entries::{EditSpec, Entry, HandleMotion, Pin, Trend};
use crate::error::{Error, Result};
use crate::rigid::{Dim, Rigid, Vect};
use crate::said::{Kind, Said};

pub use motion::MAX_TURN_DEGREES;

#[derive(Deserialize)]
struct RawSpec {
    #[serde(default)]
    fixed: Vec<Spanned<toml::Table>>,
    #[serde(default)]
    handle: Vec<Spanned<toml::Table>>,
    #[serde(default)]
    pin: Vec<Spanned<toml::Table>>,
    #[serde(default)]
    target: Vec<Spanned<toml::Table>>,
    #[serde(default)]
    stiffness: Vec<Spanned<toml::Table>>,
}

/// The largest magnitude of a motion's numbers (translations, pivots, pins, targets, scales,
/// matrix entries): f64 keeps 15–16 significant digits, so a shape moved to 1e15 keeps none
/// below the unit, and past about 1e50 the solver's squared residuals overflow (a fuzzed
/// `translate = [1e308, …]` ended in an indefinite Gauss-Newton system, exit 1). Regions are
/// not bounded: a box to ±1e308 is a way of saying "everything".
pub const LARGEST: f64 = 1e15;

/// The keys that select: one or more in an entry, combined (all must hold).
const REGION_KEYS: [&str; 7] = [
    "box",
    "sphere",
    "plane",
    "indices",
    "classification",
    "polygon",
    "polygon_file",
];
/// Keys that qualify a selection.
const SELECTION_KEYS: [&str; 4] = ["z", "invert", "view", "visible"];

/// Reads and validates the edit spec in `path`.
pub fn read_spec<const D: usize>(path: &Path) -> Result<EditSpec<D>>
where
    Dim<D>: Rigid<D>,
{
    let text = std::fs::read_to_string(path).map_err(|e| Error::spec_file(path, e))?;
    parse_spec(&text, path.parent().unwrap_or(Path::new(".")), path)
}

/// Parses an edit spec. `base` is the folder that relative file names (`indices`, `file`) are
/// resolved against; `name` names the spec in errors.
pub fn parse_spec<const D: usize>(text: &str, base: &Path, name: &Path) -> Result<EditSpec<D>>
where
    Dim<D>: Rigid<D>,
{
    let ctx = Ctx::new(text, base, name);
    let raw: RawSpec = toml::from_str(text).map_err(|e| ctx.toml(&e))?;
    let top: toml::Table = toml::from_str(text).map_err(|e| ctx.toml(&e))?;
    if let Some(k) = top
        .keys()
        .find(|k| !["fixed", "handle", "pin", "target", "stiffness", "trend"].contains(&k.as_str()))
    {
        return Err(ctx.error(
            None,
            format!(
                "unknown section `{k}` (expected fixed, handle, pin, target, stiffness or trend)"
            ),
        ));
    }
    let mut spec = EditSpec {
        name: name.to_path_buf(),
        ..EditSpec::default()
    };
    for t in &raw.fixed {
        let line = ctx.line(t);
        ctx.allow(t.get_ref(), &[], line)?;
        spec.fixed.push(Entry {
            region: ctx.region(t.get_ref(), line)?,
            value: (),
            line,
        });
    }
    for t in &raw.handle {
        let line = ctx.line(t);
        ctx.allow(
            t.get_ref(),
            &["translate", "rotate", "scale", "pivot", "matrix"],
            line,
        )?;
        spec.handles.push(Entry {
            region: ctx.region(t.get_ref(), line)?,
            value: ctx.handle_motion(t.get_ref(), line)?,
            line,
        });
    }
    for t in &raw.pin {
        let line = ctx.line(t);
        ctx.allow_only(t.get_ref(), &["point", "to"], line)?;
        spec.pins.push(Pin {
            point: ctx.motion_vector(t.get_ref(), "point", line)?,
            to: ctx.motion_vector(t.get_ref(), "to", line)?,
            line,
        });
    }
    for t in &raw.target {
        let line = ctx.line(t);
        ctx.allow_only(
            t.get_ref(),
            &["from", "to", "weight", "file", "snap", "exact"],
            line,
        )?;
        let first = spec.targets.len();
        spec.targets.extend(ctx.targets(t.get_ref(), line, first)?);
    }
    spec.trend = match top.get("trend") {
        None if raw.target.iter().any(|t| t.get_ref().contains_key("file")) => Trend::Spline,
        None => Trend::None,
        Some(value) => value.as_str().and_then(Trend::named).ok_or_else(|| {
            ctx.error(
                ctx.at(0, "trend"),
                format!(
                    "trend {value} is not one of {}",
                    Trend::NAMES.map(|n| format!("\"{n}\"")).join(", ")
                ),
            )
        })?,
    };
    for t in &raw.stiffness {
        let line = ctx.line(t);
        ctx.allow(t.get_ref(), &["scale"], line)?;
        let scale: f64 = ctx.field(t.get_ref(), "scale", line)?;
        if !(scale.is_finite() && scale > 0.0) {
            return Err(ctx.error(
                ctx.at(line, "scale"),
                format!("stiffness scale {scale} must be positive"),
            ));
        }
        spec.stiffness.push(Entry {
            region: ctx.region(t.get_ref(), line)?,
            value: scale,
            line,
        });
    }
    if !spec.has_constraints() {
        return Err(Error::NoConstraints);
    }
    Ok(spec)
}

/// Parses handle poses alone: one `[[handle]]` table a handle, holding only its motion
/// (`translate`, `rotate`, `scale`, `pivot`, or `matrix`), as a live deformation takes the
/// poses of the handles its spec already selected. `name` names the text in errors.
pub fn parse_poses<const D: usize>(text: &str, name: &Path) -> Result<Vec<HandleMotion<D>>>
where
    Dim<D>: Rigid<D>,
{
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct RawPoses {
        #[serde(default)]
        handle: Vec<Spanned<toml::Table>>,
    }
    let ctx = Ctx::new(text, Path::new("."), name);
    let raw: RawPoses = toml::from_str(text).map_err(|e| ctx.toml(&e))?;
    raw.handle
        .iter()
        .map(|t| {
            let line = ctx.line(t);
            let keys = ["translate", "rotate", "scale", "pivot", "matrix"];
            ctx.allow_only(t.get_ref(), &keys, line)?;
            ctx.handle_motion(t.get_ref(), line)
        })
        .collect()
}

struct Ctx<'a> {
    text: &'a str,
    base: &'a Path,
    name: &'a Path,
    /// Where each `\n` of the text lies: an entry's line is found by a binary search, so that
    /// a spec of many entries is read in time linear in its length.
    newlines: Vec<usize>,
}

/// The TOML parser's message, a value of the wrong kind as [`Said::mismatch`].
fn parser_said(message: &str) -> Said {
    let message = message.trim();
    match message
        .strip_prefix("invalid type: ")
        .and_then(|m| m.rsplit_once(", expected "))
    {
        Some((found, expected)) => {
            Said::new().mismatch(Kind::from_parser(expected), Kind::from_parser(found))
        }
        None => Said::from(message),
    }
}

impl<'a> Ctx<'a> {
    fn new(text: &'a str, base: &'a Path, name: &'a Path) -> Self {
        let newlines = text.match_indices('\n').map(|(at, _)| at).collect();
        Self {
            text,
            base,
            name,
            newlines,
        }
    }

    fn error(&self, line: Option<usize>, message: String) -> Error {
        Error::spec(self.name, line, message)
    }

    /// The TOML parser's error: its line and column, its message (a value of the wrong kind
    /// as [`Said::mismatch`]) and, for the command line, a picture of the line.
    fn toml(&self, e: &toml::de::Error) -> Error {
        let said = parser_said(e.message());
        let Some(span) = e.span() else {
            return Error::spec(self.name, None, said);
        };
        let at = span.start.min(self.text.len());
        let line = self.newlines.partition_point(|&n| n < at);
        let start = if line == 0 {
            0
        } else {
            self.newlines[line - 1] + 1
        };
        let text = self.text[start..].lines().next().unwrap_or("");
        let column = self.text[start..at].chars().count();
        let width = self.text[at..span.end.min(start + text.len()).max(at)]
            .chars()
            .count()
            .max(1);
        let number = (line + 1).to_string();
        let margin = " ".repeat(number.len());
        Error::Spec {
            path: self.name.to_path_buf(),
            line: Some(line + 1),
            column: Some(column + 1),
            message: said,
            excerpt: Some(format!(
                "{margin} |\n{number} | {text}\n{margin} | {}{}",
                " ".repeat(column),
                "^".repeat(width)
            )),
        }
    }

    /// The line of `key` (its first part, for `box.min`) in the entry that starts on line
    /// `entry`: where a value's error is reported. The entry's own line when the key is not
    /// written on a line of its own (a dotted key, a key of an inline table).
    fn at(&self, entry: usize, key: &str) -> Option<usize> {
        let root = key.split('.').next().unwrap_or(key);
        for (i, text) in self.text.lines().enumerate().skip(entry) {
            let t = text.trim_start();
            // The next table header ends the entry; a multi-line array's rows start with `[`
            // and a number or another `[`.
            let header = t.trim_start_matches('[').trim_start();
            if t.starts_with('[') && header.starts_with(|c: char| c.is_alphabetic() || c == '"') {
                break;
            }
            let unquoted = t
                .strip_prefix('"')
                .and_then(|r| r.strip_prefix(root)?.strip_prefix('"'))
                .or_else(|| t.strip_prefix(root));
            if let Some(rest) = unquoted.map(str::trim_start)
                && (rest.starts_with('=') || rest.starts_with('.'))
            {
                return Some(i + 1);
            }
        }
        Some(entry)
    }

    fn line<T>(&self, s: &Spanned<T>) -> usize {
        self.line_at(s.span().start)
    }

    /// The line of the byte `at` of the text.
    fn line_at(&self, at: usize) -> usize {
        let at = at.min(self.text.len());
        self.newlines.partition_point(|&n| n < at) + 1
    }

    /// The line of the element at `path` (indices into nested arrays: a polygon's point, then
    /// its coordinate; a matrix's row, then its column) of `key` (`box.min` for a key of an
    /// inline table) in the entry whose header is on line `entry`: where an element's error is
    /// reported, for arrays written over many lines. The key's line ([`Ctx::at`]) where the
    /// element is not found. The spec is parsed again for the spans of its values, which
    /// `toml::Table` does not keep: only on the way to an error.
    fn at_element(&self, entry: usize, key: &str, path: &[usize]) -> Option<usize> {
        self.element_start(entry, key, path)
            .map(|at| self.line_at(at))
            .or_else(|| self.at(entry, key))
    }

    fn element_start(&self, entry: usize, key: &str, path: &[usize]) -> Option<usize> {
        let doc = DeTable::parse(self.text).ok()?;
        let entries = doc.get_ref().values().filter_map(|v| match v.get_ref() {
            DeValue::Array(a) => Some(a.iter()),
            _ => None,
        });
        let table = entries
            .flatten()
            .find(|t| self.line_at(t.span().start) == entry)?;
        let mut value = table;
        for part in key.split('.') {
            let DeValue::Table(t) = value.get_ref() else {
                return None;
            };
            value = t.iter().find(|(k, _)| k.get_ref() == part)?.1;
        }
        for &i in path {
            let DeValue::Array(a) = value.get_ref() else {
                return None;
            };
            value = a.get(i)?;
        }
        Some(value.span().start)
    }

    /// The array of arrays of numbers under `key` (a polygon's points, a matrix's rows), each
    /// number finite; `what` names a row in messages (`point`, `row`, counted from 1). An
    /// error names the line of the row or the number at fault.
    fn rows(&self, t: &toml::Table, key: &str, what: &str, line: usize) -> Result<Vec<Vec<f64>>> {
        let Some(toml::Value::Array(rows)) = t.get(key) else {
            return self.field(t, key, line);
        };
        let mut out = Vec::with_capacity(rows.len());
        for (i, row) in rows.iter().enumerate() {
            let toml::Value::Array(row) = row else {
                return Err(self.error(
                    self.at_element(line, key, &[i]),
                    format!("`{key}` {what} {} is {row}, not a list of numbers", i + 1),
                ));
            };
            let mut numbers = Vec::with_capacity(row.len());
            for (j, v) in row.iter().enumerate() {
                let x = match v {
                    toml::Value::Float(x) => *x,
                    toml::Value::Integer(i) => *i as f64,
                    _ => f64::NAN,
                };
                if !x.is_finite() {
                    let why = match v {
                        toml::Value::Float(_) => "not finite",
                        _ => "not a number",
                    };
                    return Err(self.error(
                        self.at_element(line, key, &[i, j]),
                        format!("`{key}` {what} {} holds {v}, which is {why}", i + 1),
                    ));
                }
                numbers.push(x);
            }
            out.push(numbers);
        }
        Ok(out)
    }

    fn allow(&self, t: &toml::Table, extra: &[&str], line: usize) -> Result<()> {
        let keys: Vec<&str> = REGION_KEYS
            .iter()
            .chain(&SELECTION_KEYS)
            .chain(extra)
            .copied()
            .collect();
        self.allow_only(t, &keys, line)
    }

    fn allow_only(&self, t: &toml::Table, keys: &[&str], line: usize) -> Result<()> {
        match t.keys().find(|k| !keys.contains(&k.as_str())) {
            Some(k) => Err(self.error(
                self.at(line, k),
                format!("unknown key `{k}` (expected one of {})", keys.join(", ")),
            )),
            None => Ok(()),
        }
    }

    fn field<T: serde::de::DeserializeOwned>(
        &self,
        t: &toml::Table,
        key: &str,
        line: usize,
    ) -> Result<T> {
        let v = t
            .get(key)
            .ok_or_else(|| self.error(self.at(line, key), format!("missing `{key}`")))?;
        v.clone().try_into().map_err(|e| {
            let said = Said::from(format!("`{key}`: ")).then(parser_said(e.message()));
            Error::spec(self.name, self.at(line, key), said)
        })
    }

    fn vector<const D: usize>(&self, t: &toml::Table, key: &str, line: usize) -> Result<Vect<D>> {
        let v: Vec<f64> = self.field(t, key, line)?;
        self.to_vect(&v, key, line)
    }

    /// A vector that places or moves samples (a translation, a pivot, a pin, a target): finite
    /// and at most [`LARGEST`] in magnitude.
    fn motion_vector<const D: usize>(
        &self,
        t: &toml::Table,
        key: &str,
        line: usize,
    ) -> Result<Vect<D>> {
        let v: Vect<D> = self.vector(t, key, line)?;
        self.within_range(v.amax(), key, line)?;
        Ok(v)
    }

    fn within_range(&self, magnitude: f64, key: &str, line: usize) -> Result<()> {
        if magnitude <= LARGEST {
            Ok(())
        } else {
            Err(self.error(self.at(line, key), self.beyond_range(magnitude, key)))
        }
    }

    /// The message of a number of `key` whose `magnitude` is beyond [`LARGEST`].
    fn beyond_range(&self, magnitude: f64, key: &str) -> String {
        format!(
            "`{key}` reaches {magnitude:e}, beyond {LARGEST:e}: a shape moved or scaled that far \
             keeps no detail in 64-bit floats, and the solve fails"
        )
    }

    /// The `n` × `n` numbers of `key` ([`Ctx::rows`]: finite): a wrong count of rows names the
    /// key's line, a row of the wrong length its own.
    fn square(&self, t: &toml::Table, key: &str, n: usize, line: usize) -> Result<Vec<Vec<f64>>> {
        let rows = self.rows(t, key, "row", line)?;
        if let Some(i) = rows.iter().position(|r| r.len() != n) {
            return Err(self.error(
                self.at_element(line, key, &[i]),
                format!(
                    "`{key}` row {} has {} numbers: `{key}` is {n} rows of {n} numbers",
                    i + 1,
                    rows[i].len()
                ),
            ));
        }
        if rows.len() != n {
            return Err(self.error(
                self.at(line, key),
                format!("`{key}` must be {n} rows of {n} numbers"),
            ));
        }
        Ok(rows)
    }

    fn to_vect<const D: usize>(&self, v: &[f64], key: &str, line: usize) -> Result<Vect<D>> {
        if v.len() != D || !v.iter().all(|x| x.is_finite()) {
            return Err(self.error(
                self.at(line, key),
                format!(
                    "`{key}` must be {D} finite numbers, got {}",
                    crate::human::list(v)
                ),
            ));
        }
        Ok(Vect::<D>::from_column_slice(v))
    }

    fn resolve(&self, file: &str) -> PathBuf {
        self.base.join(file)
    }
}

/// The file name of `path` for messages.
fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rigid::Mat;
    use crate::spec::region::Polygon;

    fn parse(text: &str) -> Result<EditSpec<3>> {
        parse_spec(text, Path::new("."), Path::new("edit.toml"))
    }

    #[test]
    fn indices_come_as_a_list_or_a_file() {
        let spec = parse("[[fixed]]\nindices = [0, 5, 9]\n").unwrap();
        let origin = Vect::<3>::zeros();
        let selected: Vec<u64> = (0..12)
            .filter(|&i| spec.fixed[0].region.selects(i, &origin, None))
            .collect();
        assert_eq!(selected, [0, 5, 9]);
        let err = parse("[[fixed]]\nindices = [0, -5]\n")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("edit.toml: line 2: `indices` lists -5: a sample index is a whole number"),
            "{err}"
        );
        // An index past the input's samples is refused with the spec's line.
        let spec = parse(
            "[[fixed]]\nbox = { min = [0, 0, 0], max = [1, 1, 1] }\n\n[[handle]]\n\
                          translate = [1, 0, 0]\ninvert = true\nindices = [3, 99999]\n",
        )
        .unwrap();
        assert!(spec.check_indices(100_000).is_ok());
        let err = spec.check_indices(3000).unwrap_err().to_string();
        assert_eq!(
            err,
            "edit.toml: line 7: `indices` lists sample 99999, but the input has 3000 samples, \
             numbered 0 to 2999"
        );
    }

    #[test]
    fn parses_the_design_example() {
        let spec = parse(
            r#"
[[fixed]]
box = { min = [0.0, 0.0, 0.0], max = [1.0, 10.0, 10.0] }

[[handle]]
sphere = { center = [9.0, 5.0, 5.0], radius = 1.0 }
translate = [0.0, 0.0, 4.0]
rotate = { axis = [0.0, 1.0, 0.0], degrees = 90.0 }

[[pin]]
point = [5.0, 5.0, 9.0]
to = [5.0, 5.0, 11.0]

[[target]]
from = [1.0, 2.0, 3.0]
to = [1.1, 2.0, 3.2]
weight = 1.0

[[stiffness]]
plane = { point = [5.0, 0.0, 0.0], normal = [1.0, 0.0, 0.0] }
scale = 0.2
"#,
        )
        .unwrap();
        assert_eq!(spec.fixed.len(), 1);
        assert_eq!(spec.handles[0].line, 5);
        let h = spec.handles[0].value;
        let x = h.rotation * Vect::<3>::new(1.0, 0.0, 0.0);
        assert!((x - Vect::<3>::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        assert_eq!(spec.pins.len(), 1);
        assert_eq!(spec.targets[0].weight, 1.0);
        assert!(
            spec.stiffness[0]
                .region
                .contains_point(&Vect::<3>::new(4.0, 9.0, 9.0))
        );
    }

    /// An error in a value names the value's line, not its entry's; an error of the entry as
    /// a whole names the entry's line.
    #[test]
    fn errors_name_the_line_of_the_bad_value() {
        let line_of = |text: &str| {
            let e = parse(text).unwrap_err().to_string();
            let n = e
                .split("line ")
                .nth(1)
                .expect("a line")
                .split(':')
                .next()
                .unwrap();
            (n.parse::<usize>().unwrap(), e)
        };
        let fixed = "[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n";
        let (n, e) = line_of(&format!(
            "{fixed}[[handle]]\nsphere = {{ center = [5.0, 0.0, 0.0], radius = 1.0 }}\n\
             translate = [0, 0, \"a\"]\n"
        ));
        assert_eq!(n, 5, "{e}");
        let (n, e) = line_of(&format!(
            "{fixed}[[handle]]\n# a turn\nsphere = {{ center = [5.0, 0.0, 0.0], radius = 1.0 }}\n\
             rotate = {{ axis = [1, 0, 0], degrees = 5000 }}\n"
        ));
        assert_eq!(n, 6, "{e}");
        let (n, e) =
            line_of("[[fixed]]\n\nbox = { min = [2.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n");
        assert_eq!(n, 3, "{e}");
        let (n, e) = line_of(&format!(
            "{fixed}[[handle]]\npolygon = [\n  [0.0, 0.0],\n  [1.0, 0.0],\n  [0.0, 1.0],\n]\n\
             z = [2.0, 1.0]\ntranslate = [0, 0, 1]\n"
        ));
        assert_eq!(n, 9, "{e}");
        // The next entry's keys are not this one's: a missing `to` names the pin's line.
        let (n, e) = line_of(&format!(
            "{fixed}[[pin]]\npoint = [0, 0, 0]\n[[pin]]\nto = [1, 1, 1]\n"
        ));
        assert_eq!(n, 3, "{e}");
    }

    #[test]
    fn errors_name_the_line() {
        let e = parse("[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n\n[[handle]]\nsphere = { center = [0.0, 0.0], radius = 1.0 }\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("line 5") && e.contains("3 finite numbers"),
            "{e}"
        );
        let e = parse(
            "[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nradius = 3\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("line 3") && e.contains("unknown key `radius`"),
            "{e}"
        );
        let e = parse("[[fixed]\n").unwrap_err().to_string();
        assert!(e.contains("line 1"), "{e}");
        let e = parse("[[handle]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nmatrix = [[1.0,0.0,0.0,0.0],[0.0,1.0,0.0,0.0],[0.0,0.0,1.0,0.0],[0.0,0.0,0.0,1.0]]\nscale = 2.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot be combined"), "{e}");
    }

    #[test]
    fn no_constraint_is_an_error() {
        assert!(matches!(parse(""), Err(Error::NoConstraints)));
        assert!(matches!(
            parse(
                "[[stiffness]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nscale = 2.0\n"
            ),
            Err(Error::NoConstraints)
        ));
    }

    #[test]
    fn regions_combine_invert_and_polygons_have_holes() {
        let spec = parse(
            "[[fixed]]\nclassification = [2, 6]\npolygon = [[0, 0], [10, 0], [10, 10], [0, 10]]\n\
             z = [0, 5]\n[[stiffness]]\nsphere = { center = [0, 0, 0], radius = 1 }\n\
             invert = true\nscale = 2\n",
        )
        .unwrap();
        let r = &spec.fixed[0].region;
        let p = Vect::<3>::new(5.0, 5.0, 1.0);
        assert!(r.selects(0, &p, Some(2)) && !r.selects(0, &p, Some(3)));
        assert!(!r.selects(0, &Vect::<3>::new(5.0, 5.0, 6.0), Some(2)));
        assert!(!r.selects(0, &Vect::<3>::new(11.0, 5.0, 1.0), Some(6)));
        assert!(!r.is_geometric() && r.uses_classes());
        let s = &spec.stiffness[0].region;
        assert!(s.is_geometric() && !s.contains_point(&Vect::<3>::zeros()));
        assert!(s.contains_point(&Vect::<3>::new(2.0, 0.0, 0.0)));
        // Even–odd: a ring inside another is a hole.
        let square = |a: f64, b: f64| vec![[a, a], [b, a], [b, b], [a, b]];
        let holed = Polygon::new(vec![square(0.0, 10.0), square(4.0, 6.0)], None);
        assert!(holed.contains(1.0, 1.0, None) && !holed.contains(5.0, 5.0, None));
        assert!(!holed.contains(11.0, 5.0, None));
    }

    #[test]
    fn matrix_is_split_into_rotation_and_stretch() {
        let spec = parse("[[handle]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\nmatrix = [[0.0,-2.0,0.0,1.0],[2.0,0.0,0.0,0.0],[0.0,0.0,2.0,0.0],[0.0,0.0,0.0,1.0]]\n").unwrap();
        let h = spec.handles[0].value;
        let l = h.rotation * h.stretch;
        assert!((l - Mat::<3>::new(0.0, -2.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 2.0)).norm() < 1e-12);
        assert_eq!(h.translate, Vect::<3>::new(1.0, 0.0, 0.0));
    }
}
