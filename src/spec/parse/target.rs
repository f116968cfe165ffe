//! A `[[target]]` entry: one soft target (`from`, `to`), or the control points of a `file`,
//! with the entry's `weight`, `snap` and `exact`.

use super::{Ctx, file_name};
use crate::error::{Error, Result};
use crate::spec::control_points::read_control_points;
use crate::spec::entries::Target;

impl Ctx<'_> {
    /// The soft targets of the `[[target]]` entry on line `line`: one `from`/`to` pair, or the
    /// rows of a control-point `file`; `first` targets came before it.
    pub(super) fn targets<const D: usize>(
        &self,
        t: &toml::Table,
        line: usize,
        first: usize,
    ) -> Result<Vec<Target<D>>> {
        let weight: f64 = match t.get("weight") {
            Some(_) => self.field(t, "weight", line)?,
            None => 1.0,
        };
        if !(weight.is_finite() && weight > 0.0) {
            return Err(self.error(
                self.at(line, "weight"),
                format!("weight {weight} must be positive"),
            ));
        }
        let snap = match t.get("snap") {
            Some(_) => {
                let d: f64 = self.field(t, "snap", line)?;
                if !(d.is_finite() && d > 0.0) {
                    return Err(self.error(
                        self.at(line, "snap"),
                        format!("snap {d} must be a positive distance"),
                    ));
                }
                Some(d)
            }
            None => None,
        };
        let exact: bool = match t.get("exact") {
            Some(_) => self.field(t, "exact", line)?,
            None => false,
        };
        if let Some(file) = t.get("file") {
            if t.contains_key("from") || t.contains_key("to") {
                return Err(self.error(
                    Some(line),
                    "`file` and `from`/`to` exclude each other".into(),
                ));
            }
            let file: String = file
                .clone()
                .try_into()
                .map_err(|e| self.error(self.at(line, "file"), format!("`file`: {e}")))?;
            let path = self.resolve(&file);
            let text = std::fs::read_to_string(&path).map_err(|e| Error::spec_file(&path, e))?;
            let rows = read_control_points::<D>(&text, &path)?;
            let mut out = Vec::with_capacity(rows.len());
            for (k, row) in rows.into_iter().enumerate() {
                let place = format!("{file} line {}", row.line);
                let key = |what: &str| format!("{place}: {what}");
                self.within_range(row.from.amax(), &key("from"), line)?;
                self.within_range(row.to.amax(), &key("to"), line)?;
                out.push(Target {
                    from: row.from,
                    to: row.to,
                    weight: row.weight.unwrap_or(weight),
                    line,
                    id: row.id.unwrap_or_else(|| format!("#{}", first + k + 1)),
                    place,
                    horizontal: row.horizontal,
                    snap,
                    check: row.check,
                    exact,
                });
            }
            return Ok(out);
        }
        Ok(vec![Target {
            from: self.motion_vector(t, "from", line)?,
            to: self.motion_vector(t, "to", line)?,
            weight,
            line,
            id: format!("#{}", first + 1),
            place: format!("{} line {line}", file_name(self.name)),
            horizontal: false,
            snap,
            check: false,
            exact,
        }])
    }
}
