//! The memory budget: what would not fit is refused before it is allocated, with an
//! error naming the parameter to change, never an allocation abort.

mod common;

use common::{arg, deform, run};

/// A line of 257 points 443 units long (a long thin input).
fn line(dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("line.xyz");
    let text: String = (0..257)
        .map(|i| {
            let t = i as f64;
            format!("{t} {t} {t}\n")
        })
        .collect();
    std::fs::write(&path, text).unwrap();
    path
}

/// The line and an edit fixing its first cells.
fn fixed_line(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let spec = edit(
        dir,
        "[[fixed]]\nbox = { min = [-1, -1, -1], max = [10, 10, 10] }\n",
    );
    (line(dir), spec)
}

fn edit(dir: &std::path::Path, text: &str) -> std::path::PathBuf {
    let path = dir.join("edit.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_tiny_cell_size_on_a_long_thin_input_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let (input, spec) = fixed_line(dir.path());
    let out = dir.path().join("out.xyz");
    let start = std::time::Instant::now();
    // Past what a cell's coordinates can hold.
    let r = deform(&input, &out, &spec, &["--cell-size", "0.00001"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("--cell-size"), "{}", r.stderr);
    assert!(!out.exists());
    // A triangle 1 km across at 1 cm cells: its candidate cells are counted before they are
    // enumerated, and refused.
    let soup = dir.path().join("big.obj");
    std::fs::write(&soup, "v 0 0 0\nv 1000 0 0\nv 0 1000 1\nf 1 2 3\n").unwrap();
    let out_obj = dir.path().join("out.obj");
    let r = deform(&soup, &out_obj, &spec, &["--cell-size", "0.01"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(
        r.stderr.contains("rasterizing") && r.stderr.contains("--cell-size"),
        "{}",
        r.stderr
    );
    assert!(!out_obj.exists());
    // Both answers come at once (generous for a debug build on a busy machine).
    assert!(
        start.elapsed().as_secs_f64() < 10.0,
        "{:?}",
        start.elapsed()
    );
}

/// The cells' memory goes with the occupied cells, not with the bounding box: the
/// line at 0.5 (a dense grid of 1024³ finest cells before) and at 0.01 runs in a 64 MB budget.
#[test]
fn a_long_thin_input_costs_memory_by_its_cells() {
    let dir = tempfile::tempdir().unwrap();
    let (input, spec) = fixed_line(dir.path());
    for size in ["0.5", "0.01"] {
        let out = dir.path().join(format!("out{size}.xyz"));
        let r = deform(
            &input,
            &out,
            &spec,
            &["--cell-size", size, "--memory-limit", "64M"],
        );
        assert_eq!(r.code, 0, "{size}: {}", r.stderr);
        assert_eq!(
            std::fs::read_to_string(&out).unwrap().lines().count(),
            257,
            "{size}"
        );
    }
}

#[test]
fn the_rbf_and_the_solver_are_refused_before_they_allocate() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bar.ply");
    data_gen::write_ply(&input, &data_gen::bar([10.0, 1.0, 1.0], 8.0), true).unwrap();
    let spec = edit(
        dir.path(),
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n\
         translate = [0, 0, 2]\n",
    );
    let out = dir.path().join("out.ply");
    // `--cell-size 0.25 --memory-limit LIMIT` and `extra` are refused (exit 4, no output) with
    // a message holding each of `needles`.
    let refused = |limit: &str, extra: &[&str], needles: &[&str]| {
        let args = [&["--cell-size", "0.25", "--memory-limit", limit][..], extra].concat();
        let r = deform(&input, &out, &spec, &args);
        assert_eq!(r.code, 4, "{extra:?}: {}", r.stderr);
        for needle in needles {
            assert!(r.stderr.contains(needle), "{extra:?}: {}", r.stderr);
        }
        assert!(!out.exists());
    };
    // 1,512 cells: the dense RBF needs about 18 MiB; any solver 8.7 MiB at least, known from
    // the cells' forecast before they are built, then the direct path's sparse factor
    // 20.8 MiB, known exactly from the symbolic analysis.
    refused("10M", &["--transfer", "rbf"], &["RBF", "--transfer pu"]);
    refused(
        "5M",
        &["--transfer", "blend"],
        &["solving about 1,512 cells of size 0.25", "--cell-size"],
    );
    refused(
        "17M",
        &["--transfer", "blend", "--solver", "direct"],
        &["factoring the solver's system of 1512 cells", "--cell-size"],
    );
    // The default solver starts with local-global iterations, which need no factor of the
    // motions' system: where neither Gauss-Newton's factor (19.7 MiB with the pattern) nor
    // its multilevel path (19.2 MiB) fits, it keeps to them, and the report says so; with
    // room for the multilevel path it may take either.
    let report = dir.path().join("r.json");
    for (limit, solvers) in [
        ("10M", &["local-global"][..]),
        ("19.5M", &["local-global", "multilevel"][..]),
    ] {
        let r = deform(
            &input,
            &out,
            &spec,
            &[
                "--cell-size",
                "0.25",
                "--memory-limit",
                limit,
                "--transfer",
                "blend",
                "--report",
                arg(&report),
            ],
        );
        assert_eq!(r.code, 0, "{limit}: {}", r.stderr);
        let text = std::fs::read_to_string(&report).unwrap();
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();
        let solver = json["linear_solver"].as_str().unwrap();
        assert!(solvers.contains(&solver), "{limit}: {solver}");
        std::fs::remove_file(&out).unwrap();
    }
    // Refinement whose factor would outgrow the budget names its threshold (local-global
    // iterations, needing no factor of the motions' system, fit it).
    refused(
        "60M",
        &[
            "--transfer",
            "blend",
            "--refine-strain",
            "1e-9",
            "--solver",
            "direct",
        ],
        &["--refine-strain"],
    );
    // With room, the same run works.
    let r = deform(
        &input,
        &out,
        &spec,
        &["--cell-size", "0.25", "--memory-limit", "1G"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    // A size that is not one is a command-line error.
    let r = run(&[
        "deform",
        arg(&input),
        "-o",
        arg(&out),
        "--edit",
        arg(&spec),
        "--memory-limit",
        "lots",
    ]);
    assert_eq!(r.code, 2, "{}", r.stderr);
}

/// The 10 × 1 × 1 bar fixed at one end and turned at the other (the README's bend) in `dir`:
/// its input (8 vertices a unit), output and edit paths.
fn turned_bar(
    dir: &std::path::Path,
) -> (std::path::PathBuf, std::path::PathBuf, std::path::PathBuf) {
    let input = dir.join("bar.ply");
    data_gen::write_ply(&input, &data_gen::bar([10.0, 1.0, 1.0], 8.0), true).unwrap();
    let spec = edit(
        dir,
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n\
         rotate = { axis = [0.0, 1.0, 0.0], degrees = -90.0 }\ntranslate = [-3.4, 0.0, 5.9]\n",
    );
    (input, dir.join("out.ply"), spec)
}

/// Cells that no solver path fits in the budget are refused from their forecast, once the
/// occupied cells are known and before the empty space is classified or a cell is made: the
/// bar at 0.005 (5.4 million cells, some 30 GiB) under 16 GiB, and at 0.02 (216,016 cells)
/// under 1 GiB, which the per-cell checks had let through its coarse stages to the cells'
/// own factorization (the refusal came after a build of 216,016 cells and the coarse solves).
/// The forecast's words ("solving about N cells of size S") say where it stopped.
#[test]
fn cells_no_solver_fits_are_refused_before_they_are_built() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out, spec) = turned_bar(dir.path());
    for (size, limit, cells) in [("0.005", "16G", "5,4"), ("0.02", "1G", "21")] {
        let start = std::time::Instant::now();
        let r = deform(
            &input,
            &out,
            &spec,
            &["--cell-size", size, "--memory-limit", limit],
        );
        assert_eq!(r.code, 4, "{size}: {}", r.stderr);
        let about = format!("solving about {cells}");
        for needle in [&about[..], size, "--cell-size", "--memory-limit"] {
            assert!(r.stderr.contains(needle), "{size}: {needle}: {}", r.stderr);
        }
        assert!(!out.exists());
        // Seconds in a debug build on a busy machine: the classification of the bar's 10M
        // blocks alone takes a minute at 0.005 (release).
        let took = start.elapsed().as_secs_f64();
        assert!(took < 30.0, "{size}: {took} s");
    }
}

/// A solve expected to take longer than 10 seconds is announced on stderr before it starts,
/// with its cells, time and memory; a short one is not.
#[test]
fn a_long_solve_is_announced_before_it_starts() {
    use std::io::{BufRead, BufReader};
    let dir = tempfile::tempdir().unwrap();
    let (input, out, spec) = turned_bar(dir.path());
    // 47,816 cells: some 40 s of solve (release).
    let mut child = common::bin()
        .args(["deform", arg(&input), "-o", arg(&out), "--edit", arg(&spec)])
        .args(["--cell-size", "0.05", "--memory-limit", "8G"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let line = BufReader::new(stderr)
        .lines()
        .map(|l| l.unwrap())
        .find(|l| l.contains("the solve:"));
    child.kill().unwrap();
    child.wait().unwrap();
    let line = line.expect("no announcement");
    assert!(
        line.contains("about 47,816 cells") && line.contains("GiB"),
        "{line}"
    );
    // 1,512 cells: under a second.
    let r = deform(&input, &out, &spec, &["--cell-size", "0.25"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(!r.stderr.contains("the solve:"), "{}", r.stderr);
}

/// `pipeline::estimate` counts the cells a deformation makes (it builds them), and its
/// estimate is of the solve's path and fits the budget the run fits; cells it refuses to
/// build are forecast within 3 % of those a build makes.
#[test]
fn the_estimate_counts_the_cells_of_a_run() {
    use rigidcells::internal::estimate::Solver;
    use rigidcells::internal::pipeline::{self, Options};
    use rigidcells::internal::rigid::Vect;
    use rigidcells::internal::solve::IterationMethod;
    let bar = data_gen::bar([10.0, 1.0, 1.0], 8.0);
    let points: Vec<Vect<3>> = bar.vertices.iter().map(|&v| Vect::<3>::from(v)).collect();
    let spec = rigidcells::internal::spec::parse_spec::<3>(
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n\
         translate = [0, 0, 1]\n",
        std::path::Path::new("."),
        std::path::Path::new("edit.toml"),
    )
    .unwrap();
    let params = |size: f64, limit: Option<u64>| {
        Options {
            cell_size: Some(size),
            memory_limit: limit,
            ..Default::default()
        }
        .params()
        .unwrap()
    };
    let at = params(0.25, None);
    let e = pipeline::estimate(&points, &bar.triangles, &[], &spec, &at).unwrap();
    let silent = rigidcells::internal::progress::Silent;
    let (_, solution, info) =
        pipeline::deform(&points, &bar.triangles, &spec, &at, &silent).unwrap();
    assert_eq!(e.cells, solution.complex.len());
    assert!(e.complete && e.fits(), "{e:?}");
    assert_eq!(info.solver.estimate.map(|s| s.cells), Some(e.cells));
    // Where Gauss-Newton's system does not fit, `auto` keeps to local-global iterations: the
    // estimate is of them, fits, and holds the run's peak.
    let lean = params(0.25, Some(10 << 20));
    let e = pipeline::estimate(&points, &bar.triangles, &[], &spec, &lean).unwrap();
    assert!(e.fits() && e.solver == Solver::LocalGlobal, "{e:?}");
    let (_, _, info) = pipeline::deform(&points, &bar.triangles, &spec, &lean, &silent).unwrap();
    assert!(info.solver.log.iter().all(|l| matches!(
        l.method,
        IterationMethod::LocalGlobal | IterationMethod::Anderson
    )));
    // At 0.05 in 100 MiB: refused, forecast and not built.
    let tight = params(0.05, Some(100 << 20));
    let e = pipeline::estimate(&points, &bar.triangles, &[], &spec, &tight).unwrap();
    assert!(!e.complete && !e.fits(), "{e:?}");
    let built = rigidcells::internal::cells::build(
        &points,
        &bar.triangles,
        tight.build(),
        rigidcells::internal::memory::Budget::default(),
    )
    .unwrap()
    .0
    .len();
    let off = e.cells as f64 / built as f64 - 1.0;
    assert!(off.abs() < 0.03, "forecast {} against {built}", e.cells);
}
