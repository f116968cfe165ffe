//! Polygons from GeoJSON, for a region's `polygon_file`: the rings of every Polygon and
//! MultiPolygon in a FeatureCollection, a Feature, a GeometryCollection or a bare geometry.

use std::path::Path;

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
    let bad = |message: String| Error::Spec {
        path: path.to_path_buf(),
        message,
    };
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(format!("not GeoJSON: {e}")))?;
    let mut rings = Vec::new();
    collect_rings(&json, &mut rings).map_err(bad)?;
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

/// Adds the rings of the polygons in the GeoJSON value `v` to `out`.
fn collect_rings(
    v: &serde_json::Value,
    out: &mut Vec<Vec<[f64; 2]>>,
) -> std::result::Result<(), String> {
    let ring = |r: &serde_json::Value| -> std::result::Result<Vec<[f64; 2]>, String> {
        let points = r.as_array().ok_or("a ring is not an array")?;
        let ring = points
            .iter()
            .map(|p| {
                let c = p
                    .as_array()
                    .filter(|c| c.len() >= 2)
                    .ok_or("a position is not [x, y]")?;
                match (c[0].as_f64(), c[1].as_f64()) {
                    (Some(x), Some(y)) if x.is_finite() && y.is_finite() => Ok([x, y]),
                    _ => Err("a position is not two numbers"),
                }
            })
            .collect::<std::result::Result<Vec<_>, _>>()?;
        if ring.len() < 3 {
            return Err("a ring has fewer than 3 positions".into());
        }
        Ok(ring)
    };
    match v.get("type").and_then(|t| t.as_str()) {
        Some("FeatureCollection") => {
            for f in v
                .get("features")
                .and_then(|f| f.as_array())
                .ok_or("no `features`")?
            {
                collect_rings(f, out)?;
            }
        }
        Some("Feature") => {
            if let Some(g) = v.get("geometry").filter(|g| !g.is_null()) {
                collect_rings(g, out)?;
            }
        }
        Some("GeometryCollection") => {
            for g in v
                .get("geometries")
                .and_then(|g| g.as_array())
                .ok_or("no `geometries`")?
            {
                collect_rings(g, out)?;
            }
        }
        Some("Polygon") => {
            for r in v
                .get("coordinates")
                .and_then(|c| c.as_array())
                .ok_or("no `coordinates`")?
            {
                out.push(ring(r)?);
            }
        }
        Some("MultiPolygon") => {
            for p in v
                .get("coordinates")
                .and_then(|c| c.as_array())
                .ok_or("no `coordinates`")?
            {
                for r in p.as_array().ok_or("a polygon is not an array")? {
                    out.push(ring(r)?);
                }
            }
        }
        // Points and lines select nothing.
        Some(_) => {}
        None => return Err("an object without a `type`".into()),
    }
    Ok(())
}
