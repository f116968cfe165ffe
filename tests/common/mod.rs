//! Helpers shared by the integration tests: run the CLI, find the shared data.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

use rigidcells::Vect;
use rigidcells::internal::io::{Chunk, LasHeader, LasSource, Source};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rigidcells"))
}

pub fn shared(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

/// The paths of a test's input and output files in `dir`, and of its `edit.toml`.
pub fn files(dir: &Path, input: &str, output: &str) -> (PathBuf, PathBuf, PathBuf) {
    (dir.join(input), dir.join(output), dir.join("edit.toml"))
}

/// The 10×1×1 bar (`per_unit` vertices per unit, binary PLY) in `dir` with an edit that fixes
/// its left end and lifts its right end by 1: the input, output and edit paths.
pub fn lifted_bar(dir: &Path, per_unit: f64) -> (PathBuf, PathBuf, PathBuf) {
    let (input, output, edit) = files(dir, "bar.ply", "out.ply");
    data_gen::write_ply(&input, &data_gen::bar([10.0, 1.0, 1.0], per_unit), true).unwrap();
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n\
         translate = [0, 0, 1]\n",
    )
    .unwrap();
    (input, output, edit)
}

#[derive(Debug)]
pub struct Run {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

pub fn run(args: &[&str]) -> Run {
    let out = bin().args(args).output().expect("run rigidcells");
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// `rigidcells deform INPUT -o OUTPUT --edit EDIT -q` plus `extra` arguments.
pub fn deform(input: &Path, output: &Path, edit: &Path, extra: &[&str]) -> Run {
    let mut args = vec!["-q"];
    args.extend_from_slice(extra);
    deform_verbose(input, output, edit, &args)
}

/// `rigidcells deform INPUT -o OUTPUT --edit EDIT` plus `extra` arguments (warnings printed).
pub fn deform_verbose(input: &Path, output: &Path, edit: &Path, extra: &[&str]) -> Run {
    let mut args = vec![
        "deform",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
        "--edit",
        edit.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

/// `rigidcells cells INPUT -o OUTPUT` plus `extra` arguments.
pub fn cells(input: &Path, output: &Path, extra: &[&str]) -> Run {
    let mut args = vec!["cells", arg(input), "-o", arg(output)];
    args.extend_from_slice(extra);
    run(&args)
}

/// A path as a command-line argument.
pub fn arg(path: &Path) -> &str {
    path.to_str().expect("a UTF-8 path")
}

/// All records of a LAS/LAZ file: its header, the raw record bytes, the decoded coordinates and
/// the record length.
pub fn records(path: &Path) -> (LasHeader, Vec<u8>, Vec<Vect<3>>, usize) {
    let mut src = LasSource::open(path).unwrap();
    let mut chunk = Chunk::default();
    let (mut raw, mut pos) = (Vec::new(), Vec::new());
    while src.read(100_000, &mut chunk).unwrap() > 0 {
        raw.extend_from_slice(&chunk.raw);
        pos.extend_from_slice(&chunk.positions);
    }
    (src.header().clone(), raw, pos, chunk.record_len)
}

/// `rigidcells deform` long enough to be stopped while it writes: a 1.5M-point terrain in `dir`
/// with its west end fixed and its east end lifted, through the RBF transfer, with a saved
/// field and a report. The running child (its stderr piped) and its output, field and report.
pub fn long_run(dir: &Path) -> (std::process::Child, [PathBuf; 3]) {
    let input = dir.join("terrain.las");
    data_gen::write_las_terrain(&input, 1_500_000, false).unwrap();
    let edit = dir.join("lift.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [499990, 4999990, 0], max = [500300, 5002010, 1000] }\n\
         [[handle]]\nbox = { min = [501700, 4999990, 0], max = [502010, 5002010, 1000] }\n\
         translate = [0, 0, 20]\n",
    )
    .unwrap();
    let out = dir.join("out.las");
    let field = dir.join("lift.field");
    let report = dir.join("lift.json");
    let child = bin()
        .args(["deform", arg(&input), "-o", arg(&out), "--edit", arg(&edit)])
        .args(["--cell-size", "40", "--transfer", "rbf", "-q"])
        .args(["--save-field", arg(&field), "--report", arg(&report)])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    (child, [out, field, report])
}

/// Waits, while `child` runs, until a file whose name starts with `prefix` is in `dir`.
pub fn wait_for_file(dir: &Path, child: &mut std::process::Child, prefix: &str) {
    let there = || {
        std::fs::read_dir(dir)
            .unwrap()
            .any(|e| e.unwrap().file_name().to_string_lossy().starts_with(prefix))
    };
    let started = std::time::Instant::now();
    while !there() {
        assert!(started.elapsed().as_secs() < 120, "no {prefix}* appeared");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run finished before {prefix}* appeared: give it more work"
        );
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
}
