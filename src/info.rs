//! What `rigidcells info` tells about a file, for every format it reads: counts, bounds and
//! centroid, the coordinate reference system by name with its linear unit ([`crate::crs`]; a
//! saved field's, of the input it was solved on), the fields of the records, and the
//! format's own details (LAS header and VLRs, a PLY header, a saved field's cells, levels,
//! transfer and domain, a picture's size and foreground).
//!
//! Coordinates are printed to the file's precision: a LAS file's scale (0.01 → two decimals),
//! single precision where the file holds `float` vertices, else the shortest text that reads
//! back as the number. The centroid takes the bounds' decimals, and, where the file has no
//! step (floats, text), at least those that resolve a thousandth of its largest size: a mean
//! lies between the samples, and bounds of whole numbers say nothing of the decimals between
//! them (a 10 × 1 × 1 bar's centroid is (5, 0.5, 0.5), not (5, 0, 0)).

use std::fmt;
use std::path::Path;

pub use crate::crs::Crs;
use crate::error::{Error, Result};
pub use crate::io::crs_of as crs;
use crate::io::{self, Chunk, LasHeader};
use crate::progress::Observer;

/// A file's description; [`fmt::Display`] prints it as `rigidcells info` does.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Description {
    /// The file.
    pub path: String,
    /// The format in words (`LAZ 1.2, point data record format 3, 34 bytes per record`).
    pub format: String,
    /// Samples (points, vertices, foreground pixels, cells of a field).
    pub samples: u64,
    /// What a sample is, for the count's label (`points`, `vertices`, `cells`, …).
    pub samples_are: &'static str,
    /// Triangles of a mesh.
    pub triangles: Option<usize>,
    /// The lowest and highest coordinate per axis (2 or 3 axes).
    pub bounds: Option<(Vec<f64>, Vec<f64>)>,
    /// The mean of the samples.
    pub centroid: Option<Vec<f64>>,
    /// Decimals per axis to print coordinates with (`None`: the shortest round-trip text).
    pub decimals: Option<Vec<usize>>,
    /// Whether coordinates are single precision (print them as `f32`).
    pub single: bool,
    /// The coordinate reference system.
    pub crs: Option<Crs>,
    /// The fields of each record (LAS), or the vertex properties (PLY).
    pub fields: Vec<String>,
    /// Further lines: a label and its text.
    pub details: Vec<(String, String)>,
}

impl Description {
    fn coord(&self, axis: usize, v: f64) -> String {
        match &self.decimals {
            Some(d) => format!("{v:.*}", d[axis.min(d.len() - 1)]),
            None if self.single => format!("{}", v as f32),
            None => format!("{v}"),
        }
    }

    /// Decimals of the centroid, per axis: the bounds', and with no step of the file's own at
    /// least those that resolve a thousandth of the largest size (module docs).
    fn centroid_decimals(&self) -> Vec<usize> {
        let bounds = self.bound_decimals();
        let (Some((lo, hi)), None) = (&self.bounds, &self.decimals) else {
            return bounds;
        };
        let size = (0..lo.len()).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
        let fine = match size > 0.0 {
            true => crate::human::decimals(size / 1000.0).min(9),
            false => 0,
        };
        bounds.into_iter().map(|d| d.max(fine)).collect()
    }

    /// Decimals of the bounds as printed, per axis.
    fn bound_decimals(&self) -> Vec<usize> {
        let Some((lo, hi)) = &self.bounds else {
            return Vec::new();
        };
        (0..lo.len())
            .map(|a| {
                [lo[a], hi[a]]
                    .iter()
                    .map(|&v| {
                        let s = self.coord(a, v);
                        s.split_once('.').map_or(0, |(_, d)| d.len())
                    })
                    .max()
                    .unwrap_or(0)
                    .min(9)
            })
            .collect()
    }
}

const AXES: [&str; 3] = ["x", "y", "z"];

impl fmt::Display for Description {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "{}", self.path)?;
        writeln!(f, "  format: {}", self.format)?;
        writeln!(f, "  {}: {}", self.samples_are, self.samples)?;
        if let Some(t) = self.triangles {
            writeln!(f, "  triangles: {t}")?;
        }
        if let Some((lo, hi)) = &self.bounds {
            let axes: Vec<String> = (0..lo.len())
                .map(|a| {
                    format!(
                        "{} [{}, {}]",
                        AXES[a],
                        self.coord(a, lo[a]),
                        self.coord(a, hi[a])
                    )
                })
                .collect();
            writeln!(f, "  bounds: {}", axes.join("  "))?;
            let size: Vec<String> = (0..lo.len())
                .map(|a| {
                    let d = self.bound_decimals()[a];
                    format!("{:.d$}", hi[a] - lo[a])
                })
                .collect();
            writeln!(f, "  size: {}", size.join(" × "))?;
        }
        if let Some(c) = &self.centroid {
            let d = self.centroid_decimals();
            let v: Vec<String> = c
                .iter()
                .enumerate()
                .map(|(a, v)| format!("{v:.*}", d.get(a).copied().unwrap_or(6)))
                .collect();
            writeln!(f, "  centroid: [{}]", v.join(", "))?;
        }
        match &self.crs {
            Some(c) => {
                writeln!(f, "  CRS: {c}")?;
                writeln!(f, "  unit: {}", c.unit_line())?;
            }
            None if self.format.starts_with("LA") => writeln!(f, "  CRS: none")?,
            None if self.samples_are == "cells" => writeln!(f, "  CRS: none recorded")?,
            None => {}
        }
        if !self.fields.is_empty() {
            writeln!(f, "  fields: {}", self.fields.join(", "))?;
        }
        for (k, v) in &self.details {
            writeln!(f, "  {k}: {v}")?;
        }
        Ok(())
    }
}

/// Describes the file at `path` (module docs). Reads every sample once for the centroid (and
/// the bounds where the header gives none), with progress on `observer`.
pub fn describe(path: &Path, observer: &dyn Observer) -> Result<Description> {
    let mut info = Description {
        path: path.display().to_string(),
        ..Default::default()
    };
    match io::extension(path).as_deref() {
        Some("las") | Some("laz") => las(path, &mut info)?,
        Some("field") => return field(path, info),
        Some("png") => return picture(path, info),
        Some("xy") => {
            let file = io::XyFile::read(path)?;
            info.format = "2D point set (x y per line)".into();
            info.samples_are = "points";
            info.samples = file.points().len() as u64;
            let pts: Vec<[f64; 2]> = file.points().iter().map(|p| [p.x, p.y]).collect();
            set_extent(&mut info, pts.iter().map(|p| &p[..]), 2);
            return Ok(info);
        }
        _ => {}
    }
    let mut source = io::open(path)?;
    if info.format.is_empty() {
        other_format(path, source.as_ref(), &mut info)?;
    }
    // One pass: bounds (where the header gave none) and the centroid.
    observer.stage("reading", source.len());
    source.rewind()?;
    let mut chunk = Chunk::default();
    let (mut sum, mut n) = ([0.0f64; 3], 0u64);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    // Sums relative to the first sample keep the digits of georeferenced coordinates.
    let mut base = None;
    while source.read_samples(1 << 16, &mut chunk)? > 0 {
        for p in &chunk.positions {
            let b = *base.get_or_insert(*p);
            for a in 0..3 {
                sum[a] += p[a] - b[a];
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
            n += 1;
        }
        observer.advance(chunk.len() as u64);
    }
    observer.finish();
    if let (Some(b), true) = (base, n > 0) {
        info.centroid = Some((0..3).map(|a| b[a] + sum[a] / n as f64).collect());
        // The bounds are the samples' own; a LAS header that declares others (a damaged or
        // stale header) is shown beside them, not in their place.
        let tolerance = |a: usize| {
            info.decimals
                .as_ref()
                .map_or(0.0, |d| 0.5 * 10f64.powi(-(d[a] as i32)))
        };
        if let Some((hlo, hhi)) = info.bounds.take() {
            let differs = (0..3).any(|a| {
                (hlo[a] - lo[a]).abs() > tolerance(a) || (hhi[a] - hi[a]).abs() > tolerance(a)
            });
            if differs {
                let axes: Vec<String> = (0..3)
                    .map(|a| {
                        format!(
                            "{} [{}, {}]",
                            AXES[a],
                            info.coord(a, hlo[a]),
                            info.coord(a, hhi[a])
                        )
                    })
                    .collect();
                info.details.push((
                    "header bounds".into(),
                    format!("{} (differ from the points')", axes.join("  ")),
                ));
            }
        }
        info.bounds = Some((lo.to_vec(), hi.to_vec()));
    }
    Ok(info)
}

/// Bounds and centroid of points given in memory.
fn set_extent<'a>(info: &mut Description, points: impl Iterator<Item = &'a [f64]>, dim: usize) {
    let mut lo = vec![f64::INFINITY; dim];
    let mut hi = vec![f64::NEG_INFINITY; dim];
    let mut sum = vec![0.0; dim];
    let mut n = 0usize;
    for p in points {
        for a in 0..dim {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
            sum[a] += p[a];
        }
        n += 1;
    }
    if n > 0 {
        info.centroid = Some(sum.iter().map(|s| s / n as f64).collect());
        info.bounds = Some((lo, hi));
    }
}

fn other_format(path: &Path, source: &dyn io::Source, info: &mut Description) -> Result<()> {
    let triangles = source.triangles().len();
    let ext = io::extension(path).unwrap_or_default();
    info.samples = source.len();
    match ext.as_str() {
        "ply" => {
            let header = io::layout(path)?;
            info.format = format!(
                "PLY, {}",
                header
                    .lines()
                    .find_map(|l| l.trim().strip_prefix("format "))
                    .unwrap_or("?")
            );
            info.samples_are = "vertices";
            // The vertex element's properties, and whether x is a float.
            let mut in_vertex = false;
            for l in header.lines().map(str::trim) {
                if let Some(e) = l.strip_prefix("element ") {
                    in_vertex = e.starts_with("vertex ");
                } else if in_vertex && let Some(p) = l.strip_prefix("property ") {
                    let words: Vec<&str> = p.split_whitespace().collect();
                    if let Some(name) = words.last() {
                        info.fields.push(name.to_string());
                        if *name == "x" {
                            info.single = matches!(words[0], "float" | "float32");
                        }
                    }
                }
            }
            // Elements with their counts and properties; comments.
            let mut elements: Vec<String> = Vec::new();
            for l in header.lines().map(str::trim) {
                if let Some(e) = l.strip_prefix("element ") {
                    elements.push(format!("{e} ("));
                } else if let (Some(p), Some(last)) =
                    (l.strip_prefix("property "), elements.last_mut())
                {
                    if !last.ends_with('(') {
                        last.push_str(", ");
                    }
                    last.push_str(p.split_whitespace().last().unwrap_or(""));
                } else if let Some(c) = l.strip_prefix("comment ") {
                    info.details.push(("comment".into(), c.to_string()));
                }
            }
            let elements: Vec<String> = elements.into_iter().map(|e| e + ")").collect();
            info.details.push(("elements".into(), elements.join(", ")));
        }
        "obj" => {
            info.format = "OBJ".into();
            info.samples_are = "vertices";
            info.details.push(("statements".into(), io::layout(path)?));
        }
        _ => {
            info.format = "XYZ text (x y z per line, more columns kept)".into();
            info.samples_are = "points";
        }
    }
    if ext != "xyz" {
        info.triangles = Some(triangles);
    }
    Ok(())
}

/// The point-record fields of each LAS point data record format.
fn las_fields(format: u8) -> Vec<&'static str> {
    let mut f = vec![
        "X",
        "Y",
        "Z",
        "intensity",
        "return number",
        "number of returns",
    ];
    if format >= 6 {
        f.extend(["classification flags", "scanner channel"]);
    }
    f.extend([
        "scan direction",
        "edge of flight line",
        "classification",
        "scan angle",
        "user data",
        "point source ID",
    ]);
    if matches!(format, 1 | 3 | 4 | 5) || format >= 6 {
        f.push("GPS time");
    }
    if matches!(format, 2 | 3 | 5 | 7 | 8 | 10) {
        f.push("RGB");
    }
    if matches!(format, 8 | 10) {
        f.push("NIR");
    }
    if matches!(format, 4 | 5 | 9 | 10) {
        f.push("wave packet");
    }
    f
}

fn las(path: &Path, info: &mut Description) -> Result<()> {
    let h = LasHeader::read(path)?;
    info.format = format!(
        "{} {}.{}, point data record format {}, {} bytes per record",
        if h.compressed { "LAZ" } else { "LAS" },
        h.version.0,
        h.version.1,
        h.format,
        h.record_len
    );
    info.samples_are = "points";
    info.samples = h.count;
    info.bounds = Some((h.min.to_vec(), h.max.to_vec()));
    info.decimals = Some(h.scale.iter().map(|&s| crate::human::decimals(s)).collect());
    info.fields = las_fields(h.format).iter().map(|s| s.to_string()).collect();
    let records = crate::io::LasSource::open(path)?.vlr_records();
    for r in &records {
        if r.is("LASF_Spec", 4) {
            // Extra-bytes descriptors: 192 bytes each, the name at bytes 4..36.
            for d in r.data.chunks_exact(192) {
                let name = String::from_utf8_lossy(&d[4..36])
                    .trim_end_matches('\0')
                    .to_string();
                info.fields.push(format!("{name} (extra bytes)"));
            }
        }
    }
    info.crs = crs(&records);
    info.details.push((
        "scale".into(),
        format!("{:?}  offset: {:?}", h.scale, h.offset),
    ));
    info.details.push((
        "VLRs".into(),
        format!(
            "{} ({}), EVLRs: {}",
            h.vlrs.len(),
            h.vlrs
                .iter()
                .map(|v| format!("{}:{}", v.user_id, v.record_id))
                .collect::<Vec<_>>()
                .join(", "),
            h.evlr_count
        ),
    ));
    if records.iter().any(|r| r.user_id == "copc") {
        info.details
            .push(("COPC".into(), "yes (a cloud-optimized point cloud)".into()));
    }
    info.details
        .push(("software".into(), format!("{} / {}", h.system, h.software)));
    Ok(())
}

fn field(path: &Path, mut info: Description) -> Result<Description> {
    // "RCFIELD\0", u32 version, u32 dimension.
    let mut head = [0u8; 16];
    std::io::Read::read_exact(
        &mut std::fs::File::open(path).map_err(|e| Error::io(path, e))?,
        &mut head,
    )
    .map_err(|_| Error::format(path, "too short for a saved field"))?;
    match u32::from_le_bytes([head[12], head[13], head[14], head[15]]) {
        2 => fill_field(&mut info, &crate::field::SavedField::<2>::load(path)?),
        _ => fill_field(&mut info, &crate::field::SavedField::<3>::load(path)?),
    }
    Ok(info)
}

fn fill_field<const D: usize>(info: &mut Description, saved: &crate::field::SavedField<D>) {
    let f = &saved.field;
    info.format = format!("rigidcells saved field, {D}D");
    // The system of the input the field was solved on.
    info.crs = saved.crs.clone();
    info.samples_are = "cells";
    info.samples = f.centers.len() as u64;
    // The domain: the cells' cubes in world coordinates.
    let sizes: Vec<f64> = f.cell_sizes().iter().map(|&(s, _)| s).collect();
    if let Some((lo, hi)) = f.domain() {
        let (lo, hi): (Vec<f64>, Vec<f64>) =
            (lo.iter().copied().collect(), hi.iter().copied().collect());
        // The cubes' faces to a thousandth of the finest cell (no more decimals than that
        // needs), not to 17 digits.
        let decimals = lo
            .iter()
            .chain(&hi)
            .map(|&v| {
                let text = crate::human::length(v, sizes[0]);
                text.split_once('.').map_or(0, |(_, d)| d.len())
            })
            .max()
            .unwrap_or(0);
        info.decimals = Some(vec![decimals; lo.len()]);
        info.bounds = Some((lo, hi));
    }
    info.details.push((
        "levels".into(),
        format!(
            "{} (cell sizes {})",
            sizes.len(),
            sizes
                .iter()
                .map(|&s| crate::human::length(s, sizes[0]))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    ));
    info.details
        .push(("transfer".into(), saved.transfer.to_string()));
    if f.heights_kept {
        info.details.push((
            "heights".into(),
            "kept: the field moves x and y only (2D control points)".into(),
        ));
    }
    let moved = f
        .motions
        .iter()
        .zip(&f.centers)
        .map(|(m, c)| (m.pos - c).norm())
        .fold(0.0f64, f64::max);
    info.details.push((
        "domain".into(),
        "the bounds above: the cells' cubes, in the input's coordinates".into(),
    ));
    let finest = sizes.first().copied().unwrap_or(1.0);
    info.details.push((
        "largest cell motion".into(),
        crate::human::length(moved, finest),
    ));
}

fn picture(path: &Path, mut info: Description) -> Result<Description> {
    let r = crate::image::Raster::read_png(path)?;
    info.format = format!("PNG, {} × {} pixels", r.width, r.height);
    info.samples_are = "foreground pixels";
    let opaque = r.rgba.chunks_exact(4).all(|p| p[3] == 255);
    let w = r.width as usize;
    let centers: Vec<[f64; 2]> = r
        .rgba
        .chunks_exact(4)
        .enumerate()
        .filter(|(_, p)| opaque || p[3] > 0)
        .map(|(i, _)| [(i % w) as f64 + 0.5, (i / w) as f64 + 0.5])
        .collect();
    info.samples = centers.len() as u64;
    set_extent(&mut info, centers.iter().map(|p| &p[..]), 2);
    if opaque {
        info.details.push((
            "foreground".into(),
            "the picture is opaque: `image` needs its background color (--background R,G,B)".into(),
        ));
    }
    info.details
        .push(("coordinates".into(), "pixels, x right, y down".into()));
    Ok(info)
}
