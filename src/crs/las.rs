//! The CRS of a LAS file's (E)VLRs: the WKT (LASF_Projection 2112), else the GeoTIFF key
//! directory (34735) with its ASCII parameters (34737).

use super::{Crs, Unit, wkt};

/// The CRS of a LAS file's (E)VLRs, given the payload of its `LASF_Projection` record of each
/// id (`io::las::crs_of` finds them): the WKT's name, EPSG codes and units, else the GeoTIFF
/// keys'. A WKT without a code or a vertical system of its own takes the GeoTIFF keys' when
/// the file has both.
pub fn of_projection<'a>(find: impl Fn(u16) -> Option<&'a [u8]>) -> Option<Crs> {
    let keys = find(34735).and_then(|k| geotiff(k, find(34737).unwrap_or(&[])));
    let Some(text) = find(2112) else {
        return keys;
    };
    let text = String::from_utf8_lossy(text);
    let text = text.trim_end_matches('\0').to_string();
    let tree = wkt::parse(&text);
    let tree = tree.as_ref();
    let horizontal = tree.and_then(wkt::Wkt::horizontal);
    let unit = horizontal.and_then(wkt::Wkt::unit);
    let mut crs = Crs {
        name: tree.and_then(wkt::Wkt::name),
        epsg: tree
            .and_then(wkt::Wkt::epsg)
            .or(keys.as_ref().and_then(|k| k.epsg)),
        vertical_epsg: tree
            .and_then(wkt::Wkt::vertical_epsg)
            .or(keys.as_ref().and_then(|k| k.vertical_epsg)),
        from: "WKT",
        unit_from: if unit.is_some() {
            "the WKT".into()
        } else {
            String::new()
        },
        unit,
        vertical_unit: tree.and_then(wkt::Wkt::vertical).and_then(wkt::Wkt::unit),
        wkt: (!text.trim().is_empty()).then_some(text),
    };
    if crs.unit.is_none()
        && let Some(k) = keys
    {
        crs.unit = k.unit;
        crs.unit_from = k.unit_from;
        crs.vertical_unit = crs.vertical_unit.or(k.vertical_unit);
    }
    Some(crs)
}

/// The CRS of a GeoTIFF key directory (`keys`, LASF_Projection 34735) and its ASCII parameters
/// (`ascii`, 34737).
fn geotiff(keys: &[u8], ascii: &[u8]) -> Option<Crs> {
    let words: Vec<u16> = keys
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    let mut crs = Crs {
        from: "GeoTIFF keys",
        ..Default::default()
    };
    let n = words.get(3).copied().unwrap_or(0) as usize;
    let (mut projected, mut geographic, mut citation) = (None, None, None);
    let (mut linear, mut angular, mut model) = (None, None, None);
    for e in words.get(4..).unwrap_or(&[]).chunks_exact(4).take(n) {
        let (key, location, count, value) = (e[0], e[1], e[2] as usize, e[3] as usize);
        let code = (location == 0 && value != 0 && value != 32767).then_some(value as u32);
        let direct = (location == 0).then_some(e[3]);
        match key {
            1024 => model = direct,
            3072 => projected = code,
            2048 => geographic = code,
            4096 => crs.vertical_epsg = code,
            3076 => linear = direct,
            2054 => angular = direct,
            4099 => crs.vertical_unit = direct.and_then(Unit::of_epsg),
            1026 | 3073 if location == 34737 => {
                let s = ascii.get(value..value + count).unwrap_or(&[]);
                let s = String::from_utf8_lossy(s)
                    .trim_end_matches(['|', '\0'])
                    .trim()
                    .to_string();
                if !s.is_empty() && (key == 3073 || citation.is_none()) {
                    citation = Some(s);
                }
            }
            _ => {}
        }
    }
    crs.epsg = projected.or(geographic);
    crs.name = citation;
    // A geographic model (type 2), or a geographic code without a projected one: degrees.
    let is_geographic = model == Some(2) || (projected.is_none() && geographic.is_some());
    let stated = match is_geographic {
        true => angular.and_then(Unit::of_epsg),
        false => linear.and_then(Unit::of_epsg),
    };
    match (stated, crs.epsg) {
        (Some(u), _) => {
            crs.unit = Some(u);
            crs.unit_from = "the GeoTIFF keys".into();
        }
        (None, Some(code)) => {
            if let Some(tree) = u16::try_from(code)
                .ok()
                .and_then(crs_definitions::from_code)
                .and_then(|d| wkt::parse(d.wkt))
            {
                crs.unit = tree.horizontal().and_then(wkt::Wkt::unit);
                crs.unit_from = format!("EPSG:{code}'s definition; the keys state none");
            }
        }
        (None, None) => {}
    }
    Some(crs)
}
