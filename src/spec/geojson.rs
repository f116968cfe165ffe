//! Polygons from GeoJSON, for a region's `polygon_file`: the rings of every Polygon and
//! MultiPolygon in a FeatureCollection, a Feature, a GeometryCollection or a bare geometry.
//!
//! An error names the element at fault as a person finds it in the file: the feature (counted
//! from 1, with its `name` property or its `id` when it has one), the geometry of a collection,
//! the polygon of a MultiPolygon, the ring and the point (`feature 3 ("parcel 12"), ring 1,
//! point 5: …`), and the line where that element starts. `serde_json`'s values keep no
//! positions, so the line is found only on the way to an error, by reading the file again
//! along the element's path with [`RawValue`]s, which are slices of the text.

use std::collections::HashMap;
use std::path::Path;

use serde_json::value::RawValue;

use crate::crs::Crs;
use crate::error::{Error, Result};

/// Rings of `[x, y]` positions.
type Rings = Vec<Vec<[f64; 2]>>;

/// The rings of every polygon in the GeoJSON file `path` (a FeatureCollection, a Feature or a
/// bare geometry; Polygon and MultiPolygon, holes included; heights ignored), with the system
/// its top-level `crs` member names (the GeoJSON 2008 form, [`Crs::of_geojson`]). The
/// coordinates must be those of the input: a `crs` is checked against the scan's where the
/// spec meets it; without one, the coordinates are taken in the scan's system (RFC 7946 says
/// longitude and latitude on WGS 84, but a polygon exported for a scan is in the scan's).
pub(super) fn read_rings(path: &Path) -> Result<(Rings, Option<Crs>)> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::spec_file(path, e))?;
    let bad = |message: String| Error::spec(path, None, message);
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(format!("not GeoJSON: {e}")))?;
    let mut rings = Vec::new();
    let mut at = Place::default();
    collect_rings(&json, &mut rings, &mut at).map_err(|e| bad(e.message(&text)))?;
    if rings.is_empty() {
        return Err(bad("holds no Polygon or MultiPolygon".into()));
    }
    let crs = json
        .get("crs")
        .filter(|c| !c.is_null())
        .map(Crs::of_geojson)
        .transpose()
        .map_err(bad)?;
    Ok((rings, crs))
}

/// One step into a JSON value: a member of an object, an element of an array.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Step {
    Key(&'static str),
    Index(usize),
}

/// Where the walk is: the JSON path from the root, and the names a person reads it by.
#[derive(Debug, Clone, Default)]
struct Place {
    path: Vec<Step>,
    names: Vec<String>,
}

impl Place {
    /// `f` one step further (`steps` into the value, named `name` when it has one).
    fn within<T>(
        &mut self,
        steps: &[Step],
        name: Option<String>,
        f: impl FnOnce(&mut Self) -> std::result::Result<T, Fault>,
    ) -> std::result::Result<T, Fault> {
        let (depth, named) = (self.path.len(), self.names.len());
        self.path.extend_from_slice(steps);
        self.names.extend(name);
        let result = f(self);
        self.path.truncate(depth);
        self.names.truncate(named);
        result
    }

    /// A fault here: `what` is wrong.
    fn fault(&self, what: impl Into<String>) -> Fault {
        Fault {
            place: self.clone(),
            what: what.into(),
        }
    }
}

/// What is wrong in the file, and where.
#[derive(Debug)]
struct Fault {
    place: Place,
    what: String,
}

impl Fault {
    /// The message: the line of the element at fault in `text` (where it can be found), the
    /// element by its names, and what is wrong.
    fn message(&self, text: &str) -> String {
        let mut out = String::new();
        if let Some(at) = offset(text, &self.place.path) {
            let line = text[..at].matches('\n').count() + 1;
            out += &format!("line {line}: ");
        }
        if !self.place.names.is_empty() {
            out += &self.place.names.join(", ");
            out += ": ";
        }
        out + &self.what
    }
}

/// The byte offset in `text` of the value at `path`, read again with [`RawValue`]s (each a
/// slice of `text`).
fn offset(text: &str, path: &[Step]) -> Option<usize> {
    let mut raw: &RawValue = serde_json::from_str(text).ok()?;
    for step in path {
        raw = match step {
            Step::Key(key) => {
                let object: HashMap<String, &RawValue> = serde_json::from_str(raw.get()).ok()?;
                object.get(*key).copied()?
            }
            Step::Index(i) => {
                let array: Vec<&RawValue> = serde_json::from_str(raw.get()).ok()?;
                array.get(*i).copied()?
            }
        };
    }
    (raw.get().as_ptr() as usize).checked_sub(text.as_ptr() as usize)
}

/// A feature's name for messages: its `name` property, else its `id` (`"parcel 12"`, `id 7`).
fn feature_name(feature: &serde_json::Value) -> Option<String> {
    let name = feature.get("properties").and_then(|p| p.get("name"));
    match (name.and_then(|n| n.as_str()), feature.get("id")) {
        (Some(name), _) => Some(format!("{name:?}")),
        (None, Some(serde_json::Value::String(id))) => Some(format!("{id:?}")),
        (None, Some(id @ serde_json::Value::Number(_))) => Some(format!("id {id}")),
        _ => None,
    }
}

/// The array of `v`'s member `key`, walked one element at a time, each `named` (from its
/// index) and given to `f`; a missing member is `missing`.
fn each(
    v: &serde_json::Value,
    key: &'static str,
    at: &mut Place,
    missing: &str,
    named: impl Fn(usize, &serde_json::Value) -> String,
    mut f: impl FnMut(&serde_json::Value, &mut Place) -> std::result::Result<(), Fault>,
) -> std::result::Result<(), Fault> {
    let list = v
        .get(key)
        .and_then(|l| l.as_array())
        .ok_or_else(|| at.fault(missing))?;
    for (i, item) in list.iter().enumerate() {
        at.within(
            &[Step::Key(key), Step::Index(i)],
            Some(named(i, item)),
            |at| f(item, at),
        )?;
    }
    Ok(())
}

/// The ring at `at` (`r`): 3 positions or more, each `[x, y]` of finite numbers (more
/// coordinates are heights, ignored).
fn ring(r: &serde_json::Value, at: &mut Place) -> std::result::Result<Vec<[f64; 2]>, Fault> {
    let points = r
        .as_array()
        .ok_or_else(|| at.fault(format!("a ring is an array of positions, not {r}")))?;
    let ring = points
        .iter()
        .enumerate()
        .map(|(k, p)| {
            at.within(&[Step::Index(k)], Some(format!("point {}", k + 1)), |at| {
                let c = p
                    .as_array()
                    .filter(|c| c.len() >= 2)
                    .ok_or_else(|| at.fault(format!("a position is [x, y], not {p}")))?;
                match (c[0].as_f64(), c[1].as_f64()) {
                    (Some(x), Some(y)) if x.is_finite() && y.is_finite() => Ok([x, y]),
                    _ => Err(at.fault(format!("a position is two numbers, not {p}"))),
                }
            })
        })
        .collect::<std::result::Result<Vec<_>, _>>()?;
    if ring.len() < 3 {
        return Err(at.fault(format!(
            "a ring has 3 positions or more, this one {}",
            ring.len()
        )));
    }
    Ok(ring)
}

/// Adds the rings of the polygons in the GeoJSON value `v`, at `at`, to `out`.
fn collect_rings(
    v: &serde_json::Value,
    out: &mut Vec<Vec<[f64; 2]>>,
    at: &mut Place,
) -> std::result::Result<(), Fault> {
    let rings = |polygon: &serde_json::Value,
                 at: &mut Place,
                 out: &mut Vec<Vec<[f64; 2]>>|
     -> std::result::Result<(), Fault> {
        let list = polygon
            .as_array()
            .ok_or_else(|| at.fault(format!("a polygon is an array of rings, not {polygon}")))?;
        for (r, one) in list.iter().enumerate() {
            let name = Some(format!("ring {}", r + 1));
            out.push(at.within(&[Step::Index(r)], name, |at| ring(one, at))?);
        }
        Ok(())
    };
    match v.get("type").and_then(|t| t.as_str()) {
        Some("FeatureCollection") => each(
            v,
            "features",
            at,
            "no `features`",
            |i, f| match feature_name(f) {
                Some(name) => format!("feature {} ({name})", i + 1),
                None => format!("feature {}", i + 1),
            },
            |f, at| collect_rings(f, out, at),
        )?,
        Some("Feature") => {
            if let Some(g) = v.get("geometry").filter(|g| !g.is_null()) {
                at.within(&[Step::Key("geometry")], None, |at| {
                    collect_rings(g, out, at)
                })?;
            }
        }
        Some("GeometryCollection") => each(
            v,
            "geometries",
            at,
            "no `geometries`",
            |i, _| format!("geometry {}", i + 1),
            |g, at| collect_rings(g, out, at),
        )?,
        Some("Polygon") => {
            let c = v
                .get("coordinates")
                .ok_or_else(|| at.fault("no `coordinates`"))?;
            at.within(&[Step::Key("coordinates")], None, |at| rings(c, at, out))?;
        }
        Some("MultiPolygon") => each(
            v,
            "coordinates",
            at,
            "no `coordinates`",
            |p, _| format!("polygon {}", p + 1),
            |p, at| rings(p, at, out),
        )?,
        // Points and lines select nothing.
        Some(_) => {}
        None => return Err(at.fault("an object without a `type`")),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each fault names its feature, ring and point and the line where the element starts.
    #[test]
    fn faults_name_the_element_and_its_line() {
        let message = |text: &str| {
            let json: serde_json::Value = serde_json::from_str(text).unwrap();
            let mut at = Place::default();
            let e = collect_rings(&json, &mut Vec::new(), &mut at).unwrap_err();
            e.message(text)
        };
        let square = "[[0, 0], [1, 0], [1, 1], [0, 0]]";
        let text = format!(
            "{{\"type\": \"FeatureCollection\", \"features\": [\n\
             {{\"type\": \"Feature\", \"geometry\": {{\"type\": \"Polygon\", \"coordinates\": [{square}]}}}},\n\
             {{\"type\": \"Feature\", \"id\": 7, \"properties\": {{\"name\": \"parcel 12\"}},\n\
             \"geometry\": {{\"type\": \"Polygon\", \"coordinates\": [\n{square},\n[[0, 0],\n[1, 0],\n\
             [1, \"a\"],\n[0, 0]]]}}}}]}}"
        );
        assert_eq!(
            message(&text),
            "line 8: feature 2 (\"parcel 12\"), ring 2, point 3: a position is two numbers, \
             not [1,\"a\"]"
        );
        let text = format!(
            "{{\"type\": \"MultiPolygon\", \"coordinates\": [[{square}], [{square},\n[[0, 0], [1, 0]]]]}}"
        );
        assert_eq!(
            message(&text),
            "line 2: polygon 2, ring 2: a ring has 3 positions or more, this one 2"
        );
        let text = "{\"type\": \"Feature\", \"id\": 3, \"geometry\": {\"type\": \"Polygon\"}}";
        let json: serde_json::Value = serde_json::from_str(text).unwrap();
        let e = collect_rings(&json, &mut Vec::new(), &mut Place::default()).unwrap_err();
        assert_eq!(e.message(text), "line 1: no `coordinates`");
        let fc = r#"{"type": "FeatureCollection", "features": [{"type": "Feature", "id": 3,
            "geometry": {"type": "MultiPolygon", "coordinates": [[[[0, 0], [1, 0], [1, null]]]]}}]}"#;
        assert_eq!(
            message(fc),
            "line 2: feature 1 (id 3), polygon 1, ring 1, point 3: a position is two numbers, \
             not [1,null]"
        );
    }
}
