//! Control points a surveyor can use: CSV/TXT formats, errors that name the CSV's
//! line and column, 2D points, snapping, the per-point table, RMSE and the leave-one-out check —
//! run through the CLI on a real airborne scan.

mod common;

use common::{Run, arg, deform_verbose, records, run, shared};
use std::path::Path;

fn autzen() -> std::path::PathBuf {
    shared("las/autzen_trim.laz")
}

/// Writes the control-point file `name` (`rows`) and an edit of one `[[target]]` naming it
/// (with the `extra` lines) into `dir`, deforms autzen_trim with `--report` and `args`, and
/// returns the run and its report (`Null` when the run failed).
fn gcp(dir: &Path, name: &str, rows: &str, extra: &str, args: &[&str]) -> (Run, serde_json::Value) {
    std::fs::write(dir.join(name), rows).unwrap();
    let edit = dir.join("edit.toml");
    std::fs::write(&edit, format!("[[target]]\nfile = \"{name}\"\n{extra}")).unwrap();
    let (out, json) = (dir.join("o.laz"), dir.join("r.json"));
    let _ = std::fs::remove_file(&json);
    let mut all = vec!["--report", json.to_str().unwrap()];
    all.extend_from_slice(args);
    let r = deform_verbose(&autzen(), &out, &edit, &all);
    let report = match r.code {
        0 => serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap(),
        _ => serde_json::Value::Null,
    };
    (r, report)
}

fn point<'a>(json: &'a serde_json::Value, id: &str) -> &'a serde_json::Value {
    json["control_points"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["id"] == id)
        .unwrap_or_else(|| panic!("no control point {id}: {json}"))
}

fn coords(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

#[test]
fn semicolon_file_with_header_ids_and_decimal_commas() {
    let dir = tempfile::tempdir().unwrap();
    // The points were given off the surface (up to 50 m above it): `snap` puts them on it.
    let (r, json) = gcp(
        dir.path(),
        "gcp.csv",
        "# surveyed, EPSG:2994\nid;x;y;z;X;Y;Z;weight\n\
         P1;636200,0;849000,0;420;636200,5;849000,0;420;10\n\
         P2;637000;849400;440;637000;849400,8;440;10\n\
         \"P3\";636600;849200;450;636600;849200;451,5;10\n",
        "snap = 60.0\n",
        &[],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r.stdout.contains("control points: 3"), "{}", r.stdout);
    assert!(r.stdout.contains("RMSE"), "{}", r.stdout);
    for id in ["P1", "P2", "P3"] {
        assert!(r.stdout.contains(&format!("  {id} ")), "{}", r.stdout);
    }
    let p3 = point(&json, "P3");
    assert_eq!(p3["place"], "gcp.csv line 5");
    // Snapped onto a sample: moved, and its wanted point kept.
    assert!(p3["snapped"].as_f64().unwrap() > 0.0);
    assert_eq!(coords(&p3["wanted"]), vec![636600.0, 849200.0, 451.5]);
    // Weight 10 against the glue: each lands within half a metre of where it was wanted,
    // and the residual is the distance the report gives between got and wanted.
    for id in ["P1", "P2", "P3"] {
        let p = point(&json, id);
        let (got, wanted) = (coords(&p["got"]), coords(&p["wanted"]));
        let d = got
            .iter()
            .zip(&wanted)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        assert!((d - p["residual"].as_f64().unwrap()).abs() < 1e-9, "{p}");
        assert!(d < 0.5, "{id}: {p}");
    }
    // The three points lie nearly on one line, and snapping moved them by 8–29 m: a trend
    // through them would fold the plane, so the cells carry them alone, and say so.
    assert!(
        r.stderr.contains("folds or collapses the plane"),
        "{}",
        r.stderr
    );
    let rmse = json["control_rmse"].as_f64().unwrap();
    assert!(rmse > 0.0 && rmse < 0.5, "{rmse}");
}

#[test]
fn separators_tab_spaces_and_comma_read_alike() {
    let dir = tempfile::tempdir().unwrap();
    let rows = [
        ["P1", "636200", "849000", "636201", "849000"],
        ["P2", "637000", "849400", "637000", "849401.5"],
        ["P3", "636600", "849200", "636600", "849200"],
    ];
    let mut results = Vec::new();
    for (name, sep) in [("tab.txt", "\t"), ("spaces.txt", "   "), ("comma.csv", ",")] {
        let text: String = rows.iter().map(|r| r.join(sep) + "\n").collect();
        let (r, json) = gcp(dir.path(), name, &text, "", &[]);
        assert_eq!(r.code, 0, "{name}: {}", r.stderr);
        results.push(json["control_points"].clone());
    }
    assert_eq!(results[0].as_array().unwrap().len(), 3);
    for other in &results[1..] {
        for (a, b) in results[0]
            .as_array()
            .unwrap()
            .iter()
            .zip(other.as_array().unwrap())
        {
            assert_eq!(
                (&a["id"], &a["from"], &a["got"]),
                (&b["id"], &b["from"], &b["got"])
            );
        }
    }
}

#[test]
fn two_d_points_pull_horizontally_and_keep_the_heights() {
    let dir = tempfile::tempdir().unwrap();
    let (r, json) = gcp(
        dir.path(),
        "gcp.txt",
        "P1 636200 849000 636201 849000\nP2 637000 849400 637000 849401.5\n\
         P3 636600 849200 636600 849200\n",
        "",
        &[],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    for id in ["P1", "P2", "P3"] {
        let p = point(&json, id);
        assert_eq!(p["horizontal"], true);
        let (from, got, wanted) = (coords(&p["from"]), coords(&p["got"]), coords(&p["wanted"]));
        // x and y as given; the height the nearest sample's.
        assert!(from[2] > 380.0 && from[2] < 530.0, "{p}");
        // Pulled horizontally; the height kept (it was free, not pulled up or down).
        assert!(p["residual"].as_f64().unwrap() < 0.15, "{p}");
        assert!((got[0] - wanted[0]).hypot(got[1] - wanted[1]) < 0.15, "{p}");
        assert_eq!(got[2], from[2], "{p}");
    }
}

/// 2D points say nothing of heights, so no height moves: every record's Z comes out as it went
/// in, from `deform` and from `apply` of the field it saved, while x and y follow the pull.
#[test]
fn two_d_points_move_no_height() {
    let dir = tempfile::tempdir().unwrap();
    let field = dir.path().join("f.field");
    let (r, _) = gcp(
        dir.path(),
        "gcp.csv",
        "id,x,y,X,Y\nP1,636200,849000,636201,849000\nP2,637000,849400,637000,849401.5\n\
         P3,636600,849200,636600,849200\n",
        "weight = 10\n",
        &["--save-field", arg(&field)],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let (_, _, rest, _) = records(&autzen());
    let (_, raw, moved, _) = records(&dir.path().join("o.laz"));
    assert_eq!(rest.len(), moved.len());
    let mut horizontal: f64 = 0.0;
    for (a, b) in rest.iter().zip(&moved) {
        assert_eq!(a.z, b.z, "{a:?} -> {b:?}");
        horizontal = horizontal.max((b.x - a.x).hypot(b.y - a.y));
    }
    assert!(horizontal > 0.5, "pulled {horizontal}");
    let applied = dir.path().join("a.laz");
    let applying = run(&[
        "apply",
        arg(&field),
        arg(&autzen()),
        "-o",
        arg(&applied),
        "-q",
    ]);
    assert_eq!(applying.code, 0, "{}", applying.stderr);
    assert!(records(&applied).1 == raw, "apply gives deform's records");
    let info = run(&["info", arg(&field)]);
    assert!(info.stdout.contains("heights: kept"), "{}", info.stdout);
}

/// The trend carries a scan onto its control points while a fixed area keeps its bytes: the
/// cells take the trend back there and blend into it beyond.
#[test]
fn a_fixed_area_keeps_its_bytes_under_the_trend() {
    let dir = tempfile::tempdir().unwrap();
    let mut csv = String::from("id,x,y,X,Y\n");
    for (k, x) in [636300.0, 636700.0, 637100.0].iter().enumerate() {
        for (j, y) in [849000.0, 849200.0, 849450.0].iter().enumerate() {
            // A shift east and a slight stretch north.
            csv += &format!(
                "P{k}{j},{x},{y},{},{}\n",
                x + 0.5,
                y + 1e-3 * (y - 849000.0)
            );
        }
    }
    let (r, json) = gcp(
        dir.path(),
        "gcp.csv",
        &csv,
        "weight = 10\n\n[[fixed]]\nbox = { min = [636000, 848900, 0], max = [636150, 849500, 1000] }\n",
        &[],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert_eq!(json["control_trend"], "spline", "{json}");
    let (_, _, rest, _) = records(&autzen());
    let (_, _, moved, _) = records(&dir.path().join("o.laz"));
    let (mut fixed, mut far, mut worst, mut sum) = (0, 0, 0.0f64, 0.0);
    for (a, b) in rest.iter().zip(&moved) {
        if a.x <= 636150.0 {
            assert_eq!(a, b, "a fixed sample moved");
            fixed += 1;
        } else if a.x > 636700.0 {
            let wanted = a.y + 1e-3 * (a.y - 849000.0);
            let off = (b.x - a.x - 0.5).hypot(b.y - wanted);
            (worst, sum, far) = (worst.max(off), sum + off, far + 1);
            assert_eq!(a.z, b.z);
        }
    }
    // Far from the fixed area, the trend's motion, but for what the cells give up to hold it
    // (they blend the fixed area into the trend across the scan: 7 cm at most, 2 cm on average).
    assert!(fixed > 1000 && far > 10_000, "{fixed} fixed, {far} far");
    assert!(
        worst < 0.1 && sum / (far as f64) < 0.03,
        "{worst}, {}",
        sum / far as f64
    );
    for p in json["control_points"].as_array().unwrap() {
        let residual = p["residual"].as_f64().unwrap();
        let x = p["from"][0].as_f64().unwrap();
        assert!(residual < if x > 637000.0 { 0.01 } else { 0.2 }, "{p}");
    }
}

/// Rows marked as checks are left out of the solve and scored apart: the output is the one
/// without them, and their RMSE and 95 % accuracy are those of their known errors.
#[test]
fn checkpoints_are_scored_not_solved_for() {
    let dir = tempfile::tempdir().unwrap();
    let mut csv = String::from("id,x,y,X,Y,type\n");
    for x in [636200.0, 636600.0, 637000.0] {
        for y in [849000.0, 849200.0, 849400.0] {
            csv += &format!("P{x}{y},{x},{y},{},{y},gcp\n", x + 0.5);
        }
    }
    let controls = csv.clone();
    // Each checkpoint wanted 1–4 cm off the shift: those are the errors scored.
    let checks = [
        (636400.0, 849100.0, 0.01, 0.0),
        (636800.0, 849300.0, -0.02, 0.04),
    ];
    for (k, (x, y, dx, dy)) in checks.iter().enumerate() {
        csv += &format!("C{k},{x},{y},{},{},check\n", x + 0.5 + dx, y + dy);
    }
    let extra = "weight = 10\n";
    let (r, json) = gcp(dir.path(), "gcp.csv", &csv, extra, &["--check-gcp"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let with = records(&dir.path().join("o.laz")).1;
    let a = &json["checkpoints"];
    assert_eq!(a["count"], 2, "{json}");
    let close = |key: &str, want: f64| {
        let got = a[key].as_f64().unwrap();
        assert!((got - want).abs() < 1e-3, "{key}: {got} vs {want}");
    };
    let (rx, ry) = ((0.0005f64 / 2.0).sqrt(), (0.0016f64 / 2.0).sqrt());
    close("rmse_x", rx);
    close("rmse_y", ry);
    close("rmse_r", rx.hypot(ry));
    close("accuracy_r_95", 1.7308 * rx.hypot(ry));
    assert!(
        a["rmse_z"].is_null() && a["accuracy_z_95"].is_null(),
        "2D checkpoints: {a}"
    );
    assert!(json["control_rmse"].as_f64().unwrap() < 1e-3, "{json}");
    assert!(point(&json, "C0")["left_out"].is_null() && point(&json, "C0")["check"] == true);
    assert!(
        r.stdout.contains("checkpoints: 2 (not solved for)"),
        "{}",
        r.stdout
    );
    let (r, _) = gcp(dir.path(), "gcp.csv", &controls, extra, &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        records(&dir.path().join("o.laz")).1 == with,
        "the checkpoints moved the scan"
    );
    // A type the file cannot mean is named with its line and column.
    let bad = controls + "C9,636400,849100,636400,849100,maybe\n";
    let (r, _) = gcp(dir.path(), "gcp.csv", &bad, extra, &[]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(
        r.stderr.contains("gcp.csv: line 11, column 6: `maybe`"),
        "{}",
        r.stderr
    );
}

#[test]
fn a_point_off_the_surface_needs_snap_and_errors_name_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.laz");
    let cases = [
        // 80 m above the highest sample: outside every cell, and the message says what to do.
        (
            "P1,636600,849200,600,636600,849200,600\n",
            "gcp.csv line 1",
            "snap",
        ),
        (
            "id,x,y,z,X,Y,Z\nP1,636600,849200,450,636600,849200,4x0\n",
            "gcp.csv: line 2, column 7",
            "`4x0`",
        ),
        (
            "id;x;y;z;X;Y;H\n",
            "gcp.csv: line 1, column 7",
            "unknown column `H`",
        ),
        (
            "P1;636600;849200;450;636600;849200;450\nP2;1;2;3\n",
            "gcp.csv: line 2",
            "4 columns",
        ),
        ("1,2,3\n", "gcp.csv: line 1", "3 columns"),
    ];
    for (text, place, what) in cases {
        let (r, _) = gcp(dir.path(), "gcp.csv", text, "", &[]);
        assert_eq!(r.code, 4, "{text}: {}", r.stderr);
        assert!(
            r.stderr.contains(place) && r.stderr.contains(what),
            "{text}: {}",
            r.stderr
        );
        assert_eq!(r.stderr.lines().count(), 1, "{}", r.stderr);
        assert!(!out.exists());
    }
    // With `snap`, the point 80 m up moves onto the scan; too short a snap says so.
    let high = "P1,636600,849200,600,636600,849200,600\n";
    let (r, _) = gcp(dir.path(), "gcp.csv", high, "snap = 5.0\n", &[]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("no sample within 5"), "{}", r.stderr);
    let (r, json) = gcp(dir.path(), "gcp.csv", high, "snap = 200.0\n", &[]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let p = point(&json, "P1").clone();
    assert!(p["snapped"].as_f64().unwrap() > 70.0, "{p}");
}

#[test]
fn leave_one_out_finds_the_blunder() {
    let dir = tempfile::tempdir().unwrap();
    // A 3×3 grid of 2D points 200 m apart agrees on a 0.5 m shift east; P5, in the middle,
    // says 6 m north as well.
    let mut csv = String::from("id,x,y,X,Y\n");
    let mut k = 0;
    for x in [636200.0, 636600.0, 637000.0] {
        for y in [849000.0, 849200.0, 849400.0] {
            k += 1;
            let north = if k == 5 { 6.0 } else { 0.0 };
            csv += &format!("P{k},{x},{y},{},{}\n", x + 0.5, y + north);
        }
    }
    // The default trend, a spline through every point: no residual says anything, the others
    // predict P5 6 m off, and each other point closer.
    let (r, json) = gcp(
        dir.path(),
        "gcp.csv",
        &csv,
        "weight = 10\n",
        &["--check-gcp"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(json["control_rmse"].as_f64().unwrap() < 1e-3, "{json}");
    let left_out =
        |json: &serde_json::Value, id: &str| point(json, id)["left_out"].as_f64().unwrap();
    let blunder = left_out(&json, "P5");
    assert!((blunder - 6.0).abs() < 0.01, "{blunder}");
    for k in [1, 2, 3, 4, 6, 7, 8, 9] {
        let id = format!("P{k}");
        assert!(
            left_out(&json, &id) < blunder,
            "{id}: {}",
            left_out(&json, &id)
        );
    }
    // An affine trend and the cells alone spread the blunder less: each other point is
    // predicted well within P5's error (its neighbours, pulled by P5 when they are left out,
    // the least well).
    for trend in ["affine", "none"] {
        std::fs::write(
            dir.path().join("edit.toml"),
            format!("trend = \"{trend}\"\n[[target]]\nfile = \"gcp.csv\"\nweight = 10\n"),
        )
        .unwrap();
        let (out, report) = (dir.path().join("o.laz"), dir.path().join("t.json"));
        let args = ["--check-gcp", "--report", arg(&report)];
        let r = deform_verbose(&autzen(), &out, &dir.path().join("edit.toml"), &args);
        assert_eq!(r.code, 0, "{trend}: {}", r.stderr);
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let blunder = left_out(&json, "P5");
        assert!(blunder > 5.5, "{trend}: {blunder}");
        for k in [1, 2, 3, 4, 6, 7, 8, 9] {
            let id = format!("P{k}");
            let other = left_out(&json, &id);
            assert!(other < 0.7 * blunder, "{trend}, {id}: {other} vs {blunder}");
        }
    }
    assert!(json["control_rmse_left_out"].as_f64().unwrap() > 1.0);
    // The nine solves of the check are a stage of their own, not the transfer's.
    let timings = &json["timings_s"];
    let check = timings["check_gcp"].as_f64().unwrap();
    assert!(check > 0.0, "{timings}");
    assert!(
        r.stdout
            .contains(&format!("leave-one-out check {check:.2} s")),
        "{}",
        r.stdout
    );
    let transfer = timings["transfer"].as_f64().unwrap();
    let total = timings["total"].as_f64().unwrap();
    assert!(transfer + check <= total, "{timings}");
}

/// `exact = true` pins each control point's cell: under an affine trend, which cannot carry a
/// local bump, the soft points keep centimetres of residual where the exact ones land on their
/// destinations — measured, like every residual of a file, on the output's coordinates as
/// written (autzen's scale is 0.01), and the table says so.
#[test]
fn exact_control_points_land_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let mut csv = String::from("id,x,y,X,Y\n");
    for (k, x) in [636300.0, 636650.0, 637000.0].iter().enumerate() {
        for (j, y) in [849000.0, 849200.0, 849400.0].iter().enumerate() {
            // A shift, and a bump of 0.3 m at the middle point that no affine map holds.
            let bump = if (k, j) == (1, 1) { 0.3 } else { 0.0 };
            csv += &format!("P{k}{j},{x},{y},{},{}\n", x + 0.2 + bump, y - 0.1);
        }
    }
    let extra = "weight = 10\n";
    let soft = format!("trend = \"affine\"\n[[target]]\nfile = \"gcp.csv\"\n{extra}");
    std::fs::write(dir.path().join("gcp.csv"), &csv).unwrap();
    let edit = dir.path().join("soft.toml");
    std::fs::write(&edit, &soft).unwrap();
    let json_path = dir.path().join("soft.json");
    let out = dir.path().join("o.laz");
    let r = deform_verbose(
        &autzen(),
        &out,
        &edit,
        &["--report", json_path.to_str().unwrap()],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    let bumped = point(&json, "P11")["residual"].as_f64().unwrap();
    assert!(
        bumped > 0.02,
        "a soft point under an affine trend: {bumped}"
    );

    let edit = dir.path().join("exact.toml");
    std::fs::write(
        &edit,
        soft.replace(extra, &format!("{extra}exact = true\n")),
    )
    .unwrap();
    let json_path = dir.path().join("exact.json");
    let r = deform_verbose(
        &autzen(),
        &out,
        &edit,
        &["--report", json_path.to_str().unwrap(), "--check-gcp"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    assert_eq!(
        json["control_rounding"], "the output's scale 0.01",
        "{json}"
    );
    assert!(
        r.stdout
            .contains("residuals as written, to the output's scale 0.01"),
        "{}",
        r.stdout
    );
    for p in json["control_points"].as_array().unwrap() {
        assert_eq!(p["exact"], true, "{p}");
        // On the output's grid of 0.01 (offset 0), within half a step of where it is wanted.
        let got = coords(&p["got"]);
        for g in &got {
            assert!(((g * 100.0).round() - g * 100.0).abs() < 1e-6, "{p}");
        }
        assert!(
            p["residual"].as_f64().unwrap() <= 0.005 * 2f64.sqrt() + 1e-9,
            "{p}"
        );
        // The others predict it: the bumped point worst.
        assert!(p["left_out"].as_f64().is_some(), "{p}");
    }
    assert!(r.stdout.contains(" 2D exact"), "{}", r.stdout);
    let worst = json["control_points"]
        .as_array()
        .unwrap()
        .iter()
        .max_by(|a, b| {
            a["left_out"]
                .as_f64()
                .partial_cmp(&b["left_out"].as_f64())
                .unwrap()
        })
        .unwrap();
    assert_eq!(worst["id"], "P11", "{json}");

    // An exact point inside a fixed area is a contradiction, named with its file and line.
    std::fs::write(
        &edit,
        soft.replace(extra, &format!("{extra}exact = true\n"))
            + "[[fixed]]\nbox = { min = [636200, 848900, 0], max = [636400, 849100, 1000] }\n",
    )
    .unwrap();
    let r = deform_verbose(&autzen(), &out, &edit, &[]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("exact control point P00 (gcp.csv line 2)"),
        "{}",
        r.stderr
    );
}

/// A trend that cannot be undone where the points go (an affine map that flattens the scan
/// onto a line) is not used, and the run says so rather than solving against it.
#[test]
fn a_trend_that_folds_is_dropped_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let mut csv = String::from("id,x,y,X,Y\n");
    for (k, (x, y)) in [
        (636300.0, 849000.0),
        (637000.0, 849000.0),
        (636650.0, 849400.0),
    ]
    .iter()
    .enumerate()
    {
        csv += &format!("P{k},{x},{y},{x},849000\n");
    }
    let (r, json) = gcp(dir.path(), "gcp.csv", &csv, "", &[]);
    let edit = dir.path().join("edit.toml");
    let text = std::fs::read_to_string(&edit).unwrap();
    std::fs::write(&edit, format!("trend = \"affine\"\n{text}")).unwrap();
    let _ = (r, json);
    let json_path = dir.path().join("r.json");
    let r = deform_verbose(
        &autzen(),
        &dir.path().join("o.laz"),
        &edit,
        &["--report", json_path.to_str().unwrap()],
    );
    assert!(
        r.stderr
            .contains("trend \"affine\" folds or collapses the plane")
            && r.stderr.contains("no trend is used"),
        "{}",
        r.stderr
    );
    if r.code == 0 {
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
        assert!(json["control_trend"].is_null(), "{json}");
    }
}
