//! Offset grids as GeoTIFF files in PROJ's Geodetic TIFF Grid profile
//! (<https://proj.org/specifications/geodetictiffgrids.html>), which `+proj=gridshift`
//! applies to projected coordinates (PROJ 9.4 and later) and GDAL reads as a raster.
//!
//! The file is one image of `columns × rows` pixels with three `Float32` samples per pixel,
//! east, north and up offsets, interleaved (`PlanarConfiguration` 1, which PROJ reads as well
//! as the separate planes of its own grids), uncompressed, in strips of whole rows, little
//! endian. Beside the baseline TIFF tags:
//!
//! - `ModelPixelScale` (33550) and `ModelTiepoint` (33922): the spacing, and pixel (0, 0) at
//!   the north-west node;
//! - `GeoKeyDirectory` (34735), GeoTIFF 1.1: `GTModelTypeGeoKey` = projected (PROJ then takes
//!   the grid's coordinates and offsets as lengths, not degrees), `GTRasterTypeGeoKey` =
//!   PixelIsPoint (a pixel is a node, as the tie point says), and `ProjectedCRSGeoKey` = the
//!   EPSG code when it is known (left out otherwise; PROJ does not read it);
//! - `GDAL_METADATA` (42112): `TYPE` = `HORIZONTAL_OFFSET`, the samples' descriptions
//!   `easting_offset`, `northing_offset` and `vertical_offset` with `UNITTYPE` `metre`, and
//!   `interpolation_method` `bilinear`. `gridshift` reads the third sample of such a grid as the
//!   height's offset and adds all three, interpolated at the point's own position, in one step;
//! - `GDAL_NODATA` (42113): the value of nodes without one ([`NO_VALUE`], finite, as the profile
//!   asks); PROJ refuses points whose interpolation would reach one.
//!
//! The few tags are written here by hand rather than through an image crate: every one of
//! them is spelled out above, and the writer stays a page long.

/// Offsets on a grid of nodes: what a grid file holds (a field sampled by [`crate::field::grid`]).
#[derive(Debug, Clone, PartialEq)]
pub struct OffsetGrid {
    /// The north-west node (world coordinates).
    pub west: f64,
    /// The north-west node's y (world coordinates).
    pub north: f64,
    /// The distance between nodes, east and south.
    pub spacing: f64,
    /// Nodes per row.
    pub columns: usize,
    /// Rows of nodes.
    pub rows: usize,
    /// East, north and up offsets of each node, row by row from the north (NaN: no value).
    pub offsets: Vec<[f32; 3]>,
}

/// The value written for a node without an offset.
pub const NO_VALUE: f32 = -999_999.0;

/// Rows per strip: strips of about 64 KiB (PROJ reads and caches a strip at a time).
fn rows_per_strip(columns: usize) -> usize {
    (65_536 / (columns * 12)).max(1)
}

const SHORT: u16 = 3;
const LONG: u16 = 4;
const ASCII: u16 = 2;
const DOUBLE: u16 = 12;

/// A tag of the image directory: its number, type, count and value bytes.
struct Entry {
    tag: u16,
    kind: u16,
    count: u32,
    bytes: Vec<u8>,
}

fn shorts(tag: u16, values: &[u16]) -> Entry {
    let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    Entry {
        tag,
        kind: SHORT,
        count: values.len() as u32,
        bytes,
    }
}

fn longs(tag: u16, values: &[u32]) -> Entry {
    let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    Entry {
        tag,
        kind: LONG,
        count: values.len() as u32,
        bytes,
    }
}

fn doubles(tag: u16, values: &[f64]) -> Entry {
    let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    Entry {
        tag,
        kind: DOUBLE,
        count: values.len() as u32,
        bytes,
    }
}

/// TIFF text: 7-bit ASCII (other characters become `?`), ending with NUL.
fn ascii(tag: u16, text: &str) -> Entry {
    let mut bytes: Vec<u8> = text
        .chars()
        .map(|c| {
            if c.is_ascii() && c != '\0' {
                c as u8
            } else {
                b'?'
            }
        })
        .collect();
    bytes.push(0);
    Entry {
        tag,
        kind: ASCII,
        count: bytes.len() as u32,
        bytes,
    }
}

/// The `GDAL_METADATA` XML of an offset grid (module docs).
fn metadata(epsg: Option<u16>) -> String {
    let mut xml = String::from("<GDALMetadata>\n");
    xml += "  <Item name=\"TYPE\">HORIZONTAL_OFFSET</Item>\n";
    xml += "  <Item name=\"interpolation_method\">bilinear</Item>\n";
    if let Some(code) = epsg {
        xml += &format!("  <Item name=\"target_crs_epsg_code\">{code}</Item>\n");
    }
    for (k, name) in ["easting_offset", "northing_offset", "vertical_offset"]
        .iter()
        .enumerate()
    {
        xml += &format!(
            "  <Item name=\"DESCRIPTION\" sample=\"{k}\" role=\"description\">{name}</Item>\n\
             \x20 <Item name=\"UNITTYPE\" sample=\"{k}\" role=\"unittype\">metre</Item>\n"
        );
    }
    xml + "</GDALMetadata>"
}

/// The GeoTIFF of `grid` (module docs), its CRS `epsg` when known, with `description` as its
/// `ImageDescription`. The caller keeps the file under 4 GiB (12 bytes a node).
pub fn offsets_tiff(grid: &OffsetGrid, epsg: Option<u16>, description: &str) -> Vec<u8> {
    let (columns, rows) = (grid.columns, grid.rows);
    let per_strip = rows_per_strip(columns);
    let strips = rows.div_ceil(per_strip);
    let strip_bytes: Vec<u32> = (0..strips)
        .map(|s| ((rows - s * per_strip).min(per_strip) * columns * 12) as u32)
        .collect();
    let mut geokeys = vec![1, 1, 1, 2, 1024, 0, 1, 1, 1025, 0, 1, 2];
    if let Some(code) = epsg {
        geokeys[3] = 3;
        geokeys.extend([3072, 0, 1, code]);
    }
    let mut entries = vec![
        longs(256, &[columns as u32]),
        longs(257, &[rows as u32]),
        shorts(258, &[32, 32, 32]),
        shorts(259, &[1]),
        shorts(262, &[1]),
        ascii(270, description),
        longs(273, &vec![0; strips]),
        shorts(277, &[3]),
        longs(278, &[per_strip as u32]),
        longs(279, &strip_bytes),
        shorts(284, &[1]),
        ascii(305, &format!("rigidcells {}", env!("CARGO_PKG_VERSION"))),
        shorts(338, &[0, 0]),
        shorts(339, &[3, 3, 3]),
        doubles(33550, &[grid.spacing, grid.spacing, 0.0]),
        doubles(33922, &[0.0, 0.0, 0.0, grid.west, grid.north, 0.0]),
        shorts(34735, &geokeys),
        ascii(42112, &metadata(epsg)),
        ascii(42113, &format!("{NO_VALUE}")),
    ];
    // Header, directory, the values too long for an entry (each at an even offset), strips.
    let directory = 8 + 2 + 12 * entries.len() + 4;
    let mut place = directory;
    let mut offsets = Vec::with_capacity(entries.len());
    for e in &entries {
        offsets.push(place);
        if e.bytes.len() > 4 {
            place += e.bytes.len().next_multiple_of(2);
        }
    }
    let first_strip = place.next_multiple_of(4);
    let starts: Vec<u32> = (0..strips)
        .map(|s| (first_strip + s * per_strip * columns * 12) as u32)
        .collect();
    entries[6] = longs(273, &starts);
    let mut out = Vec::with_capacity(first_strip + rows * columns * 12);
    out.extend_from_slice(b"II");
    out.extend_from_slice(&42u16.to_le_bytes());
    out.extend_from_slice(&8u32.to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for (e, &at) in entries.iter().zip(&offsets) {
        out.extend_from_slice(&e.tag.to_le_bytes());
        out.extend_from_slice(&e.kind.to_le_bytes());
        out.extend_from_slice(&e.count.to_le_bytes());
        let mut value = [0u8; 4];
        match e.bytes.len() {
            n if n <= 4 => value[..n].copy_from_slice(&e.bytes),
            _ => value = (at as u32).to_le_bytes(),
        }
        out.extend_from_slice(&value);
    }
    out.extend_from_slice(&0u32.to_le_bytes());
    for e in entries.iter().filter(|e| e.bytes.len() > 4) {
        out.extend_from_slice(&e.bytes);
        out.resize(out.len().next_multiple_of(2), 0);
    }
    out.resize(first_strip, 0);
    for o in &grid.offsets {
        for v in o {
            let v = if v.is_nan() { NO_VALUE } else { *v };
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}
