//! Where the spec meets the scan it edits: a GeoJSON polygon's `crs` against the scan's
//! coordinate system, and polygons against the scan's bounds. The spec is read on its own
//! (before, or without, the input); these checks run when the pipeline opens the input, before
//! any pass over its samples.

use std::path::Path;

use super::entries::EditSpec;
use super::region::{Polygon, Region};
use crate::crs::Crs;
use crate::error::{Error, Result};

impl<const D: usize> EditSpec<D> {
    /// The polygons of the spec's regions (alone or among an entry's parts; not inverted ones,
    /// which select the rest), each with the line of its entry.
    fn polygons(&self) -> Vec<(&Polygon, usize)> {
        fn walk<'a, const D: usize>(
            r: &'a Region<D>,
            line: usize,
            out: &mut Vec<(&'a Polygon, usize)>,
        ) {
            match r {
                Region::Polygon(p) => out.push((p, line)),
                Region::All(parts) => parts.iter().for_each(|p| walk(p, line, out)),
                _ => {}
            }
        }
        let mut out = Vec::new();
        let regions = self
            .fixed
            .iter()
            .map(|e| (&e.region, e.line))
            .chain(self.handles.iter().map(|e| (&e.region, e.line)))
            .chain(self.stiffness.iter().map(|e| (&e.region, e.line)));
        for (r, line) in regions {
            walk(r, line, &mut out);
        }
        out
    }

    /// Checks each GeoJSON polygon's `crs` against `scan`, the system of the input `input`:
    /// refused ([`Error::CrsMismatch`], naming the GeoJSON file and both systems) when the
    /// codes differ; a warning when the scan declares no system, or one without an EPSG code,
    /// which a code cannot be compared with here. A GeoJSON without `crs` is in the scan's
    /// coordinates.
    pub fn check_geojson_crs(&self, scan: Option<&Crs>, input: &Path) -> Result<Vec<String>> {
        let mut warnings = Vec::new();
        for (polygon, _) in self.polygons() {
            let (Some(file), Some(declared)) = (&polygon.file, &polygon.crs) else {
                continue;
            };
            let warning = match scan {
                None => format!(
                    "{} declares no coordinate system and {} names {}; the polygon is taken in \
                     the scan's coordinates",
                    input.display(),
                    file.display(),
                    declared.label()
                ),
                Some(s) if s.epsg.is_none() => format!(
                    "{} names {}, and the system of {}, {}, has no EPSG code to compare it \
                     with; the polygon is taken in the scan's coordinates",
                    file.display(),
                    declared.label(),
                    input.display(),
                    s.label()
                ),
                Some(s) if s.epsg == declared.epsg => continue,
                Some(s) => {
                    return Err(Error::CrsMismatch {
                        what: "the polygon's coordinate system differs from the scan's".into(),
                        first: format!("{} in {}", declared.label(), file.display()),
                        second: format!("{} in {}", s.label(), input.display()),
                        advice: "give the polygon in the scan's system (or, if its coordinates \
                                 are the scan's, remove the GeoJSON's `crs`)"
                            .into(),
                    });
                }
            };
            if !warnings.contains(&warning) {
                warnings.push(warning);
            }
        }
        Ok(warnings)
    }

    /// Refuses a polygon that lies entirely outside the scan's bounds in x, y (`lo`, `hi`; of
    /// the input `input`, whose system is `scan`): it selects nothing, and is a mistake (a
    /// polygon of another area, or in another system). The message gives both extents as a user
    /// would write them and, when the polygon's coordinates look like longitude and latitude
    /// on a scan that is not geographic, says so.
    pub fn check_polygons(
        &self,
        (lo, hi): ([f64; 2], [f64; 2]),
        scan: Option<&Crs>,
        input: &Path,
    ) -> Result<()> {
        for (polygon, line) in self.polygons() {
            let (plo, phi) = polygon.extent();
            if (0..2).all(|a| plo[a] <= hi[a] && phi[a] >= lo[a]) {
                continue;
            }
            let of = match &polygon.file {
                Some(f) => format!(" of {}", f.display()),
                None => String::new(),
            };
            let degrees = (0..2).all(|a| {
                let limit = [180.0, 90.0][a];
                plo[a] >= -limit && phi[a] <= limit
            });
            let projected = match scan {
                Some(s) => !s.is_geographic(),
                None => (0..2).any(|a| lo[a] < -180.0 || hi[a] > 180.0),
            };
            let hint = match (degrees && projected, scan) {
                (true, Some(s)) => format!(
                    ". Its coordinates look like longitude and latitude in degrees, and the \
                     scan's are projected ({}{}): give the polygon in the scan's coordinates",
                    s.label(),
                    s.unit
                        .as_ref()
                        .map_or(String::new(), |u| format!(", in {}", u.plural()))
                ),
                (true, None) => ". Its coordinates look like longitude and latitude in degrees, \
                                  and the scan's are not: give the polygon in the scan's \
                                  coordinates"
                    .into(),
                (false, _) => String::new(),
            };
            return Err(Error::spec(
                self.name.clone(),
                Some(line),
                format!(
                    "the polygon{of} lies outside the scan's bounds, and selects \
                     nothing: it spans {}, and {} spans {}{hint}",
                    extent(plo, phi),
                    input.display(),
                    extent(lo, hi)
                ),
            ));
        }
        Ok(())
    }
}

/// `x [a, b], y [c, d]`, rounded as a user would write them: to a thousandth of the larger
/// side (of the largest coordinate, for a point).
fn extent(lo: [f64; 2], hi: [f64; 2]) -> String {
    let side = (0..2).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
    let size = match side > 0.0 {
        true => side,
        false => lo.iter().chain(&hi).fold(1.0f64, |m, v| m.max(v.abs())),
    };
    let v = |v: f64| crate::human::length(v, size);
    format!(
        "x [{}, {}], y [{}, {}]",
        v(lo[0]),
        v(hi[0]),
        v(lo[1]),
        v(hi[1])
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extents_are_rounded_to_their_size() {
        assert_eq!(
            extent([636001.76, 848935.2], [637179.22, 849497.9]),
            "x [636002, 637179], y [848935, 849498]"
        );
        assert_eq!(
            extent([-123.0751234567, 44.05], [-123.06, 44.0612345]),
            "x [-123.07512, -123.06], y [44.05, 44.06123]"
        );
    }
}
