//! Coordinate reference systems as files declare them: a LAS file's WKT (LASF_Projection 2112)
//! or GeoTIFF keys (34735, with the ASCII parameters of 34737), a GeoJSON's old `crs` member,
//! a saved field's record of the system it was solved in. Nothing here transforms coordinates:
//! rigidcells works in the input's own coordinates, and the CRS is there to tell the user
//! (`info`), and to refuse what mixes two systems (`solve` over tiles, `apply`, a GeoJSON
//! polygon).
//!
//! **When two systems are the same** ([`Crs::same_as`]): when both have an EPSG code, the codes
//! are equal (and the vertical codes, when both have one); else, when both have a WKT, the
//! texts are equal but for whitespace outside quotes; else their descriptions (name, codes and
//! units) are equal. Two descriptions of one system that these rules cannot match (a WKT without
//! a code beside the GeoTIFF keys of the same system) differ; the user says they are the same
//! with `--same-crs`. A file that declares no system beside one that does is not refused: the
//! comparison is left to the user, with a warning ([`check`]), as a PLY exported from the same
//! scan has no CRS to compare.
//!
//! **The linear unit** ([`Crs::unit`]) is the WKT's unit of the horizontal system (and of the
//! vertical one, [`Crs::vertical_unit`]), or the GeoTIFF keys' ProjLinearUnitsGeoKey (3076;
//! GeogAngularUnitsGeoKey, 2054, for a geographic system) and VerticalUnitsGeoKey (4099); where
//! the keys state none, the unit of the EPSG code's definition ([`crs_definitions`], the table
//! the COPC writer takes its WKT from), else none.

mod las;
mod wkt;

use std::fmt;
use std::path::Path;

use crate::error::{Error, Result};
use crate::said::Said;

pub use las::of_projection;

/// A coordinate reference system, as a file declares it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Crs {
    /// Its name (the WKT's, or the GeoTIFF citation, or a GeoJSON's `crs` name as written).
    pub name: Option<String>,
    /// The EPSG code of the horizontal system (a compound system's horizontal component).
    pub epsg: Option<u32>,
    /// The EPSG code of the vertical system.
    pub vertical_epsg: Option<u32>,
    /// Where it was found: `WKT`, `GeoTIFF keys` or `GeoJSON`.
    pub from: &'static str,
    /// The WKT text, when the file has one (without its terminating nulls).
    pub wkt: Option<String>,
    /// The unit of the horizontal coordinates.
    pub unit: Option<Unit>,
    /// The unit of heights, when the system has a vertical component that states one.
    pub vertical_unit: Option<Unit>,
    /// Where the unit was read, as `info` says it: `the WKT`, `the GeoTIFF keys`, or
    /// `EPSG:n's definition; the keys state none`.
    pub unit_from: String,
}

/// The unit of a system's coordinates.
#[derive(Debug, Clone, PartialEq)]
pub enum Unit {
    /// The metre.
    Metre,
    /// The US survey foot, 1200/3937 m.
    UsSurveyFoot,
    /// The international foot, 0.3048 m.
    Foot,
    /// The degree of a geographic system (longitude and latitude).
    Degree,
    /// Another unit, by the name the file gives it.
    Other(String),
}

impl Unit {
    /// The unit of a WKT `UNIT[name, factor]`: by its name when that is a known one, else by
    /// its factor to metres (or radians), else by the name as written.
    pub(crate) fn of_wkt(name: &str, factor: Option<f64>) -> Self {
        let lower = name.to_ascii_lowercase().replace(['_', '-'], " ");
        match lower.trim() {
            "metre" | "meter" | "metres" | "meters" | "m" => return Self::Metre,
            "us survey foot" | "foot us" | "us foot" | "ftus" | "us ft" | "survey foot"
            | "foot (us survey)" => return Self::UsSurveyFoot,
            "foot" | "international foot" | "ft" | "foot international" | "international feet" => {
                return Self::Foot;
            }
            "degree" | "degrees" | "deg" => return Self::Degree,
            _ => {}
        }
        let near = |v: f64| factor.is_some_and(|f| (f - v).abs() <= 1e-9 * v);
        if near(1.0) {
            Self::Metre
        } else if near(1200.0 / 3937.0) {
            Self::UsSurveyFoot
        } else if near(0.3048) {
            Self::Foot
        } else if near(std::f64::consts::PI / 180.0) {
            Self::Degree
        } else {
            Self::Other(name.to_string())
        }
    }

    /// The unit of an EPSG unit code (GeoTIFF keys 3076, 2054, 4099); `None` for none or a
    /// user-defined one.
    pub(crate) fn of_epsg(code: u16) -> Option<Self> {
        Some(match code {
            9001 => Self::Metre,
            9002 => Self::Foot,
            9003 => Self::UsSurveyFoot,
            9102 | 9122 => Self::Degree,
            0 | 32767 | 65535 => return None,
            c => Self::Other(format!("EPSG unit {c}")),
        })
    }

    /// The unit printed as [`fmt::Display`] does, read back (a saved field's).
    fn named(name: &str) -> Option<Self> {
        match name {
            "" => None,
            "metre" => Some(Self::Metre),
            "US survey foot" => Some(Self::UsSurveyFoot),
            "international foot" => Some(Self::Foot),
            "degree" => Some(Self::Degree),
            other => Some(Self::Other(other.to_string())),
        }
    }
}

impl Unit {
    /// The unit's plural, for lengths in it (`in US survey feet`).
    pub fn plural(&self) -> String {
        match self {
            Self::Metre => "metres".into(),
            Self::UsSurveyFoot => "US survey feet".into(),
            Self::Foot => "international feet".into(),
            Self::Degree => "degrees".into(),
            Self::Other(name) => format!("units of {name}"),
        }
    }
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Metre => "metre",
            Self::UsSurveyFoot => "US survey foot",
            Self::Foot => "international foot",
            Self::Degree => "degree",
            Self::Other(name) => name,
        })
    }
}

impl fmt::Display for Crs {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut parts = Vec::new();
        if let Some(n) = &self.name {
            parts.push(n.clone());
        }
        if let Some(e) = self.epsg {
            parts.push(format!("EPSG:{e}"));
        }
        if let Some(e) = self.vertical_epsg {
            parts.push(format!("vertical EPSG:{e}"));
        }
        if parts.is_empty() {
            parts.push("present, unnamed".into());
        }
        write!(f, "{} (from the {})", parts.join(", "), self.from)
    }
}

impl Crs {
    /// The system in a message: `EPSG:2903 (NAD83(HARN) / New Mexico Central (ftUS))`, the
    /// name alone, or `an unnamed system (GeoTIFF keys)`.
    pub fn label(&self) -> String {
        match (self.epsg, &self.name) {
            (Some(e), Some(n)) if *n != format!("EPSG:{e}") => format!("EPSG:{e} ({n})"),
            (Some(e), _) => format!("EPSG:{e}"),
            (None, Some(n)) => n.clone(),
            (None, None) => format!("an unnamed system ({})", self.from),
        }
    }

    /// The unit line of `info`: the horizontal unit, where it was read, and the vertical unit
    /// when it differs.
    pub fn unit_line(&self) -> String {
        let mut line = match &self.unit {
            Some(u) => format!("{u} (from {})", self.unit_from),
            None => match self.epsg {
                Some(e) => format!("not stated (EPSG:{e} has no definition known here)"),
                None => "not stated".into(),
            },
        };
        if let Some(v) = self
            .vertical_unit
            .as_ref()
            .filter(|v| Some(*v) != self.unit.as_ref())
        {
            line += &format!("; heights: {v}");
        }
        line
    }

    /// Whether this and `other` are the same system (module docs).
    pub fn same_as(&self, other: &Crs) -> bool {
        if let (Some(a), Some(b)) = (self.epsg, other.epsg) {
            let vertical = match (self.vertical_epsg, other.vertical_epsg) {
                (Some(a), Some(b)) => a == b,
                _ => true,
            };
            return a == b && vertical;
        }
        if let (Some(a), Some(b)) = (&self.wkt, &other.wkt) {
            return normalized(a) == normalized(b);
        }
        (&self.name, self.epsg, self.vertical_epsg, &self.unit)
            == (&other.name, other.epsg, other.vertical_epsg, &other.unit)
    }

    /// Whether the system is a geographic one (longitude and latitude in degrees).
    pub fn is_geographic(&self) -> bool {
        self.unit == Some(Unit::Degree)
    }

    /// The bytes of a saved field's CRS section (version 5; [`crate::field::SavedField`]):
    /// `u8` where from (0 WKT, 1 GeoTIFF keys, 2 GeoJSON), `u32` EPSG code, `u32` vertical EPSG
    /// code (0: none), then five texts, each a `u32` length and UTF-8 bytes: the name, the WKT,
    /// the unit, the vertical unit and where the unit was read (empty: none).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = vec![match self.from {
            "WKT" => 0u8,
            "GeoTIFF keys" => 1,
            _ => 2,
        }];
        out.extend_from_slice(&self.epsg.unwrap_or(0).to_le_bytes());
        out.extend_from_slice(&self.vertical_epsg.unwrap_or(0).to_le_bytes());
        let unit = |u: &Option<Unit>| u.as_ref().map(Unit::to_string).unwrap_or_default();
        for text in [
            self.name.clone().unwrap_or_default(),
            self.wkt.clone().unwrap_or_default(),
            unit(&self.unit),
            unit(&self.vertical_unit),
            self.unit_from.clone(),
        ] {
            out.extend_from_slice(&(text.len() as u32).to_le_bytes());
            out.extend_from_slice(text.as_bytes());
        }
        out
    }

    /// The CRS of bytes [`Crs::to_bytes`] wrote at the start of `bytes`, and how many bytes it
    /// took; why not, when they are not such bytes.
    pub fn from_bytes(bytes: &[u8]) -> std::result::Result<(Self, usize), String> {
        let short = || "the CRS section is truncated".to_string();
        let from = match bytes.first().ok_or_else(short)? {
            0 => "WKT",
            1 => "GeoTIFF keys",
            2 => "GeoJSON",
            b => return Err(format!("the CRS section's source {b} is unknown")),
        };
        let u32_at = |at: usize| -> std::result::Result<u32, String> {
            let b = bytes.get(at..at + 4).ok_or_else(short)?;
            Ok(u32::from_le_bytes(b.try_into().expect("4")))
        };
        let code = |c: u32| (c != 0).then_some(c);
        let (epsg, vertical_epsg) = (code(u32_at(1)?), code(u32_at(5)?));
        let mut at = 9;
        let mut texts = Vec::new();
        for _ in 0..5 {
            let len = u32_at(at)? as usize;
            let text = bytes.get(at + 4..at + 4 + len).ok_or_else(short)?;
            let text = std::str::from_utf8(text)
                .map_err(|_| "the CRS section holds a text that is not UTF-8".to_string())?;
            texts.push(text.to_string());
            at += 4 + len;
        }
        let some = |t: &String| (!t.is_empty()).then(|| t.clone());
        let crs = Crs {
            name: some(&texts[0]),
            epsg,
            vertical_epsg,
            from,
            wkt: some(&texts[1]),
            unit: Unit::named(&texts[2]),
            vertical_unit: Unit::named(&texts[3]),
            unit_from: texts[4].clone(),
        };
        Ok((crs, at))
    }

    /// The system a GeoJSON's `crs` member names (the GeoJSON 2008 form, `{"type": "name",
    /// "properties": {"name": …}}`): `urn:ogc:def:crs:EPSG::2903` (with or without a version
    /// between the colons), `EPSG:2903`, or `urn:ogc:def:crs:OGC:1.3:CRS84` (longitude and
    /// latitude on WGS 84, taken as EPSG:4326); why not, for another form.
    pub fn of_geojson(member: &serde_json::Value) -> std::result::Result<Self, String> {
        let name = member
            .get("properties")
            .and_then(|p| p.get("name"))
            .and_then(|n| n.as_str())
            .filter(|_| member.get("type").and_then(|t| t.as_str()) == Some("name"))
            .ok_or(
                "its `crs` is not {\"type\": \"name\", \"properties\": {\"name\": …}}: give the \
                 system as urn:ogc:def:crs:EPSG::CODE, or remove `crs` to take the coordinates \
                 as the scan's",
            )?;
        let upper = name.trim().to_ascii_uppercase();
        let code = if upper.ends_with("CRS84") {
            Some(4326)
        } else if let Some(rest) = upper.strip_prefix("URN:OGC:DEF:CRS:EPSG:") {
            rest.rsplit(':').next().and_then(|c| c.parse().ok())
        } else if let Some(rest) = upper.strip_prefix("EPSG:") {
            rest.parse().ok()
        } else {
            None
        };
        let epsg = code.ok_or(format!(
            "its `crs` names {name:?}, which is not an EPSG code (urn:ogc:def:crs:EPSG::CODE or \
             EPSG:CODE) nor CRS84"
        ))?;
        Ok(Crs {
            name: Some(name.to_string()),
            epsg: Some(epsg),
            from: "GeoJSON",
            unit: (epsg == 4326).then_some(Unit::Degree),
            ..Default::default()
        })
    }
}

/// A WKT without the whitespace outside its quoted texts.
fn normalized(wkt: &str) -> String {
    let mut quoted = false;
    wkt.trim_end_matches('\0')
        .chars()
        .filter(|&c| {
            if c == '"' {
                quoted = !quoted;
            }
            quoted || !c.is_whitespace()
        })
        .collect()
}

/// A file in a message.
fn shown(path: &Path) -> String {
    path.display().to_string()
}

/// Refuses, unless `same` (the user's `--same-crs`), two systems that differ ([`Crs::same_as`])
/// with [`Error::CrsMismatch`]: `what` says what differs (`the tiles' coordinate systems
/// differ`), each system is named with its file, and `advice` says what to do. When only one
/// of the two files declares a system, the warning that says so; nothing when neither does.
pub fn check(
    what: &str,
    (first, first_path): (Option<&Crs>, &Path),
    (second, second_path): (Option<&Crs>, &Path),
    same: bool,
    advice: Said,
) -> Result<Option<Said>> {
    match (first, second) {
        (Some(a), Some(b)) if !same && !a.same_as(b) => Err(Error::CrsMismatch {
            what: what.to_string(),
            first: format!("{} in {}", a.label(), shown(first_path)),
            second: format!("{} in {}", b.label(), shown(second_path)),
            advice,
        }),
        (Some(a), None) => Ok(Some(one_declared(a, first_path, second_path).into())),
        (None, Some(b)) => Ok(Some(one_declared(b, second_path, first_path).into())),
        _ => Ok(None),
    }
}

fn one_declared(crs: &Crs, with: &Path, without: &Path) -> String {
    format!(
        "{} declares no coordinate system and {} declares {}; they are taken to be in the same \
         one",
        shown(without),
        shown(with),
        crs.label()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn code(epsg: u32) -> Crs {
        Crs {
            epsg: Some(epsg),
            from: "GeoTIFF keys",
            ..Default::default()
        }
    }

    #[test]
    fn sameness_by_code_then_wkt_then_description() {
        assert!(code(2903).same_as(&code(2903)));
        assert!(!code(2903).same_as(&code(26915)));
        let wkt = |t: &str| Crs {
            wkt: Some(t.into()),
            from: "WKT",
            ..Default::default()
        };
        assert!(
            wkt("PROJCS[\"a b\", UNIT[\"m\",1]]").same_as(&wkt("PROJCS[\"a b\",UNIT[\"m\",1]]\0"))
        );
        assert!(!wkt("PROJCS[\"a b\"]").same_as(&wkt("PROJCS[\"ab\"]")));
        assert!(!wkt("PROJCS[\"a\"]").same_as(&code(2903)));
    }

    #[test]
    fn a_saved_crs_reads_back_and_damage_is_refused() {
        let crs = Crs {
            name: Some("NAD83 / UTM zone 15N".into()),
            epsg: Some(26915),
            vertical_epsg: Some(5703),
            from: "GeoTIFF keys",
            wkt: None,
            unit: Some(Unit::Metre),
            vertical_unit: Some(Unit::UsSurveyFoot),
            unit_from: "the GeoTIFF keys".into(),
        };
        let bytes = crs.to_bytes();
        assert_eq!(Crs::from_bytes(&bytes), Ok((crs, bytes.len())));
        for cut in 0..bytes.len() {
            assert!(Crs::from_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
        }
    }

    #[test]
    fn geojson_names() {
        let member = |name: &str| serde_json::json!({"type": "name", "properties": {"name": name}});
        let epsg = |name: &str| Crs::of_geojson(&member(name)).map(|c| c.epsg);
        assert_eq!(epsg("urn:ogc:def:crs:EPSG::2903"), Ok(Some(2903)));
        assert_eq!(epsg("urn:ogc:def:crs:EPSG:6.6:2903"), Ok(Some(2903)));
        assert_eq!(epsg("EPSG:2903"), Ok(Some(2903)));
        assert_eq!(epsg("urn:ogc:def:crs:OGC:1.3:CRS84"), Ok(Some(4326)));
        assert!(epsg("WGS84").is_err());
        assert!(Crs::of_geojson(&serde_json::json!({"type": "link"})).is_err());
    }
}
