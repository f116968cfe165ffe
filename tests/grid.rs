//! `rigidcells grid`: a saved field as a GeoTIFF of offsets that PROJ applies. A scan
//! rubber-sheeted onto control points, its field written as a grid and applied by PROJ
//! (pyproj's `+proj=gridshift`), lands where `rigidcells apply` puts it, to within the
//! deviation `grid` reports; bad parameters exit 4 and write nothing.

mod common;

use common::{Run, arg, records, run, shared};
use std::path::Path;

/// autzen_trim rubber-sheeted onto nine 3D control points that move it smoothly (a shift,
/// a stretch, and heights tilted and bent), its field saved as `f.field` in `dir`.
fn rubber_sheeted(dir: &Path) -> std::path::PathBuf {
    let scan = shared("las/autzen_trim.laz");
    let (_, _, rest, _) = records(&scan);
    let mut csv = String::from("id,x,y,z,X,Y,Z\n");
    for (k, x) in [636300.0, 636700.0, 637100.0].iter().enumerate() {
        for (j, y) in [849050.0, 849250.0, 849450.0].iter().enumerate() {
            // A point of the scan near (x, y), so that the control point lies on it.
            let p = rest
                .iter()
                .min_by(|a, b| {
                    let d = |p: &&rigidcells::internal::rigid::Vect<3>| (p.x - x).hypot(p.y - y);
                    d(a).total_cmp(&d(b))
                })
                .unwrap();
            let (u, v) = (k as f64 / 2.0, j as f64 / 2.0);
            csv += &format!(
                "P{k}{j},{},{},{},{},{},{}\n",
                p.x,
                p.y,
                p.z,
                p.x + 0.8 + 0.6 * u * v,
                p.y - 0.5 + 0.9 * u,
                p.z + 0.3 * u - 0.5 * v * v
            );
        }
    }
    std::fs::write(dir.join("gcp.csv"), csv).unwrap();
    let edit = dir.join("edit.toml");
    std::fs::write(&edit, "[[target]]\nfile = \"gcp.csv\"\n").unwrap();
    let field = dir.join("f.field");
    let r = common::deform(
        &scan,
        &dir.join("o.laz"),
        &edit,
        &["--save-field", arg(&field)],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    field
}

/// The figure after `label` on the deviation line of `text` (`… horizontal 0.012 at (…)`).
fn figure_after(text: &str, label: &str) -> f64 {
    let line = text
        .lines()
        .find(|l| l.starts_with("largest deviation"))
        .unwrap_or_else(|| panic!("no deviation in {text}"));
    let at = line.find(label).unwrap() + label.len();
    let figure = line[at..].split_whitespace().next().unwrap();
    figure.trim_end_matches(',').parse().unwrap()
}

/// A Python with pyproj: `$RIGIDCELLS_PYTHON` (CI's venv, which must have it) or `python3`;
/// `None`, said, where neither has it.
fn python_with_pyproj() -> Option<String> {
    let given = std::env::var("RIGIDCELLS_PYTHON").ok();
    let python = given.clone().unwrap_or_else(|| "python3".into());
    let has = std::process::Command::new(&python)
        .args(["-c", "import pyproj"])
        .status()
        .is_ok_and(|s| s.success());
    if !has {
        assert!(given.is_none(), "{python} lacks pyproj");
        eprintln!("note: no python with pyproj; PROJ's reading of the grid is not checked");
        return None;
    }
    Some(python)
}

/// Transforms the points of `input` (one `x y z` a line) through PROJ's `pipeline` into
/// `output` with pyproj.
fn proj(python: &str, pipeline: &str, input: &Path, output: &Path) -> Run {
    let script = "import sys\nfrom pyproj import Transformer\n\
        t = Transformer.from_pipeline(sys.argv[1])\n\
        xs, ys, zs = zip(*(map(float, l.split()) for l in open(sys.argv[2])))\n\
        out = t.transform(xs, ys, zs)\n\
        open(sys.argv[3], 'w').write(''.join(f'{x!r} {y!r} {z!r}\\n' for x, y, z in zip(*out)))\n";
    let out = std::process::Command::new(python)
        .args(["-c", script, pipeline, arg(input), arg(output)])
        .output()
        .unwrap();
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

#[test]
fn proj_moves_a_scan_as_apply_does_within_the_deviation() {
    let dir = tempfile::tempdir().unwrap();
    let field = rubber_sheeted(dir.path());
    let tif = dir.path().join("correction.tif");
    let r = run(&["grid", arg(&field), "-o", arg(&tif), "--spacing", "10"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let (horizontal, vertical) = (
        figure_after(&r.stdout, "horizontal "),
        figure_after(&r.stdout, "vertical "),
    );
    // The field is smooth: 10 ft between nodes gives it within a few hundredths.
    assert!(horizontal < 0.05 && vertical < 0.05, "{}", r.stdout);
    assert!(r.stdout.contains("+proj=gridshift +grids="), "{}", r.stdout);
    let applied = dir.path().join("a.laz");
    let a = run(&[
        "apply",
        arg(&field),
        arg(&shared("las/autzen_trim.laz")),
        "-o",
    ]
    .into_iter()
    .chain([arg(&applied), "-q"])
    .collect::<Vec<_>>());
    assert_eq!(a.code, 0, "{}", a.stderr);
    let Some(python) = python_with_pyproj() else {
        return;
    };
    let (_, _, rest, _) = records(&shared("las/autzen_trim.laz"));
    let (_, _, moved, _) = records(&applied);
    let picked: Vec<usize> = (0..rest.len()).step_by(37).collect();
    let points = dir.path().join("points.txt");
    let text: String = picked
        .iter()
        .map(|&k| format!("{} {} {}\n", rest[k].x, rest[k].y, rest[k].z))
        .collect();
    std::fs::write(&points, text).unwrap();
    let through = dir.path().join("proj.txt");
    let pipeline = format!("+proj=gridshift +grids={}", arg(&tif));
    let p = proj(&python, &pipeline, &points, &through);
    assert_eq!(p.code, 0, "{}{}", p.stdout, p.stderr);
    let (mut worst_h, mut worst_v, mut done, mut moved_most) = (0.0f64, 0.0f64, 0, 0.0f64);
    for (line, &k) in std::fs::read_to_string(&through)
        .unwrap()
        .lines()
        .zip(&picked)
    {
        let v: Vec<f64> = line
            .split_whitespace()
            .map(|s| s.parse().unwrap())
            .collect();
        if !v.iter().all(|c| c.is_finite()) {
            continue;
        }
        let (want, from) = (moved[k], rest[k]);
        worst_h = worst_h.max((v[0] - want.x).hypot(v[1] - want.y));
        worst_v = worst_v.max((v[2] - want.z).abs());
        moved_most = moved_most.max((want - from).norm());
        done += 1;
    }
    // PROJ took (nearly) every point: the grid covers the scan.
    assert!(
        done * 100 >= picked.len() * 99,
        "{done} of {}",
        picked.len()
    );
    // PROJ added the offsets forward (target minus source): the points moved a metre or more,
    // and they went where `apply` puts them, to within the reported deviation and the
    // stored offsets' and the records' rounding (a LAS step of 0.01).
    assert!(moved_most > 1.0, "{moved_most}");
    eprintln!(
        "{done} points: PROJ {worst_h} horizontally, {worst_v} vertically from apply; {}",
        r.stdout
            .lines()
            .find(|l| l.starts_with("largest deviation"))
            .unwrap()
    );
    let slack = 0.011;
    assert!(
        worst_h <= horizontal + slack && worst_v <= vertical + slack,
        "PROJ is {worst_h} horizontally and {worst_v} vertically from apply; the grid \
         reported {horizontal} and {vertical}"
    );
}

#[test]
fn bad_parameters_exit_4_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let field = rubber_sheeted(dir.path());
    let tif = dir.path().join("g.tif");
    for (args, says) in [
        (vec!["--spacing", "0"], "--spacing 0"),
        (vec!["--spacing=-1"], "--spacing -1"),
        (vec!["--extent", "1,2,3"], "--extent 1,2,3"),
        (vec!["--extent", "5,0,1,1"], "--extent 5,0,1,1"),
        (vec!["--epsg", "40000"], "--epsg 40000"),
        (vec!["--extent", "0,0,10,10"], "--extent"),
        (
            vec!["--spacing", "0.01", "--memory-limit", "64M"],
            "--spacing",
        ),
    ] {
        let mut all = vec!["grid", arg(&field), "-o", arg(&tif)];
        all.extend_from_slice(&args);
        let r = run(&all);
        assert_eq!(r.code, 4, "{args:?}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{args:?}: {}", r.stderr);
        assert!(!tif.exists(), "{args:?} wrote the grid");
    }
    let png = dir.path().join("g.png");
    let r = run(&["grid", arg(&field), "-o", arg(&png)]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("GeoTIFF"), "{}", r.stderr);
    let r = run(&["grid", arg(&dir.path().join("edit.toml")), "-o", arg(&tif)]);
    assert_eq!(r.code, 3, "{}", r.stderr);
}

/// The grid declares the system the field records: Topography.laz's EPSG:2949 without being
/// told, and an `--epsg` that contradicts it is refused; a field solved in longitude and
/// latitude has no east and north offsets to give.
#[test]
fn the_grid_declares_the_fields_system() {
    let dir = tempfile::tempdir().unwrap();
    let edit = dir.path().join("lift.toml");
    let field = dir.path().join("t.field");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [273300, 5274300, 700], max = [273450, 5274700, 900] }\n\
         [[handle]]\nbox = { min = [273550, 5274300, 700], max = [273700, 5274700, 900] }\n\
         translate = [0, 0, 1]\n",
    )
    .unwrap();
    let out = dir.path().join("t.laz");
    let r = run(&[
        "deform",
        arg(&shared("las/Topography.laz")),
        "-o",
        arg(&out),
        "--edit",
        arg(&edit),
        "--save-field",
        arg(&field),
        "-q",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let tif = dir.path().join("t.tif");
    let r = run(&["grid", arg(&field), "-o", arg(&tif), "--spacing", "20"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    // ProjectedCSTypeGeoKey (3072), in the key directory: no location, one value, 2949.
    let key: Vec<u8> = [3072u16, 0, 1, 2949]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let bytes = std::fs::read(&tif).unwrap();
    assert!(bytes.windows(8).any(|w| w == key), "no EPSG:2949 key");
    std::fs::remove_file(&tif).unwrap();
    let r = run(&["grid", arg(&field), "-o", arg(&tif), "--epsg", "2992"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(
        r.stderr.contains("--epsg 2992") && r.stderr.contains("EPSG:2949"),
        "{}",
        r.stderr
    );
    assert!(!tif.exists());

    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [-94.69, 31.03, 0], max = [-94.68, 31.05, 100] }\n\
         [[handle]]\nbox = { min = [-94.665, 31.03, 0], max = [-94.66, 31.05, 100] }\n\
         translate = [0, 0, 1]\n",
    )
    .unwrap();
    let r = run(&[
        "deform",
        arg(&shared("las/epsg_4326.las")),
        "-o",
        arg(&dir.path().join("d.las")),
        "--edit",
        arg(&edit),
        "--save-field",
        arg(&field),
        "-q",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let r = run(&["grid", arg(&field), "-o", arg(&tif)]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("longitude and latitude"), "{}", r.stderr);
    assert!(!tif.exists());
}
