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
    // 1,512 cells: the dense RBF needs about 18 MiB; the solver 6 MiB before anything is built,
    // then its sparse factor 20.5 MiB, known exactly from the symbolic analysis.
    refused("10M", &["--transfer", "rbf"], &["RBF", "--transfer pu"]);
    refused("5M", &["--transfer", "blend"], &["solving 1512 cells"]);
    refused(
        "16M",
        &["--transfer", "blend", "--solver", "direct"],
        &["factoring the solver's system of 1512 cells", "--cell-size"],
    );
    // The default solver falls back to the multilevel one (12 KB a cell, 17.7 MiB) where the
    // factor does not fit, and says so in the report; below that, both are refused.
    refused(
        "16M",
        &["--transfer", "blend"],
        &["solving 1512 cells by the multilevel solver", "--cell-size"],
    );
    let report = dir.path().join("r.json");
    let r = deform(
        &input,
        &out,
        &spec,
        &[
            "--cell-size",
            "0.25",
            "--memory-limit",
            "19M",
            "--transfer",
            "blend",
            "--report",
            arg(&report),
        ],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let text = std::fs::read_to_string(&report).unwrap();
    assert!(text.contains(r#""linear_solver": "multilevel""#), "{text}");
    std::fs::remove_file(&out).unwrap();
    // Refinement that would outgrow the budget names its threshold.
    refused(
        "60M",
        &["--transfer", "blend", "--refine-strain", "1e-9"],
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
