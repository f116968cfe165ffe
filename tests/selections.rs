//! Selections that combine: classification AND a polygon, polygons from GeoJSON,
//! `invert` — run through the CLI on a real airborne scan, checked sample by sample.

mod common;

use common::{deform, shared};
use rigidcells::Vect;
use rigidcells::internal::io::{Chunk, LasSource, Source};
use rigidcells::internal::spec::Polygon;

/// Positions and classes of every record.
fn samples(path: &std::path::Path) -> (Vec<Vect<3>>, Vec<u8>) {
    let mut src = LasSource::open(path).unwrap();
    let mut chunk = Chunk::default();
    let (mut pos, mut classes) = (Vec::new(), Vec::new());
    while src.read_samples(100_000, &mut chunk).unwrap() > 0 {
        pos.extend_from_slice(&chunk.positions);
        classes.extend_from_slice(&chunk.classes);
    }
    (pos, classes)
}

const OUTER: [[f64; 2]; 5] = [
    [636300.0, 849000.0],
    [636900.0, 849000.0],
    [636950.0, 849250.0],
    [636700.0, 849420.0],
    [636300.0, 849400.0],
];
const INNER: [[f64; 2]; 4] = [
    [636500.0, 849120.0],
    [636700.0, 849120.0],
    [636700.0, 849280.0],
    [636500.0, 849280.0],
];

fn toml_ring(ring: &[[f64; 2]]) -> String {
    let v: Vec<String> = ring
        .iter()
        .map(|p| format!("[{}, {}]", p[0], p[1]))
        .collect();
    format!("[{}]", v.join(", "))
}

#[test]
fn ground_in_a_polygon_lifts_and_everything_outside_another_stays() {
    let dir = tempfile::tempdir().unwrap();
    let input = shared("las/autzen_trim.laz");
    // The outer area from a GeoJSON file (a FeatureCollection, as GIS tools write it).
    let ring: Vec<String> = OUTER
        .iter()
        .chain(&OUTER[..1])
        .map(|p| format!("[{}, {}]", p[0], p[1]))
        .collect();
    std::fs::write(
        dir.path().join("area.geojson"),
        format!(
            r#"{{"type": "FeatureCollection", "features": [{{"type": "Feature", "properties": {{}},
                "geometry": {{"type": "Polygon", "coordinates": [[{}]]}}}}]}}"#,
            ring.join(", ")
        ),
    )
    .unwrap();
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        format!(
            "[[fixed]]\npolygon_file = \"area.geojson\"\ninvert = true\n\n\
             [[handle]]\nclassification = [2]\npolygon = {}\nz = [300, 600]\ntranslate = [0, 0, 5]\n",
            toml_ring(&INNER)
        ),
    )
    .unwrap();
    let out = dir.path().join("o.laz");
    let r = deform(&input, &out, &edit, &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let (before, classes) = samples(&input);
    let (after, _) = samples(&out);
    let (outer, inner) = (
        Polygon::new(vec![OUTER.to_vec()], None),
        Polygon::new(vec![INNER.to_vec()], None),
    );
    let (mut still, mut lifted, mut other_inside) = (0, 0, 0);
    for ((b, a), c) in before.iter().zip(&after).zip(&classes) {
        if !outer.contains(b.x, b.y, None) {
            // Fixed: exactly where it was.
            assert_eq!(a, b);
            still += 1;
        } else if inner.contains(b.x, b.y, None) && *c == 2 {
            // The handle: lifted 5 m exactly (to the file's centimetres).
            assert!(
                (a - b - Vect::<3>::new(0.0, 0.0, 5.0)).amax() < 0.006,
                "{b} -> {a}"
            );
            lifted += 1;
        } else if inner.contains(b.x, b.y, None) {
            other_inside += 1;
        }
    }
    assert!(still > 10_000 && lifted > 500, "{still} {lifted}");
    // The polygon held other classes too; the classification kept them out of the handle.
    assert!(other_inside > 0, "{other_inside}");
}

#[test]
fn entries_combine_and_errors_say_why() {
    let dir = tempfile::tempdir().unwrap();
    let input = shared("las/autzen_trim.laz");
    let edit = dir.path().join("edit.toml");
    let out = dir.path().join("o.laz");
    let cases = [
        ("[[fixed]]\ninvert = true\n", "needs a region"),
        (
            "[[fixed]]\nz = [0, 1]\nbox = { min = [0, 0, 0], max = [1, 1, 1] }\n",
            "`z`",
        ),
        (
            "[[fixed]]\npolygon = [[0, 0], [1, 0]]\n",
            "at least 3 points",
        ),
        (
            "[[fixed]]\npolygon_file = \"none.geojson\"\n",
            "none.geojson",
        ),
        ("[[fixed]]\npolygon_file = \"bad.geojson\"\n", "bad.geojson"),
        // Indices past the samples, or not indices at all, in the spec's words with its line.
        (
            "[[fixed]]\nindices = [0, 99999999]\n",
            "edit.toml: line 2: `indices` lists sample 99999999, but the input has 110000 \
             samples, numbered 0 to 109999",
        ),
        (
            "[[fixed]]\nbox = { min = [0, 0, 0], max = [1, 1, 1] }\n[[handle]]\n\
             indices = \"ids.txt\"\ntranslate = [0, 0, 1]\n",
            "line 4: `indices` lists sample 110000,",
        ),
        (
            "[[fixed]]\nindices = [-1]\n",
            "line 2: `indices` lists -1: a sample index is a whole number, 0 or more",
        ),
    ];
    std::fs::write(dir.path().join("ids.txt"), "5, 109999\n110000\n").unwrap();
    std::fs::write(dir.path().join("bad.geojson"), "{\"type\": \"Point\"").unwrap();
    for (text, what) in cases {
        std::fs::write(&edit, text).unwrap();
        let r = deform(&input, &out, &edit, &[]);
        assert_eq!(r.code, 4, "{text}: {}", r.stderr);
        assert!(r.stderr.contains(what), "{text}: {}", r.stderr);
    }
    // A classification on an input without classes says so.
    let (bar, bar_out, _) = common::lifted_bar(dir.path(), 4.0);
    std::fs::write(
        &edit,
        "[[fixed]]\nclassification = [2]\nbox = { min = [-1, -1, -1], max = [1, 2, 2] }\n",
    )
    .unwrap();
    let r = deform(&bar, &bar_out, &edit, &[]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("LAS classes"), "{}", r.stderr);
}

/// Runs `deform` on autzen_trim under the spec `text` (in `dir`), expecting exit 4 and an error
/// that is exactly `error: edit.toml: …` as `want` gives it after the file's name.
fn refused(dir: &std::path::Path, name: &str, text: &str, want: &str) {
    let edit = dir.join(name);
    std::fs::write(&edit, text).unwrap();
    let r = deform(
        &shared("las/autzen_trim.laz"),
        &dir.join("o.laz"),
        &edit,
        &[],
    );
    assert_eq!(r.code, 4, "{text}: {}", r.stderr);
    let line = r.stderr.lines().find(|l| l.starts_with("error:"));
    let want = format!("error: {}: {want}", edit.display());
    assert_eq!(line, Some(want.as_str()), "{text}");
    assert!(!dir.join("o.laz").exists());
}

/// A bad element of an array written over many lines is named by its own line and its place in
/// the array, not by the line its key starts on.
#[test]
fn spec_errors_name_the_line_of_the_element() {
    let dir = tempfile::tempdir().unwrap();
    let fixed = "[[fixed]]\nbox = { min = [636000, 848900, 0], max = [636300, 849600, 1000] }\n";
    let ring = |bad: &str| {
        let mut points: Vec<String> = (0..9).map(|k| format!("  [{k}, {}],", k % 2)).collect();
        points[7] = format!("  {bad},");
        format!(
            "# parcels\n[[handle]]\ntranslate = [0, 0, 1]\npolygon = [\n{}\n]\n{fixed}",
            points.join("\n")
        )
    };
    // The 8th point sits on line 12.
    for (bad, want) in [
        (
            "[636100.5]",
            "line 12: `polygon` point 8 is [636100.5]: a point is [x, y], two finite numbers",
        ),
        (
            "\"a\"",
            "line 12: `polygon` point 8 is \"a\", not a list of numbers",
        ),
        (
            "[636100, nan]",
            "line 12: `polygon` point 8 holds nan, which is not finite",
        ),
        (
            "[636100, -inf]",
            "line 12: `polygon` point 8 holds -inf, which is not finite",
        ),
        (
            "[636100, \"849000\"]",
            "line 12: `polygon` point 8 holds \"849000\", which is not a number",
        ),
    ] {
        refused(dir.path(), "edit.toml", &ring(bad), want);
    }
    let matrix = |rows: [&str; 4]| {
        format!(
            "{fixed}[[handle]]\nbox = {{ min = [636900, 848900, 0], max = [637200, 849600, 1000] }}\n\
             matrix = [\n  {},\n]\n",
            rows.join(",\n  ")
        )
    };
    let id = [
        "[1, 0, 0, 0]",
        "[0, 1, 0, 0]",
        "[0, 0, 1, 0]",
        "[0, 0, 0, 1]",
    ];
    for (row, bad, want) in [
        (
            1,
            "[0, 1, 0]",
            "line 7: `matrix` row 2 has 3 numbers: `matrix` is 4 rows of 4 numbers",
        ),
        (
            2,
            "[0, 0, 1, 1e20]",
            "line 8: `matrix` reaches 1e20, beyond 1e15: a shape moved or scaled that far keeps \
             no detail in 64-bit floats, and the solve fails",
        ),
        (
            3,
            "[0, 0, 1, 1]",
            "line 9: `matrix` must be finite with last row [0 … 0 1], got [0, 0, 1, 1]",
        ),
    ] {
        let mut rows = id;
        rows[row] = bad;
        refused(dir.path(), "edit.toml", &matrix(rows), want);
    }
    refused(
        dir.path(),
        "edit.toml",
        &format!("{fixed}[[handle]]\ntranslate = [0, 0, 1]\nindices = [\n  1,\n  2,\n  -3,\n]\n"),
        "line 8: `indices` lists -3: a sample index is a whole number, 0 or more",
    );
    refused(
        dir.path(),
        "edit.toml",
        &format!("{fixed}[[handle]]\ntranslate = [0, 0, 1]\nclassification = [\n  2,\n  300,\n]\n"),
        "line 7: `classification` lists 300: a LAS class is a whole number 0 to 255",
    );
}

/// A bad position in a GeoJSON file is named by its feature (with its name or id), polygon,
/// ring and point, and the line where it starts.
#[test]
fn geojson_errors_name_the_feature_ring_and_point() {
    let dir = tempfile::tempdir().unwrap();
    let square = "[[636000, 848900], [636300, 848900], [636300, 849600], [636000, 848900]]";
    let write = |bad: &str| {
        let text = format!(
            "{{\"type\": \"FeatureCollection\", \"features\": [\n\
             {{\"type\": \"Feature\", \"properties\": {{\"name\": \"parcel 11\"}},\n\
              \"geometry\": {{\"type\": \"Polygon\", \"coordinates\": [{square}]}}}},\n\
             {{\"type\": \"Feature\", \"id\": 7,\n\
              \"geometry\": {{\"type\": \"MultiPolygon\", \"coordinates\": [[{square}], [\n\
             {square},\n\
             [[636100, 849000],\n\
              [636200, 849000],\n\
              {bad},\n\
              [636100, 849000]]]]}}}},\n\
             {{\"type\": \"Feature\", \"properties\": {{\"name\": \"parcel 12\"}},\n\
              \"geometry\": {{\"type\": \"Polygon\", \"coordinates\": [{square}, [\n\
              [636100, 849000],\n\
              {bad}]]}}}}\n\
             ]}}\n"
        );
        std::fs::write(dir.path().join("area.geojson"), text).unwrap();
    };
    let edit = "[[fixed]]\npolygon_file = \"area.geojson\"\n";
    let geojson = dir.path().join("area.geojson");
    let refused_geojson = |want: &str| {
        let path = dir.path().join("edit.toml");
        std::fs::write(&path, edit).unwrap();
        let r = deform(
            &shared("las/autzen_trim.laz"),
            &dir.path().join("o.laz"),
            &path,
            &[],
        );
        assert_eq!(r.code, 4, "{}", r.stderr);
        let line = r.stderr.lines().find(|l| l.starts_with("error:"));
        assert_eq!(
            line,
            Some(format!("error: {}: {want}", geojson.display()).as_str())
        );
    };
    write("[636200, \"849100\"]");
    refused_geojson(
        "line 9: feature 2 (id 7), polygon 2, ring 2, point 3: a position is two numbers, \
         not [636200,\"849100\"]",
    );
    write("[636200, 849100]");
    refused_geojson(
        "line 12: feature 3 (\"parcel 12\"), ring 2: a ring has 3 positions or more, this one 2",
    );
}
