//! Control-point files (`[[target]] file = …`): CSV, TSV or whitespace-separated rows of a
//! point and where it goes, as surveyors and GIS tools write them: with or without an ID, a
//! weight, a header naming the columns, decimal commas; 2D points leave the height free.

use std::path::Path;

use crate::error::{Error, Result};
use crate::rigid::Vect;

/// One row of a control-point file.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlRow<const D: usize> {
    /// The ID column, if the file has one.
    pub id: Option<String>,
    /// The point (for a horizontal point, its height is 0 until snapped).
    pub from: Vect<D>,
    /// Where it goes (for a horizontal point, its height is 0).
    pub to: Vect<D>,
    /// The weight column, if the file has one.
    pub weight: Option<f64>,
    /// Whether the file gives x and y only.
    pub horizontal: bool,
    /// A checkpoint (the `check` or `type` column): scored, not solved for.
    pub check: bool,
    /// The line in the file (1-based).
    pub line: usize,
}

/// What a column of a control-point file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Column {
    Id,
    From(usize),
    To(usize),
    Weight,
    /// `check` (yes/no) or `type` (check/control): whether the row is a checkpoint.
    Check,
}

/// Whether a `check` or `type` field marks a checkpoint (`None`: neither).
fn checkpoint(field: &str) -> Option<bool> {
    match field.trim().to_ascii_lowercase().as_str() {
        "1" | "yes" | "y" | "true" | "x" | "check" | "checkpoint" | "cp" | "chk" => Some(true),
        "" | "0" | "no" | "n" | "false" | "control" | "gcp" | "gcps" => Some(false),
        _ => None,
    }
}

/// Reads a control-point file (`[[target]] file = …`), naming `path` in errors with the line
/// and column.
///
/// - Separators: `,`, `;`, tab or spaces, the first that the first data row holds, in that
///   order. With `;`, tab or spaces, a decimal comma (`12,5`) reads as `12.5`. Fields may be
///   quoted (`"P1"`); `#` starts a comment line; blank lines are skipped.
/// - Columns by count, without a header (3D): `x,y,z,X,Y,Z` (6), `id,x,y,z,X,Y,Z` (7),
///   `id,x,y,z,X,Y,Z,weight` (8); 2D control points, whose height is free: `x,y,X,Y` (4),
///   `id,x,y,X,Y` (5). A first field that is not a number is an ID whatever the count. In a
///   2D (image) spec: `x,y,X,Y`, `id,x,y,X,Y`, `id,x,y,X,Y,weight`.
/// - A header row (a first data row that is not numbers) names the columns, in any order:
///   `id` (or `name`, `point`, `label`), `x y z` (or `from_x …`) for the point, `X Y Z` (or
///   `to_x …`, `x2 …`) for where it goes, `weight` (or `w`). Unknown names are errors.
pub fn read_control_points<const D: usize>(text: &str, path: &Path) -> Result<Vec<ControlRow<D>>> {
    let fail = |line: usize, column: Option<usize>, message: String| Error::Spec {
        path: path.to_path_buf(),
        line: Some(line),
        column,
        message: message.into(),
        excerpt: None,
    };
    let mut rows = text
        .lines()
        .enumerate()
        .map(|(k, l)| (k + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((first_line, first)) = rows.next() else {
        return Ok(Vec::new());
    };
    let sep = [';', ',', '\t']
        .into_iter()
        .find(|c| first.contains(*c))
        .unwrap_or(' ');
    let split = |row: &str| -> Vec<String> {
        let fields: Vec<&str> = if sep == ' ' {
            row.split_whitespace().collect()
        } else {
            row.split(sep).collect()
        };
        fields
            .iter()
            .map(|f| f.trim().trim_matches('"').trim().to_string())
            .collect()
    };
    let number = |f: &str| -> Option<f64> {
        let v = match f.parse::<f64>() {
            Ok(v) => Some(v),
            Err(_) if sep != ',' && f.contains(',') && !f.contains('.') => {
                f.replace(',', ".").parse::<f64>().ok()
            }
            Err(_) => None,
        };
        v.filter(|v| v.is_finite())
    };
    let head = split(first);
    let all_numbers = head.iter().skip(1).all(|f| number(f).is_some());
    let (layout, mut pending) = if all_numbers {
        let id = number(&head[0]).is_none();
        (
            by_count::<D>(head.len(), id).ok_or_else(|| {
                fail(
                    first_line,
                    None,
                    format!(
                        "{} columns; expected {} (see the README's control points)",
                        head.len(),
                        expected_counts::<D>()
                    ),
                )
            })?,
            Some((first_line, first)),
        )
    } else {
        (
            by_header::<D>(&head).map_err(|(c, m)| fail(first_line, Some(c), m))?,
            None,
        )
    };
    let horizontal = D == 3 && !layout.contains(&Column::From(2));
    let mut out = Vec::new();
    let mut next = || pending.take().or_else(|| rows.next());
    while let Some((line, row)) = next() {
        let fields = split(row);
        if fields.len() != layout.len() {
            return Err(fail(
                line,
                None,
                format!(
                    "{} columns, the file's rows have {}",
                    fields.len(),
                    layout.len()
                ),
            ));
        }
        let mut r = ControlRow {
            id: None,
            from: Vect::<D>::zeros(),
            to: Vect::<D>::zeros(),
            weight: None,
            horizontal,
            check: false,
            line,
        };
        for (c, (field, col)) in fields.iter().zip(&layout).enumerate() {
            if *col == Column::Id {
                r.id = Some(field.clone());
                continue;
            }
            if *col == Column::Check {
                r.check = checkpoint(field).ok_or_else(|| {
                    fail(
                        line,
                        Some(c + 1),
                        format!("`{field}` is neither a checkpoint (check, yes, 1) nor a control point (control, no, 0)"),
                    )
                })?;
                continue;
            }
            let v = number(field).ok_or_else(|| {
                fail(
                    line,
                    Some(c + 1),
                    format!("`{field}` is not a finite number"),
                )
            })?;
            match *col {
                Column::From(a) => r.from[a] = v,
                Column::To(a) => r.to[a] = v,
                Column::Weight if v > 0.0 => r.weight = Some(v),
                Column::Weight => {
                    return Err(fail(
                        line,
                        Some(c + 1),
                        format!("weight {v} must be positive"),
                    ));
                }
                Column::Id | Column::Check => {}
            }
        }
        out.push(r);
    }
    Ok(out)
}

fn expected_counts<const D: usize>() -> &'static str {
    if D == 3 {
        "6 (x,y,z,X,Y,Z), 7 (id,x,y,z,X,Y,Z), 8 (id,…,weight), 4 (x,y,X,Y) or 5 (id,x,y,X,Y)"
    } else {
        "4 (x,y,X,Y), 5 (id,x,y,X,Y) or 6 (id,x,y,X,Y,weight)"
    }
}

/// The columns of a file without a header, from their count and whether the first field is
/// an ID that is not a number.
fn by_count<const D: usize>(count: usize, text_id: bool) -> Option<Vec<Column>> {
    let points = |dims: usize, id: bool, weight: bool| {
        let mut c = Vec::new();
        if id {
            c.push(Column::Id);
        }
        c.extend((0..dims).map(Column::From));
        c.extend((0..dims).map(Column::To));
        if weight {
            c.push(Column::Weight);
        }
        c
    };
    let layout = match (D, count) {
        (3, 6) if !text_id => points(3, false, false),
        (3, 7) => points(3, true, false),
        (3, 8) => points(3, true, true),
        (3, 4) if !text_id => points(2, false, false),
        (3, 5) => points(2, true, false),
        (2, 4) if !text_id => points(2, false, false),
        (2, 5) => points(2, true, false),
        (2, 6) => points(2, true, true),
        _ => return None,
    };
    Some(layout)
}

/// The columns of a file from its header row; an error gives the column (1-based).
fn by_header<const D: usize>(
    names: &[String],
) -> std::result::Result<Vec<Column>, (usize, String)> {
    const AXES: [&str; 3] = ["x", "y", "z"];
    let mut layout = Vec::new();
    for (c, name) in names.iter().enumerate() {
        let lower = name.to_ascii_lowercase();
        let axis = |n: &str| AXES[..D].iter().position(|a| *a == n);
        let col = match name.as_str() {
            "X" | "Y" | "Z" => axis(&lower).map(Column::To),
            "x" | "y" | "z" => axis(name).map(Column::From),
            _ => match lower.as_str() {
                "id" | "name" | "point" | "label" | "gcp" => Some(Column::Id),
                "weight" | "w" => Some(Column::Weight),
                "check" | "type" | "use" => Some(Column::Check),
                _ => {
                    // The last character is the axis (a header is the user's text: the split
                    // falls on a character boundary, whatever the name holds).
                    let last = lower.char_indices().last().map_or(0, |(i, _)| i);
                    let (prefix, a) = lower.split_at(last);
                    match prefix {
                        "from_" | "from" | "src_" => axis(a).map(Column::From),
                        "to_" | "to" | "dst_" => axis(a).map(Column::To),
                        _ => match lower.strip_suffix('2') {
                            Some(a) => axis(a).map(Column::To),
                            None => None,
                        },
                    }
                }
            },
        };
        let col = col.ok_or_else(|| {
            (
                c + 1,
                format!(
                    "unknown column `{name}` (expected id, x, y{z}, X, Y{Z}, weight, check)",
                    z = if D == 3 { ", z" } else { "" },
                    Z = if D == 3 { ", Z" } else { "" },
                ),
            )
        })?;
        if layout.contains(&col) {
            return Err((c + 1, format!("column `{name}` appears twice")));
        }
        layout.push(col);
    }
    let has = |c: Column| layout.contains(&c);
    let dims = if D == 3 && !has(Column::From(2)) && !has(Column::To(2)) {
        2
    } else {
        D
    };
    if let Some(a) = (0..dims).find(|&a| !has(Column::From(a)) || !has(Column::To(a))) {
        return Err((
            1,
            format!(
                "the header names no column for {} or {}",
                AXES[a],
                AXES[a].to_ascii_uppercase()
            ),
        ));
    }
    Ok(layout)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rigid::Vect;

    #[test]
    fn control_point_files_by_count_and_by_header() {
        let read = |text: &str| read_control_points::<3>(text, Path::new("gcp.csv"));
        // By count: 6, 7 (an ID), 8 (an ID and a weight), 4 and 5 (2D).
        let r = read("1 2 3 4 5 6\n").unwrap();
        assert_eq!(
            (r[0].id.clone(), r[0].to[2], r[0].horizontal),
            (None, 6.0, false)
        );
        let r = read("7;1;2;3;4;5;6\n").unwrap();
        assert_eq!((r[0].id.as_deref(), r[0].from[0]), (Some("7"), 1.0));
        let r = read("A,1,2,3,4,5,6,2.5\n").unwrap();
        assert_eq!(r[0].weight, Some(2.5));
        let r = read("1\t2\t3\t4\n").unwrap();
        assert!(r[0].horizontal && r[0].to[1] == 4.0);
        let r = read("P9 1 2 3 4\n").unwrap();
        assert!(r[0].horizontal && r[0].id.as_deref() == Some("P9"));
        // A text ID needs its column: 6 fields with a name first is not 3D without one.
        assert!(read("P1,1,2,3,4,5\n").is_err());
        // By header, in any order; decimal commas with `;`.
        let r = read("# c\n\nZ;Y;X;z;y;x;name\n6;5;4;3;2;1,5;Q\n").unwrap();
        assert_eq!(r[0].from, Vect::<3>::new(1.5, 2.0, 3.0));
        assert_eq!(r[0].to, Vect::<3>::new(4.0, 5.0, 6.0));
        assert_eq!((r[0].id.as_deref(), r[0].line), (Some("Q"), 4));
        let r = read("point,from_x,from_y,to_x,to_y,w\nA,1,2,3,4,0.5\n").unwrap();
        assert!(r[0].horizontal && r[0].weight == Some(0.5));
        let e = read("id,x,y,X\n").unwrap_err().to_string();
        assert!(e.contains("no column for y or Y"), "{e}");
        let e = read("id,x,x,y,X,Y\n").unwrap_err().to_string();
        assert!(e.contains("column 3") && e.contains("twice"), "{e}");
        let e = read("1,2,3,4,5,6\n1,2,3,4,5,-6,7\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("7 columns"), "{e}");
        assert!(read("# nothing\n").unwrap().is_empty());
        // A name ending in a character of several bytes is an unknown column.
        let e = read("id,x,y,X,Yé\nA,1,2,3,4\n").unwrap_err().to_string();
        assert!(e.contains("unknown column `Yé`"), "{e}");
    }
}
