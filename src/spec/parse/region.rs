//! The region of an entry: its region keys (`box`, `sphere`, `plane`, `polygon`,
//! `polygon_file`, `indices`, `classification`) read, validated and combined, with the keys
//! that qualify them (`z`, `view`, `visible`, `invert`).

use std::collections::HashSet;

use serde::Deserialize;

use super::{Ctx, REGION_KEYS};
use crate::error::{Error, Result};
use crate::rigid::Vect;
use crate::spec::geojson;
use crate::spec::region::{Polygon, Region};

#[derive(Deserialize)]
struct RawBox {
    min: Vec<f64>,
    max: Vec<f64>,
}
#[derive(Deserialize)]
struct RawSphere {
    center: Vec<f64>,
    radius: f64,
}
#[derive(Deserialize)]
struct RawPlane {
    point: Vec<f64>,
    normal: Vec<f64>,
}

impl Ctx<'_> {
    /// The region of an entry: its region keys combined (a sample must satisfy all), then
    /// `invert`ed.
    pub(super) fn region<const D: usize>(&self, t: &toml::Table, line: usize) -> Result<Region<D>> {
        let present: Vec<&str> = REGION_KEYS
            .iter()
            .copied()
            .filter(|k| t.contains_key(*k))
            .collect();
        if present.is_empty() {
            return Err(self.error(
                Some(line),
                format!(
                    "an entry needs a region ({}; several combine)",
                    REGION_KEYS.join(", ")
                ),
            ));
        }
        if present.contains(&"polygon") && present.contains(&"polygon_file") {
            return Err(self.error(
                Some(line),
                "`polygon` and `polygon_file` exclude each other".into(),
            ));
        }
        if t.contains_key("view") && !present.contains(&"polygon") {
            return Err(self.error(
                self.at(line, "view"),
                "`view` (a screen's world-to-clip matrix) goes with a `polygon`".into(),
            ));
        }
        if t.contains_key("visible") && !t.contains_key("view") {
            return Err(self.error(
                Some(line),
                "`visible` (only what a screen's camera sees) goes with a `view`".into(),
            ));
        }
        if t.contains_key("z") && !present.iter().any(|k| k.starts_with("polygon")) {
            return Err(self.error(
                self.at(line, "z"),
                "`z` (a height range) goes with a `polygon` or `polygon_file`".into(),
            ));
        }
        let mut parts = present
            .iter()
            .map(|k| self.region_part::<D>(t, k, line))
            .collect::<Result<Vec<_>>>()?;
        let region = match parts.len() {
            1 => parts.pop().unwrap(),
            _ => Region::All(parts),
        };
        let invert = match t.get("invert") {
            Some(_) => self.field::<bool>(t, "invert", line)?,
            None => false,
        };
        if invert && region.visible_from().is_some() {
            return Err(self.error(
                Some(line),
                "`visible = true` and `invert = true` exclude each other".into(),
            ));
        }
        Ok(if invert {
            Region::Not(Box::new(region))
        } else {
            region
        })
    }

    fn region_part<const D: usize>(
        &self,
        t: &toml::Table,
        key: &str,
        line: usize,
    ) -> Result<Region<D>> {
        Ok(match key {
            "box" => {
                let b: RawBox = self.field(t, key, line)?;
                let (min, max) = (
                    self.to_vect(&b.min, "box.min", line)?,
                    self.to_vect(&b.max, "box.max", line)?,
                );
                if (0..D).any(|a| min[a] > max[a]) {
                    return Err(self.error(self.at(line, "box"), "box.min exceeds box.max".into()));
                }
                Region::Box { min, max }
            }
            "sphere" => {
                let s: RawSphere = self.field(t, key, line)?;
                if !(s.radius.is_finite() && s.radius >= 0.0) {
                    return Err(
                        self.error(self.at(line, "sphere"), "sphere.radius must be ≥ 0".into())
                    );
                }
                Region::Sphere {
                    center: self.to_vect(&s.center, "sphere.center", line)?,
                    radius: s.radius,
                }
            }
            "plane" => {
                let p: RawPlane = self.field(t, key, line)?;
                let normal: Vect<D> = self.to_vect(&p.normal, "plane.normal", line)?;
                if normal.norm() == 0.0 {
                    return Err(self.error(self.at(line, "plane"), "plane.normal is zero".into()));
                }
                Region::Plane {
                    point: self.to_vect(&p.point, "plane.point", line)?,
                    normal,
                }
            }
            // A list of indices, or the file that holds them.
            "indices" => {
                let samples = match t.get(key) {
                    Some(toml::Value::Array(list)) => list
                        .iter()
                        .enumerate()
                        .map(|(k, v)| {
                            match v {
                                toml::Value::Integer(i) => u64::try_from(*i).ok(),
                                _ => None,
                            }
                            .ok_or_else(|| {
                                self.error(
                                    self.at_element(line, key, &[k]),
                                    format!(
                                        "`indices` lists {v}: a sample index is a whole number, 0 \
                                     or more"
                                    ),
                                )
                            })
                        })
                        .collect::<Result<_>>()?,
                    _ => {
                        let file: String = self.field(t, key, line)?;
                        self.read_indices(&file, line)?
                    }
                };
                Region::Indices {
                    samples,
                    line: self.at(line, key).unwrap_or(line),
                }
            }
            "polygon" | "polygon_file" => {
                let (rings, file) = if key == "polygon" {
                    let ring = self.rows(t, key, "point", line)?;
                    (vec![self.ring(&ring, "polygon", line)?], None)
                } else {
                    let file: String = self.field(t, key, line)?;
                    let path = self.resolve(&file);
                    let (rings, crs) = geojson::read_rings(&path)?;
                    (rings, Some((path, crs)))
                };
                if t.contains_key("view") {
                    return self.screen::<D>(t, rings, line);
                }
                let z = match t.get("z") {
                    Some(_) if D == 2 => {
                        return Err(self.error(self.at(line, "z"), "`z` is for 3D inputs".into()));
                    }
                    Some(_) => {
                        let z: Vec<f64> = self.field(t, "z", line)?;
                        match z[..] {
                            [a, b] if a <= b => Some([a, b]),
                            _ => {
                                return Err(self.error(
                                    self.at(line, "z"),
                                    format!("`z` must be [lowest, highest], got {z:?}"),
                                ));
                            }
                        }
                    }
                    None => None,
                };
                let polygon = Polygon::new(rings, z);
                Region::Polygon(match file {
                    Some((path, crs)) => polygon.from_file(path, crs),
                    None => polygon,
                })
            }
            _ => Region::Classification(self.classes(t, key, line)?.into_iter().collect()),
        })
    }

    /// A `polygon` on the screen of `view`.
    fn screen<const D: usize>(
        &self,
        t: &toml::Table,
        rings: Vec<Vec<[f64; 2]>>,
        line: usize,
    ) -> Result<Region<D>> {
        if D != 3 || t.contains_key("z") {
            return Err(self.error(
                self.at(line, "view"),
                "`view` is for 3D inputs, without `z`".into(),
            ));
        }
        let rows = self.square(t, "view", 4, line)?;
        let mut view = [[0.0; 4]; 4];
        for (out, row) in view.iter_mut().zip(&rows) {
            out.copy_from_slice(row);
        }
        let visible = match t.get("visible") {
            Some(_) => self.field::<bool>(t, "visible", line)?,
            None => false,
        };
        if visible && view[2][..3].iter().all(|&v| v == 0.0) {
            return Err(self.error(
                Some(line),
                "`visible` needs the view's depth: its third row is zero".into(),
            ));
        }
        Ok(Region::Screen {
            view,
            polygon: Polygon::new(rings, None),
            visible,
        })
    }

    /// A ring of `[x, y]` vertices ([`Ctx::rows`]: finite): at least 3. A point of another
    /// length is named by its line.
    fn ring(&self, v: &[Vec<f64>], key: &str, line: usize) -> Result<Vec<[f64; 2]>> {
        if let Some(i) = v.iter().position(|p| p.len() != 2) {
            return Err(self.error(
                self.at_element(line, key, &[i]),
                format!(
                    "`{key}` point {} is {}: a point is [x, y], two finite numbers",
                    i + 1,
                    crate::human::list(&v[i])
                ),
            ));
        }
        if v.len() < 3 {
            return Err(self.error(
                self.at(line, key),
                format!("`{key}` must be at least 3 points [x, y] of finite numbers"),
            ));
        }
        Ok(v.iter().map(|p| [p[0], p[1]]).collect())
    }

    /// The LAS classes of `classification`: whole numbers 0 to 255, an error naming the line
    /// of the one at fault.
    fn classes(&self, t: &toml::Table, key: &str, line: usize) -> Result<Vec<u8>> {
        let Some(toml::Value::Array(list)) = t.get(key) else {
            return self.field(t, key, line);
        };
        list.iter()
            .enumerate()
            .map(|(k, v)| {
                v.as_integer()
                    .and_then(|c| u8::try_from(c).ok())
                    .ok_or_else(|| {
                        self.error(
                            self.at_element(line, key, &[k]),
                            format!("`{key}` lists {v}: a LAS class is a whole number 0 to 255"),
                        )
                    })
            })
            .collect()
    }

    /// The sample indices in `file`: whitespace or comma separated, 0-based.
    fn read_indices(&self, file: &str, line: usize) -> Result<HashSet<u64>> {
        let path = self.resolve(file);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::spec_file(&path, e))?;
        text.split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<u64>().map_err(|_| {
                    self.error(
                        self.at(line, "indices"),
                        format!("{}: `{s}` is not a sample index", path.display()),
                    )
                })
            })
            .collect()
    }
}
