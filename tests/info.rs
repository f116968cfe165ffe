//! `rigidcells info` for every format (issue 17): counts, bounds and centroid, coordinates to
//! the file's precision, the CRS by name and EPSG code, record fields, a field's cells and
//! levels, a picture's foreground.

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
    assert!(
        line(&t, "centroid:").starts_with("  centroid: [-0.02"),
        "{t}"
    );
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
    assert!(line(&t, "centroid:").contains("[2, 3.2]"), "{t}");
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
    let cells: usize = line(&t, "cells:")[9..].trim().parse().unwrap();
    assert!(cells > 100, "{t}");
    assert!(line(&t, "bounds:").contains("x [-0.25, 10.25]"), "{t}");
    let png = dir.path().join("gingerbread.png");
    let t = info(&png);
    assert!(line(&t, "format:").contains("240 × 240"), "{t}");
    let raster = rigidcells::image::Raster::read_png(&png).unwrap();
    let opaque = raster.rgba.chunks_exact(4).filter(|p| p[3] > 0).count();
    assert_eq!(
        line(&t, "foreground pixels:"),
        format!("  foreground pixels: {opaque}")
    );
    assert!(line(&t, "centroid:").contains('['), "{t}");
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
    let edit = dir.path().join("lift.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [636000, 848900, 0], max = [636300, 849600, 1000] }\n\
         [[handle]]\nbox = { min = [636900, 848900, 0], max = [637200, 849600, 1000] }\n\
         translate = [0, 0, 5]\n",
    )
    .unwrap();
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
