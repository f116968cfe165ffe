//! `rigidcells info` for every format: counts, bounds and centroid, coordinates to the file's
//! precision, the CRS by name and EPSG code, record fields, the software that wrote a LAS file,
//! a field's cells and levels, a picture's foreground.

mod common;

use common::{arg, run, shared};

fn info(path: &std::path::Path) -> String {
    let r = run(&["info", arg(path)]);
    assert_eq!(r.code, 0, "{}: {}", path.display(), r.stderr);
    r.stdout
}

fn line<'a>(text: &'a str, key: &str) -> &'a str {
    text.lines()
        .find(|l| l.trim_start().starts_with(key))
        .unwrap_or_else(|| panic!("no `{key}` in\n{text}"))
}

#[test]
fn las_bounds_to_the_scale_crs_by_name_and_fields() {
    let t = info(&shared("las/autzen_trim.laz"));
    // 637179.2200000001 in the header's doubles: printed to the scale's 0.01.
    assert!(
        line(&t, "bounds:").contains("x [636001.76, 637179.22]"),
        "{t}"
    );
    assert!(
        line(&t, "centroid:").contains("[636546.40, 849145.79, 430.34]"),
        "{t}"
    );
    assert!(
        line(&t, "CRS:").contains("NAD_1983_HARN_Lambert_Conformal_Conic"),
        "{t}"
    );
    assert!(line(&t, "fields:").contains("GPS time, RGB"), "{t}");
    // A compound WKT: its name and its horizontal system's code (not a unit's).
    let t = info(&shared("las/1.2-with-color.copc.laz"));
    let crs = line(&t, "CRS:");
    assert!(
        crs.contains("NAD83 / Oregon LCC (m) + NAVD88 height (ftUS)"),
        "{crs}"
    );
    assert!(crs.contains("EPSG:2991"), "{crs}");
    assert!(line(&t, "COPC:").contains("yes"), "{t}");
    // GeoTIFF keys only.
    let t = info(&shared("las/epsg_4326.las"));
    assert!(
        line(&t, "CRS:").contains("EPSG:4326 (from the GeoTIFF keys)"),
        "{t}"
    );
    assert!(
        line(&t, "bounds:").contains("x [-94.6834654, -94.6606311]"),
        "{t}"
    );
    // A header that declares bounds in record units (simple1_3.las): the points' own bounds,
    // and the header's beside them, marked.
    let t = info(&shared("las/simple1_3.las"));
    assert!(
        line(&t, "bounds:").contains("x [-235434.519, -234935.841]"),
        "{t}"
    );
    assert!(
        line(&t, "header bounds:").contains("differ from the points'"),
        "{t}"
    );
    assert!(!info(&shared("las/autzen_trim.laz")).contains("header bounds"));
    // Extra bytes by name.
    let t = info(&shared("las/extrabytes.las"));
    assert!(line(&t, "fields:").contains("Colors (extra bytes)"), "{t}");
    assert!(line(&t, "CRS:").contains("none"), "{t}");
}

#[test]
fn meshes_and_point_sets_have_bounds_and_centroids() {
    let t = info(&shared("meshes/bun_zipper.ply"));
    assert!(line(&t, "vertices:").contains("35947"), "{t}");
    assert!(line(&t, "triangles:").contains("69451"), "{t}");
    // Single-precision vertices print as the floats they are.
    assert!(
        line(&t, "bounds:").contains("x [-0.0946899, 0.0610091]"),
        "{t}"
    );
    // The mean of the vertices, to the bounds' seven decimals; checked against a mean taken
    // here from the file's text.
    assert_eq!(
        line(&t, "centroid:"),
        "  centroid: [-0.0267599, 0.0952161, 0.0089471]"
    );
    let mean = ascii_ply_vertex_mean(&shared("meshes/bun_zipper.ply"));
    for (printed, mean) in [-0.0267599, 0.0952161, 0.0089471].iter().zip(mean) {
        assert!((printed - mean).abs() <= 0.5e-7, "{printed} against {mean}");
    }
    assert!(line(&t, "elements:").contains("vertex 35947 (x, y, z, confidence, intensity)"));
    let t = info(&shared("meshes/spot.obj"));
    assert!(
        line(&t, "bounds:").contains("x [-0.471552, 0.471552]"),
        "{t}"
    );
    assert!(line(&t, "triangles:").contains("5856"), "{t}");
    let dir = tempfile::tempdir().unwrap();
    let xy = dir.path().join("p.xy");
    std::fs::write(&xy, "1 2\n3 4.5\n").unwrap();
    let t = info(&xy);
    assert!(line(&t, "points:").contains('2'), "{t}");
    assert!(line(&t, "bounds:").contains("x [1, 3]  y [2, 4.5]"), "{t}");
    // (2, 3.25) to a thousandth of the largest size, 2.5: the bounds' decimals (none for x,
    // one for y) would print 3.25 as 3.2.
    assert_eq!(line(&t, "centroid:"), "  centroid: [2.000, 3.250]");
    // Single-precision vertices of whole-numbered bounds: a bar's centroid between them.
    let bar = dir.path().join("bar.ply");
    data_gen::write_ply(&bar, &data_gen::bar([10.0, 1.0, 1.0], 8.0), true).unwrap();
    let t = info(&bar);
    assert!(line(&t, "bounds:").contains("x [0, 10]  y [0, 1]"), "{t}");
    assert_eq!(line(&t, "centroid:"), "  centroid: [5.00, 0.50, 0.50]");
    let xyz = dir.path().join("p.xyz");
    std::fs::write(&xyz, "1 2 3\n3 4.5 5\n").unwrap();
    let t = info(&xyz);
    assert!(line(&t, "bounds:").contains("z [3, 5]"), "{t}");
}

#[test]
fn fields_and_pictures() {
    let dir = tempfile::tempdir().unwrap();
    let r = run(&["demo", "--out", arg(dir.path()), "-q"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let field = dir.path().join("bar.field");
    let r = common::deform(
        &dir.path().join("bar.ply"),
        &dir.path().join("o.ply"),
        &dir.path().join("bend.toml"),
        &["--save-field", arg(&field), "--cell-size", "0.25"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let t = info(&field);
    assert!(line(&t, "format:").contains("saved field, 3D"), "{t}");
    assert!(line(&t, "levels:").contains("cell sizes 0.25"), "{t}");
    assert!(line(&t, "transfer:").contains("pu"), "{t}");
    assert!(!t.contains("heights:"), "a bend moves heights: {t}");
    let cells: usize = line(&t, "cells:")[9..].trim().parse().unwrap();
    assert!(cells > 100, "{t}");
    assert!(line(&t, "bounds:").contains("x [-0.25, 10.25]"), "{t}");
    let png = dir.path().join("gingerbread.png");
    let t = info(&png);
    assert!(line(&t, "format:").contains("240 × 240"), "{t}");
    let raster = rigidcells::internal::image::Raster::read_png(&png).unwrap();
    let opaque = raster.rgba.chunks_exact(4).filter(|p| p[3] > 0).count();
    assert_eq!(
        line(&t, "foreground pixels:"),
        format!("  foreground pixels: {opaque}")
    );
    // The mean of the foreground pixels' centers, to the bounds' one decimal.
    let w = raster.width as usize;
    let (mut sum, mut n) = ([0.0f64; 2], 0usize);
    for (i, _) in raster
        .rgba
        .chunks_exact(4)
        .enumerate()
        .filter(|(_, p)| p[3] > 0)
    {
        sum[0] += (i % w) as f64 + 0.5;
        sum[1] += (i / w) as f64 + 0.5;
        n += 1;
    }
    let (cx, cy) = (sum[0] / n as f64, sum[1] / n as f64);
    assert_eq!(
        line(&t, "centroid:"),
        format!("  centroid: [{cx:.1}, {cy:.1}]")
    );
    assert_eq!(line(&t, "centroid:"), "  centroid: [120.0, 114.8]");
}

/// The mean of the first three numbers of each vertex line of an ASCII PLY whose first element
/// is `vertex`.
fn ascii_ply_vertex_mean(path: &std::path::Path) -> [f64; 3] {
    let text = std::fs::read_to_string(path).unwrap();
    let (header, body) = text.split_once("end_header\n").unwrap();
    let count: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let mut sum = [0.0f64; 3];
    for l in body.lines().take(count) {
        for (s, w) in sum.iter_mut().zip(l.split_whitespace()) {
            *s += w.parse::<f64>().unwrap();
        }
    }
    sum.map(|s| s / count as f64)
}

/// A LAS file rigidcells wrote names it, with this crate's version exactly, after the system
/// that made the input; its format line gives the LAS version and record layout of the input.
#[test]
fn a_written_las_names_rigidcells_and_its_version() {
    let dir = tempfile::tempdir().unwrap();
    let edit = autzen_lift(dir.path());
    let out = dir.path().join("o.laz");
    let r = common::deform(
        &shared("las/autzen_trim.laz"),
        &out,
        &edit,
        &["--cell-size", "20"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let t = info(&out);
    assert_eq!(
        line(&t, "format:"),
        "  format: LAZ 1.2, point data record format 3, 34 bytes per record"
    );
    assert_eq!(
        line(&t, "software:"),
        format!(
            "  software: PDAL / rigidcells {}",
            env!("CARGO_PKG_VERSION")
        )
    );
    assert_eq!(
        line(&info(&shared("las/autzen_trim.laz")), "software:"),
        "  software: PDAL / PDAL 1.0.0 (9e8465)"
    );
    let r = run(&["--version"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(
        r.stdout,
        format!("rigidcells {}\n", env!("CARGO_PKG_VERSION"))
    );
}

/// An edit of autzen written in `dir`: the west edge fixed, the east edge lifted by 5 m.
fn autzen_lift(dir: &std::path::Path) -> std::path::PathBuf {
    let edit = dir.join("lift.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [636000, 848900, 0], max = [636300, 849600, 1000] }\n\
         [[handle]]\nbox = { min = [636900, 848900, 0], max = [637200, 849600, 1000] }\n\
         translate = [0, 0, 5]\n",
    )
    .unwrap();
    edit
}

/// The decimals of every number in `text`.
fn decimals_in(text: &str) -> Vec<usize> {
    text.split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter(|w| w.contains('.') && w.starts_with(|c: char| c.is_ascii_digit()))
        .map(|w| w.split('.').nth(1).unwrap_or("").len())
        .collect()
}

/// A cell size chosen for `--cells`, a field's bounds and cell sizes print to a thousandth of
/// the finest cell, not to 17 digits.
#[test]
fn lengths_the_cells_decided_print_to_their_precision() {
    let dir = tempfile::tempdir().unwrap();
    let edit = autzen_lift(dir.path());
    let field = dir.path().join("lift.field");
    let r = common::deform_verbose(
        &shared("las/autzen_trim.las"),
        &dir.path().join("o.las"),
        &edit,
        &["--cells", "3000", "--save-field", arg(&field)],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let printed = format!("{}{}", r.stdout, r.stderr);
    let note = printed
        .lines()
        .find(|l| l.contains("finest cell size"))
        .unwrap_or_else(|| panic!("no note of the cell size in\n{}", r.stderr));
    let size: f64 = note.rsplit(' ').next().unwrap().parse().unwrap();
    assert!(size > 10.0 && size < 25.0, "{note}");
    // A cell of 10–25 resolves to 0.01–0.025: two decimals at most.
    assert!(decimals_in(note).iter().all(|&d| d <= 2), "{note}");
    let t = info(&field);
    for label in ["bounds:", "size:", "levels:", "largest cell motion:"] {
        let l = line(&t, label);
        assert!(decimals_in(l).iter().all(|&d| d <= 2), "{l}");
    }
}

/// A WKT is the file's text, not ours: a character of several bytes right before a keyword's
/// bracket (here `GEOGCS[` damaged into `GEOGé[`) is read past, not sliced through, and the
/// system is still named with its own code (and its vertical one, nested in it).
#[test]
fn a_damaged_wkt_is_read_without_slicing_a_character() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = std::fs::read(shared("las/test1_4.las")).unwrap();
    let at = bytes
        .windows(7)
        .position(|w| w == b"GEOGCS[")
        .expect("a WKT in the file");
    bytes[at..at + 6].copy_from_slice("GEOGé".as_bytes());
    let path = dir.path().join("damaged.las");
    std::fs::write(&path, bytes).unwrap();
    let t = info(&path);
    let crs = line(&t, "CRS:");
    assert!(
        crs.contains(
            "NAD83(HARN) / New Mexico Central (ftUS), EPSG:2903, vertical EPSG:5703 (from the WKT)"
        ),
        "{crs}"
    );
}
