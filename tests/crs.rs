//! Coordinate reference systems as the user sees them: `info`'s CRS and unit lines on real
//! scans and on a saved field, `solve` refusing tiles in two systems and `apply` a field of
//! another system (exit 4, both systems named) unless `--same-crs`, a GeoJSON's `crs` checked
//! against the scan's, and a polygon outside the scan's bounds (lon/lat on a projected scan)
//! refused in plain words.

mod common;

use std::path::{Path, PathBuf};

use common::{arg, run, shared};

fn line<'a>(text: &'a str, key: &str) -> &'a str {
    text.lines()
        .find(|l| l.trim_start().starts_with(key))
        .unwrap_or_else(|| panic!("no `{key}` in\n{text}"))
}

fn info(path: &Path) -> String {
    let r = run(&["info", arg(path)]);
    assert_eq!(r.code, 0, "{}: {}", path.display(), r.stderr);
    r.stdout
}

/// A copy of autzen_trim.las in `dir` whose WKT names another system (the same length, so
/// the file stays valid): a scan in a second system with the same points.
fn autzen_renamed(dir: &Path) -> PathBuf {
    let mut bytes = std::fs::read(shared("las/autzen_trim.las")).unwrap();
    let from = b"NAD_1983_HARN_Lambert_Conformal_Conic";
    let to = b"NAD_1983_HARN_Lambert_Conformal_Conix";
    // The WKT's name, and the GeoTIFF citation's copy of it.
    let mut found = 0;
    for at in 0..bytes.len() - from.len() {
        if &bytes[at..at + from.len()] == from {
            bytes[at..at + from.len()].copy_from_slice(to);
            found += 1;
        }
    }
    assert!(found > 0, "the WKT's name");
    let path = dir.join("autzen_other.las");
    std::fs::write(&path, bytes).unwrap();
    path
}

/// An edit of autzen: its west end fixed, its east end lifted by 2.
fn autzen_edit(dir: &Path) -> PathBuf {
    let edit = dir.join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [636000, 848900, 400], max = [636300, 849500, 530] }\n\
         [[handle]]\nbox = { min = [636900, 848900, 400], max = [637200, 849500, 530] }\n\
         translate = [0, 0, 2]\n",
    )
    .unwrap();
    edit
}

#[test]
fn info_says_the_linear_unit_and_where_it_was_read() {
    for (file, unit) in [
        // The keys name EPSG:2229 and no unit; the code's definition is in US survey feet.
        (
            "certainty3d-color-utm-feet-navd88.las",
            "unit: US survey foot (from EPSG:2229's definition; the keys state none)",
        ),
        ("1_4_w_evlr.las", "unit: US survey foot (from the WKT)"),
        ("autzen_trim.las", "unit: international foot (from the WKT)"),
        ("v1.2_pdrf2.las", "unit: metre (from the GeoTIFF keys)"),
        ("epsg_4326.las", "unit: degree (from the GeoTIFF keys)"),
        ("32-1-472-150-76.laz", "unit: metre (from the GeoTIFF keys)"),
        (
            "Topography.laz",
            "unit: metre (from EPSG:2949's definition; the keys state none)",
        ),
        // A compound WKT: metres across, US survey feet up.
        (
            "1.2-with-color.copc.laz",
            "unit: metre (from the WKT); heights: US survey foot",
        ),
    ] {
        let t = info(&shared(&format!("las/{file}")));
        assert_eq!(line(&t, "unit:").trim(), unit, "{file}:\n{t}");
    }
    let t = info(&shared("las/certainty3d-color-utm-feet-navd88.las"));
    assert!(line(&t, "CRS:").ends_with("(from the GeoTIFF keys)"), "{t}");
    let t = info(&shared("las/1.2-with-color.copc.laz"));
    assert!(
        line(&t, "CRS:").contains("EPSG:2991, vertical EPSG:6360 (from the WKT)"),
        "{t}"
    );
}

#[test]
fn solve_refuses_tiles_in_different_systems_unless_told_they_are_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let field = dir.path().join("f.field");
    let edit = autzen_edit(dir.path());
    // Two real scans, EPSG:2903 and EPSG:26915: refused before any pass, nothing written.
    let (a, b) = (shared("las/1_4_w_evlr.las"), shared("las/v1.2_pdrf2.las"));
    let r = run(&[
        "solve",
        arg(&a),
        arg(&b),
        "--edit",
        arg(&edit),
        "--save-field",
        arg(&field),
    ]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    let e = &r.stderr;
    assert!(e.contains("the tiles' coordinate systems differ"), "{e}");
    assert!(
        e.contains(&format!(
            "EPSG:2903 (NAD83(HARN) / New Mexico Central (ftUS)) in {}",
            a.display()
        )),
        "{e}"
    );
    assert!(
        e.contains(&format!(
            "EPSG:26915 (NAD83 / UTM zone 15N) in {}",
            b.display()
        )),
        "{e}"
    );
    assert!(e.contains("--same-crs"), "{e}");
    assert!(!field.exists());
    // Two WKTs without codes that differ: refused; with --same-crs, solved, the field
    // recording the first tile's system.
    let (a, b) = (shared("las/autzen_trim.las"), autzen_renamed(dir.path()));
    let solve = |extra: &[&str]| {
        let mut args = vec![
            "solve",
            arg(&a),
            arg(&b),
            "--edit",
            arg(&edit),
            "--save-field",
            arg(&field),
            "--cells",
            "1500",
            "-q",
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let r = solve(&[]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(
        r.stderr.contains("Conic in") && r.stderr.contains("Conix in"),
        "{}",
        r.stderr
    );
    let r = solve(&["--same-crs"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let t = info(&field);
    assert!(
        line(&t, "CRS:").contains("NAD_1983_HARN_Lambert_Conformal_Conic (from the WKT)"),
        "{t}"
    );
    assert_eq!(
        line(&t, "unit:").trim(),
        "unit: international foot (from the WKT)"
    );
}

#[test]
fn apply_refuses_a_field_of_another_system_unless_told_they_are_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let (field, out) = (dir.path().join("a.field"), dir.path().join("out.las"));
    let autzen = shared("las/autzen_trim.las");
    let r = common::deform(
        &autzen,
        &dir.path().join("deformed.las"),
        &autzen_edit(dir.path()),
        &["--cells", "1500", "--save-field", arg(&field)],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let apply = |input: &Path, extra: &[&str]| {
        let mut args = vec!["apply", arg(&field), arg(input), "-o", arg(&out)];
        args.extend_from_slice(extra);
        run(&args)
    };
    // A real scan in EPSG:2903: refused before the pass, naming both systems.
    let other = shared("las/1_4_w_evlr.las");
    let r = apply(&other, &[]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    let e = &r.stderr;
    assert!(
        e.contains("the field's coordinate system differs from the input's"),
        "{e}"
    );
    assert!(
        e.contains(&format!(
            "NAD_1983_HARN_Lambert_Conformal_Conic in {}",
            field.display()
        )),
        "{e}"
    );
    assert!(
        e.contains(&format!(
            "EPSG:2903 (NAD83(HARN) / New Mexico Central (ftUS)) in {}",
            other.display()
        )),
        "{e}"
    );
    assert!(!out.exists());
    // The same points under another WKT: refused, then let through by --same-crs with the
    // same moved points as on the original.
    let renamed = autzen_renamed(dir.path());
    assert_eq!(apply(&renamed, &[]).code, 4);
    let r = apply(&renamed, &["--same-crs", "-q"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let moved = common::records(&out).2;
    assert_eq!(apply(&autzen, &["-q"]).code, 0);
    assert_eq!(moved, common::records(&out).2);
    // A scan that declares no system: applied, with a warning that says so.
    let r = apply(&shared("las/extrabytes.las"), &["--outside", "keep"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("extrabytes.las declares no coordinate system"),
        "{}",
        r.stderr
    );
}

/// A GeoJSON polygon over 1_4_w_evlr.las (EPSG:2903), its `crs` naming `crs`.
fn geojson(dir: &Path, crs: &str) -> PathBuf {
    let member = match crs {
        "" => String::new(),
        c => format!(r#""crs": {{"type": "name", "properties": {{"name": "{c}"}}}}, "#),
    };
    let path = dir.join("area.geojson");
    std::fs::write(
        &path,
        format!(
            r#"{{"type": "FeatureCollection", {member}"features": [{{"type": "Feature",
            "properties": {{}}, "geometry": {{"type": "Polygon", "coordinates": [[
            [1694400, 1816490], [1694600, 1816490], [1694600, 1816500], [1694400, 1816500]]]}}}}]}}"#
        ),
    )
    .unwrap();
    let edit = dir.join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [1694000, 1816490, 5500], max = [1694150, 1816500, 5700] }\n\
         [[handle]]\npolygon_file = \"area.geojson\"\ntranslate = [0, 0, 1]\n",
    )
    .unwrap();
    path
}

#[test]
fn a_geojson_crs_is_honoured_when_it_is_the_scans_and_refused_when_not() {
    let dir = tempfile::tempdir().unwrap();
    let (scan, out, edit) = (
        shared("las/1_4_w_evlr.las"),
        dir.path().join("out.las"),
        dir.path().join("edit.toml"),
    );
    for name in ["urn:ogc:def:crs:EPSG::2903", "EPSG:2903", ""] {
        geojson(dir.path(), name);
        let r = common::deform(&scan, &out, &edit, &["--cells", "500"]);
        assert_eq!(r.code, 0, "{name}: {}", r.stderr);
    }
    let area = geojson(dir.path(), "urn:ogc:def:crs:EPSG::26915");
    let r = common::deform(&scan, &out, &edit, &["--cells", "500"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    let e = &r.stderr;
    assert!(
        e.contains("the polygon's coordinate system differs from the scan's"),
        "{e}"
    );
    assert!(
        e.contains(&format!(
            "EPSG:26915 (urn:ogc:def:crs:EPSG::26915) in {}",
            area.display()
        )),
        "{e}"
    );
    assert!(
        e.contains(&format!(
            "EPSG:2903 (NAD83(HARN) / New Mexico Central (ftUS)) in {}",
            scan.display()
        )),
        "{e}"
    );
    // A `crs` this cannot read is the GeoJSON's error.
    geojson(dir.path(), "WGS84");
    let r = common::deform(&scan, &out, &edit, &["--cells", "500"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(
        r.stderr.contains("area.geojson: its `crs` names \"WGS84\""),
        "{}",
        r.stderr
    );
}

#[test]
fn a_polygon_outside_the_scan_is_refused_in_plain_words() {
    let dir = tempfile::tempdir().unwrap();
    let (scan, out) = (shared("las/autzen_trim.las"), dir.path().join("out.las"));
    // Lon/lat degrees of the Autzen stadium, as a GeoJSON exported without reprojection.
    std::fs::write(
        dir.path().join("lonlat.geojson"),
        r#"{"type": "Polygon", "coordinates": [[[-123.075, 44.05], [-123.06, 44.05],
            [-123.06, 44.06], [-123.075, 44.06]]]}"#,
    )
    .unwrap();
    let edit = dir.path().join("edit.toml");
    // A handle outside (which otherwise moved nothing, silently) and a fixed polygon outside.
    for (spec, line) in [
        "[[fixed]]\nbox = { min = [636000, 848900, 400], max = [636300, 849500, 530] }\n\
         [[handle]]\npolygon_file = \"lonlat.geojson\"\ntranslate = [0, 0, 2]\n",
        "[[fixed]]\npolygon = [[-123.075, 44.05], [-123.06, 44.05], [-123.06, 44.06]]\n\
         [[handle]]\nbox = { min = [636900, 848900, 400], max = [637200, 849500, 530] }\n\
         translate = [0, 0, 2]\n",
    ]
    .into_iter()
    .zip([3, 1])
    {
        std::fs::write(&edit, spec).unwrap();
        let r = common::deform(&scan, &out, &edit, &["--cells", "1500"]);
        assert_eq!(r.code, 4, "{}", r.stderr);
        let e = &r.stderr;
        assert!(e.contains(&format!("line {line}: the polygon")), "{e}");
        assert!(e.contains("lies outside the scan's bounds"), "{e}");
        assert!(
            e.contains("it spans x [-123.075, -123.06], y [44.05, 44.06]"),
            "{e}"
        );
        assert!(
            e.contains("spans x [636002, 637179], y [848935, 849498]"),
            "{e}"
        );
        assert!(
            e.contains("look like longitude and latitude in degrees"),
            "{e}"
        );
        assert!(e.contains("in international feet"), "{e}");
        assert!(!out.exists());
    }
    // A polygon beside the scan, in its own coordinates, says nothing of degrees.
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [636000, 848900, 400], max = [636300, 849500, 530] }\n\
         [[handle]]\npolygon = [[640000, 848900], [641000, 848900], [641000, 849500]]\n\
         translate = [0, 0, 2]\n",
    )
    .unwrap();
    let r = common::deform(&scan, &out, &edit, &["--cells", "1500"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(
        r.stderr.contains("lies outside the scan's bounds"),
        "{}",
        r.stderr
    );
    assert!(!r.stderr.contains("degrees"), "{}", r.stderr);
}
