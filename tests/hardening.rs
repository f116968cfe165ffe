//! Errors said once with the user's path, the exit-code contract for edit specs, parameters
//! and malformed inputs, outputs that collide, interrupted runs, and field files that cannot
//! be trusted. Each case is a minimal reproducer: the command, its exit code, its message, and
//! nothing written.

mod common;

use std::path::{Path, PathBuf};

use common::{arg, deform, run};

/// The 10×1×1 bar, a bend of it, and a field saved from it (PU, format 3).
fn bar(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let (input, output, edit) = common::lifted_bar(dir, 8.0);
    let field = dir.join("bar.field");
    let r = deform(
        &input,
        &output,
        &edit,
        &["--cell-size", "0.5", "--save-field", arg(&field)],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    std::fs::remove_file(&output).unwrap();
    (input, edit, field)
}

/// `edit.toml` in `dir`: the x range `x[0]..x[1]` fixed, `x[2]..x[3]` lifted by 20, over the
/// y range `y` (a scan's two ends).
fn lift_spec(dir: &Path, x: [f64; 4], y: [f64; 2]) -> PathBuf {
    let edit = dir.join("edit.toml");
    let region = |a: f64, b: f64| {
        format!(
            "box = {{ min = [{a}, {}, 0], max = [{b}, {}, 1000] }}\n",
            y[0], y[1]
        )
    };
    std::fs::write(
        &edit,
        format!(
            "[[fixed]]\n{}[[handle]]\n{}translate = [0, 0, 20]\n",
            region(x[0], x[1]),
            region(x[2], x[3])
        ),
    )
    .unwrap();
    edit
}

#[test]
fn an_os_error_is_said_once_with_the_users_path() {
    let dir = tempfile::tempdir().unwrap();
    let (_, edit, _) = bar(dir.path());
    let missing = dir.path().join("missing.las");
    let r = deform(&missing, &dir.path().join("o.las"), &edit, &[]);
    assert_eq!(r.code, 3, "{}", r.stderr);
    assert!(r.stderr.contains("missing.las"), "{}", r.stderr);
    assert_eq!(r.stderr.matches("os error 2").count(), 1, "{}", r.stderr);
}

#[test]
fn edit_spec_problems_exit_4() {
    let dir = tempfile::tempdir().unwrap();
    let (input, _, _) = bar(dir.path());
    let out = dir.path().join("o.ply");
    // A target CSV the spec names whose row is not 6 or 7 numbers (the fuzz harness's
    // `1,2` and `nan,0,0,0,0,0`) is the spec's problem too.
    std::fs::write(dir.path().join("short.csv"), "1,2\n").unwrap();
    std::fs::write(dir.path().join("nan.csv"), "nan,0,0,0,0,0\n").unwrap();
    // A motion past 1e15 (the fuzz harness's `translate = [1e308, …]`) was a solver failure,
    // exit 1: the spec asks what 64-bit floats cannot hold.
    let far = b"[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
                [[handle]]\nbox = { min = [0, 0, 0], max = [0, 0, 0] }\ntranslate = [1e308, 0, 0]\n";
    let huge = b"[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
                 [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\nscale = 1e300\n";
    let cases: [(&str, &[u8]); 7] = [
        ("far.toml", far),
        ("huge.toml", huge),
        ("missing.toml", b""),
        ("latin1.toml", b"# caf\xe9\n[[fixed]]\n"),
        ("csv.toml", b"[[target]]\nfile = \"nowhere.csv\"\n"),
        ("short.toml", b"[[target]]\nfile = \"short.csv\"\n"),
        ("nan.toml", b"[[target]]\nfile = \"nan.csv\"\n"),
    ];
    for (name, text) in cases {
        let spec = dir.path().join(name);
        if !text.is_empty() {
            std::fs::write(&spec, text).unwrap();
        }
        let r = deform(&input, &out, &spec, &[]);
        assert_eq!(r.code, 4, "{name}: {}", r.stderr);
        assert_eq!(r.stderr.lines().count(), 1, "{name}: {}", r.stderr);
        assert!(!out.exists(), "{name}");
    }
}

#[test]
fn cells_0_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, _) = bar(dir.path());
    let out = dir.path().join("o.ply");
    let r = deform(&input, &out, &edit, &["--cells", "0"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("--cells 0"), "{}", r.stderr);
    assert!(!out.exists());
}

/// `--cells 2⁶⁴−1` (and 2³² + 1) had the size search build ever finer trial grids for minutes
/// until an allocation aborted: refused at once against the memory budget, naming `--cells`.
#[test]
fn a_huge_cells_target_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, _) = bar(dir.path());
    let out = dir.path().join("o.ply");
    for n in ["18446744073709551615", "4294967297"] {
        let started = std::time::Instant::now();
        let r = deform(&input, &out, &edit, &["--cells", n]);
        assert!(
            started.elapsed().as_secs() < 10,
            "--cells {n}: took too long"
        );
        assert_eq!(r.code, 4, "--cells {n}: {}", r.stderr);
        assert!(r.stderr.contains("--cells"), "{}", r.stderr);
        let r = common::cells(&input, &dir.path().join("c.ply"), &["--cells", n]);
        assert_eq!(r.code, 4, "cells --cells {n}: {}", r.stderr);
    }
    assert!(!out.exists());
}

/// Four samples cannot fill 400 cells: the size search built ever finer grids of millions of
/// empty blocks (20 s on a damaged LAS of four points, 9 s here); trial grids past the target
/// are now counted as too many unbuilt, and the shortfall is said.
#[test]
fn a_cells_target_the_shape_cannot_reach_is_said_quickly() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("four.xyz");
    std::fs::write(&input, "0 1 1\n0 4 4\n0 1 4\n0 4 1\n").unwrap();
    let out = dir.path().join("cells.ply");
    let started = std::time::Instant::now();
    let r = run(&["cells", arg(&input), "-o", arg(&out), "--cells", "400"]);
    assert!(started.elapsed().as_secs() < 5, "took too long");
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r.stderr.contains("gives only 4 cells"), "{}", r.stderr);
}

/// The build's estimate covers the complex it hands on: at 160 B per occupied cell a soup at
/// `--min-cell-size` 1 mm passed a 1.5 GB budget and peaked at 2.3 GB (an abort under
/// `ulimit -v`). Here a build of 210,016 occupied cells (the bar at 2 cm, two layers on each
/// face) is refused under 100 MB before it starts.
#[test]
fn the_cell_build_is_refused_when_its_complex_would_not_fit() {
    let dir = tempfile::tempdir().unwrap();
    let (input, _, _) = bar(dir.path());
    let out = dir.path().join("cells.ply");
    let r = common::cells(
        &input,
        &out,
        &["--cell-size", "0.02", "--memory-limit", "100M"],
    );
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("occupied finest cells"), "{}", r.stderr);
    assert!(r.stderr.contains("--cell-size"), "{}", r.stderr);
    assert!(!out.exists());
    // Without the limit it builds, and has the cells the old estimate passed under 100 MB.
    let r = common::cells(&input, &out, &["--cell-size", "0.02"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let boundary: usize = r
        .stdout
        .split(" cells (")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no count in {}", r.stdout));
    assert!(
        boundary * 160 < 100 << 20 && boundary * 1024 > 100 << 20,
        "{boundary}"
    );
}

#[test]
fn outputs_that_name_the_same_file_are_refused_before_work() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, _) = bar(dir.path());
    let out = dir.path().join("o.ply");
    let same = dir.path().join(".").join("o.ply");
    let field = dir.path().join("f.field");
    for extra in [
        vec!["--report", arg(&same)],
        vec!["--save-field", arg(&out)],
        vec!["--save-field", arg(&field), "--report", arg(&field)],
    ] {
        let r = deform(&input, &out, &edit, &extra);
        assert_eq!(r.code, 4, "{extra:?}: {}", r.stderr);
        assert!(r.stderr.contains("name the same file"), "{}", r.stderr);
        assert!(!out.exists() && !field.exists(), "{extra:?}");
    }
}

/// An output of another format than the input's is refused before any work: here a memory
/// limit that the first estimate of any work would exceed is not what the run reports, and
/// nothing is written (the writer's own refusal came after the solve: 11.7 s on a scan).
#[test]
fn an_output_of_another_format_is_refused_before_work() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, field) = bar(dir.path());
    for name in ["o.las", "o.xyz", "o.copc.laz"] {
        let out = dir.path().join(name);
        let r = deform(&input, &out, &edit, &["--memory-limit", "1K"]);
        assert_eq!(r.code, 4, "{name}: {}", r.stderr);
        assert!(
            r.stderr
                .contains("the output must have the input's format (.ply)"),
            "{name}: {}",
            r.stderr
        );
        assert!(!r.stderr.contains("memory limit"), "{name}: {}", r.stderr);
        assert!(!out.exists(), "{name}");
        let r = run(&["apply", arg(&field), arg(&input), "-o", arg(&out)]);
        assert_eq!(r.code, 4, "{name}: {}", r.stderr);
        assert!(
            r.stderr.contains("the input's format (.ply)"),
            "{name}: {}",
            r.stderr
        );
        assert!(!out.exists(), "{name}");
    }
    let las = common::shared("las/autzen_trim.laz");
    let out = dir.path().join("o.ply");
    let r = deform(&las, &out, &edit, &["--memory-limit", "1K"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(
        r.stderr.contains("the input's format (.las or .laz)"),
        "{}",
        r.stderr
    );
}

/// Fewer octree levels than the default make the largest cells smaller than the shape, and
/// the inside takes as many of them as the box holds: `cells --max-level 1 --cell-size 1e-3`
/// on a 4 × 1 × 1 bar wrote 3.5M cells in 32 s. Their count is known before any sample is
/// read, and a run past the budget is refused at once, naming `--max-level`.
#[test]
fn few_levels_over_a_large_box_are_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bar.ply");
    data_gen::write_ply(&input, &data_gen::bar([4.0, 1.0, 1.0], 3.0), true).unwrap();
    let out = dir.path().join("cells.ply");
    let started = std::time::Instant::now();
    let r = common::cells(
        &input,
        &out,
        &[
            "--max-level",
            "1",
            "--cell-size",
            "1e-3",
            "--memory-limit",
            "3G",
        ],
    );
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("--max-level"), "{}", r.stderr);
    assert!(started.elapsed().as_secs() < 5, "took too long");
    assert!(!out.exists());
}

/// A saved field with one number replaced, at `at` bytes past the first cell's record.
fn damaged(field: &Path, at: usize, value: f64, out: &Path) {
    let mut bytes = std::fs::read(field).unwrap();
    // magic 8, version 4, dimension 4, transfer 1, origin 24, cell count 8.
    let first = 8 + 4 + 4 + 1 + 24 + 8;
    bytes[first + at..first + at + 8].copy_from_slice(&value.to_le_bytes());
    std::fs::write(out, bytes).unwrap();
}

#[test]
fn field_files_that_cannot_be_trusted_are_format_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (input, _, field) = bar(dir.path());
    let out = dir.path().join("o.ply");
    // The first cell's record: center (3), half-size, rotation (9, row-major), position (3).
    let cases = [
        ("a NaN center", 0, f64::NAN),
        ("a zero half-size", 24, 0.0),
        ("an infinite half-size", 24, f64::INFINITY),
        ("a rotation that is not one", 32, 2.0),
        ("a NaN position", 8 * 13, f64::NAN),
        // Past 1e15, as no spec motion can reach (a −1.8e308 made the RBF singular, exit 1).
        ("a huge position", 8 * 13, 1e308),
    ];
    for (what, at, value) in cases {
        let bad = dir.path().join("bad.field");
        damaged(&field, at, value, &bad);
        let started = std::time::Instant::now();
        let r = run(&["apply", arg(&bad), arg(&input), "-o", arg(&out), "-q"]);
        assert!(started.elapsed().as_secs() < 20, "{what}: took too long");
        let code = r.code;
        assert_eq!(code, 3, "{what}: {}", r.stderr);
        assert!(r.stderr.contains("bad.field"), "{what}: {}", r.stderr);
        assert!(!out.exists(), "{what}");
    }
}

#[test]
fn an_output_that_cannot_be_written_exits_1_naming_the_users_path() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, field) = bar(dir.path());
    let out = dir.path().join("no such folder").join("out.ply");
    // Refused before any work: a memory limit that any work would exceed is not what is said.
    for r in [
        deform(
            &input,
            &out,
            &edit,
            &["--cell-size", "0.5", "--memory-limit", "1K"],
        ),
        run(&["apply", arg(&field), arg(&input), "-o", arg(&out), "-q"]),
    ] {
        assert_eq!(r.code, 1, "{}", r.stderr);
        assert!(r.stderr.contains("out.ply: cannot write"), "{}", r.stderr);
        assert!(!r.stderr.contains(".out.ply."), "{}", r.stderr);
        assert_eq!(r.stderr.matches("os error").count(), 1, "{}", r.stderr);
    }
}

/// SIGINT while the output is being written removes the temporary output, and the field the
/// run saved before it, and exits 130: a run leaves all its files or none.
#[cfg(unix)]
#[test]
fn an_interrupted_run_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    let (mut child, [out, field, report]) = common::long_run(dir.path());
    let temporary = || {
        std::fs::read_dir(dir.path())
            .unwrap()
            .any(|e| e.unwrap().file_name().to_string_lossy().ends_with(".tmp"))
    };
    // Wait for the temporary output to appear, then interrupt.
    common::wait_for_file(dir.path(), &mut child, ".out.las.");
    let kill = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait().unwrap();
    assert_eq!(
        status.code(),
        Some(130),
        "the run did not end by the signal (exit 0: it finished first; give it more work)"
    );
    assert!(!temporary(), "the temporary output was left behind");
    assert!(!out.exists());
    assert!(!field.exists(), "the field of an interrupted run was left");
    assert!(!report.exists());
}

/// An output that fails at the end (the preview's folder does not exist) takes the run's other
/// outputs with it: the deformed file, its field and its report were complete, and are gone.
#[test]
fn a_failed_output_takes_the_runs_other_outputs_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out, edit) = common::lifted_bar(dir.path(), 4.0);
    let field = dir.path().join("bar.field");
    let report = dir.path().join("bar.json");
    let preview = dir.path().join("missing").join("bar.png");
    let r = deform(
        &input,
        &out,
        &edit,
        &[
            "--save-field",
            arg(&field),
            "--report",
            arg(&report),
            "--preview",
            arg(&preview),
        ],
    );
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(r.stderr.contains("bar.png"), "{}", r.stderr);
    for path in [&out, &field, &report, &preview] {
        assert!(!path.exists(), "{} was left", path.display());
    }
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left.len(), 2, "{left:?}");
}

/// CRC-32 (PNG's), bit by bit.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A PNG whose header claims 2³¹ − 1 rows (with a valid checksum) is refused before anything
/// is allocated for it, with the budget's message, not an abort.
#[test]
fn a_png_claiming_huge_dimensions_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("huge.png");
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend_from_slice(&64u32.to_be_bytes());
    ihdr.extend_from_slice(&0x7fff_ffffu32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]); // 8-bit RGBA
    let mut bytes = b"\x89PNG\r\n\x1a\n".to_vec();
    bytes.extend_from_slice(&13u32.to_be_bytes());
    bytes.extend_from_slice(&ihdr);
    bytes.extend_from_slice(&crc32(&ihdr).to_be_bytes());
    for (kind, data) in [
        (&b"IDAT"[..], &[0x78u8, 0x9c, 0x03, 0x00][..]),
        (b"IEND", &[]),
    ] {
        let mut chunk = kind.to_vec();
        chunk.extend_from_slice(data);
        bytes.extend_from_slice(&(data.len() as u32).to_be_bytes());
        bytes.extend_from_slice(&chunk);
        bytes.extend_from_slice(&crc32(&chunk).to_be_bytes());
    }
    std::fs::write(&png, &bytes).unwrap();
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [0, 0], max = [10, 10] }\n\
         [[handle]]\nbox = { min = [50, 0], max = [64, 10] }\ntranslate = [0, 5]\n",
    )
    .unwrap();
    let out = dir.path().join("out.png");
    let started = std::time::Instant::now();
    let r = run(&[
        "image",
        arg(&png),
        "--edit",
        arg(&edit),
        "-o",
        arg(&out),
        "-q",
    ]);
    assert!(started.elapsed().as_secs() < 20);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("huge.png"), "{}", r.stderr);
    assert!(r.stderr.contains("memory limit"), "{}", r.stderr);
    assert!(!out.exists());
}

/// A LAZ whose header's record length disagrees with its LAZ items made `laz`'s parallel
/// decompressor panic (exit 101): now a format error naming the file, without a panic message.
#[test]
fn a_laz_whose_record_length_disagrees_with_its_items_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = std::fs::read(common::shared("las/autzen_trim.laz")).unwrap();
    let len = u16::from_le_bytes([bytes[105], bytes[106]]);
    bytes[105..107].copy_from_slice(&(len + 2).to_le_bytes());
    let input = dir.path().join("bad.laz");
    std::fs::write(&input, bytes).unwrap();
    let edit = lift_spec(
        dir.path(),
        [636000.0, 636300.0, 636900.0, 637200.0],
        [848900.0, 849600.0],
    );
    let out = dir.path().join("out.laz");
    let r = deform(&input, &out, &edit, &[]);
    assert_eq!(r.code, 3, "{}", r.stderr);
    assert!(r.stderr.contains("bad.laz"), "{}", r.stderr);
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    assert!(!out.exists());
}

/// A write that fails for lack of room (a file-size limit standing for a full disk) exits 1
/// naming the output, and leaves neither the output nor its temporary.
#[cfg(unix)]
#[test]
fn a_full_disk_exits_1_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, _) = bar(dir.path());
    let out = dir.path().join("out.ply");
    // 1 block of 512 bytes: the bar's PLY (about 10 KB) does not fit.
    let r = std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -f 1; exec '{}' deform '{}' -o '{}' --edit '{}' --cell-size 0.5 -q",
            env!("CARGO_BIN_EXE_rigidcells"),
            arg(&input),
            arg(&out),
            arg(&edit)
        ))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("out.ply: cannot write"), "{stderr}");
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("out.ply"))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// A saved RBF whose frame (one over the cells' half extent) was damaged to 5e-324 made every
/// sample NaN, and `apply` wrote them: the frame is checked against the cells, and no
/// transfer's result that is not finite reaches an output.
#[test]
fn an_rbf_field_whose_frame_was_damaged_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, _) = bar(dir.path());
    let field = dir.path().join("rbf.field");
    let out = dir.path().join("o.ply");
    let r = deform(
        &input,
        &out,
        &edit,
        &[
            "--cell-size",
            "0.5",
            "--transfer",
            "rbf",
            "--save-field",
            arg(&field),
        ],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    std::fs::remove_file(&out).unwrap();
    let mut bytes = std::fs::read(&field).unwrap();
    let u64_at =
        |b: &[u8], at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap()) as usize;
    // Preamble 17, origin 24, n; n cells of 16 numbers; r maps of 12 numbers and, with maps,
    // a u32 per cell; the RBF flag; then its shift (3 numbers) and 1/scale.
    let n = u64_at(&bytes, 41);
    let maps_at = 49 + n * 128;
    let r = u64_at(&bytes, maps_at);
    let rbf_at = maps_at + 8 + r * 96 + if r > 0 { 4 * n } else { 0 };
    assert_eq!(bytes[rbf_at], 1, "no RBF where expected");
    let inv_scale = rbf_at + 1 + 24;
    bytes[inv_scale..inv_scale + 8].copy_from_slice(&5e-324f64.to_le_bytes());
    let bad = dir.path().join("bad.field");
    std::fs::write(&bad, bytes).unwrap();
    let r = run(&["apply", arg(&bad), arg(&input), "-o", arg(&out), "-q"]);
    assert_eq!(r.code, 3, "{}", r.stderr);
    assert!(r.stderr.contains("frame"), "{}", r.stderr);
    assert!(!out.exists());
}

/// A field whose window cell lies off the grid of the others (one damaged center of a PU field
/// applied to a tile, so that only a window of its cells is read) was a solver failure (exit 1):
/// the file is malformed, exit 3.
#[test]
fn a_field_window_cell_off_the_grid_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("terrain.las");
    data_gen::write_las_terrain(&input, 3000, false).unwrap();
    let edit = lift_spec(
        dir.path(),
        [499990.0, 500300.0, 501700.0, 502010.0],
        [4999990.0, 5002010.0],
    );
    let out = dir.path().join("out.las");
    let field = dir.path().join("pu.field");
    let r = deform(
        &input,
        &out,
        &edit,
        &[
            "--cells",
            "300",
            "--transfer",
            "pu",
            "--save-field",
            arg(&field),
        ],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    std::fs::remove_file(&out).unwrap();
    // The first cell's center moved by 0.37 of its half-size along x: off every grid voxel.
    let saved = rigidcells::internal::field::SavedField::<3>::load(&field).unwrap();
    assert!(!saved.is_window());
    let bytes = std::fs::read(&field).unwrap();
    let first = 8 + 4 + 4 + 1 + 24 + 8;
    let x = f64::from_le_bytes(bytes[first..first + 8].try_into().unwrap());
    let half = f64::from_le_bytes(bytes[first + 24..first + 32].try_into().unwrap());
    let bad = dir.path().join("bad.field");
    damaged(&field, 0, x + 0.37 * half, &bad);
    let r = run(&["apply", arg(&bad), arg(&input), "-o", arg(&out), "-q"]);
    assert_eq!(r.code, 3, "{}", r.stderr);
    assert!(r.stderr.contains("bad.field"), "{}", r.stderr);
    assert!(!out.exists());
}

/// A PLY header claiming 2³² − 1 vertices in a small file had 206 GB reserved and aborted: the
/// counts are checked against the body's bytes first, for every element and both readers.
#[test]
fn a_ply_whose_counts_cannot_fit_its_body_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, _) = bar(dir.path());
    let good = std::fs::read(&input).unwrap();
    let text = String::from_utf8_lossy(&good[..200]).into_owned();
    let line = text
        .lines()
        .find(|l| l.starts_with("element vertex"))
        .unwrap()
        .to_string();
    for (name, claim) in [
        ("vertex.ply", "element vertex 4294967295"),
        ("extra.ply", ""),
    ] {
        let mut bytes = good.clone();
        let at = text.find(&line).unwrap();
        let replacement = if claim.is_empty() {
            // An element without properties and a huge count, before the vertices.
            format!("element nothing 4294967295\n{line}")
        } else {
            claim.to_string()
        };
        bytes.splice(at..at + line.len(), replacement.bytes());
        let bad = dir.path().join(name);
        std::fs::write(&bad, &bytes).unwrap();
        let out = dir.path().join("o.ply");
        for r in [
            run(&["render", arg(&bad), "-o", arg(&dir.path().join("r.png"))]),
            deform(&bad, &out, &edit, &[]),
        ] {
            assert_eq!(r.code, 3, "{name}: {}", r.stderr);
            assert!(r.stderr.contains("cannot fit"), "{name}: {}", r.stderr);
        }
        assert!(!out.exists());
    }
}

/// A LAS 1.4 file whose extended VLR claims 35 TB had `las` size a buffer from it and abort:
/// the extended VLRs are walked against the file's length first.
#[test]
fn a_las_whose_extended_vlr_runs_past_the_end_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = std::fs::read(common::shared("las/1_4_w_evlr.las")).unwrap();
    let start = u64::from_le_bytes(bytes[235..243].try_into().unwrap()) as usize;
    bytes[start + 20..start + 28].copy_from_slice(&35_201_149_304_832u64.to_le_bytes());
    let input = dir.path().join("evlr.las");
    std::fs::write(&input, &bytes).unwrap();
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [0, 0, 0], max = [1, 1, 1] }\n",
    )
    .unwrap();
    let out = dir.path().join("out.las");
    let r = deform(&input, &out, &edit, &[]);
    assert_eq!(r.code, 3, "{}", r.stderr);
    assert!(r.stderr.contains("extended VLR 1"), "{}", r.stderr);
    assert!(r.stderr.contains("evlr.las"), "{}", r.stderr);
    assert!(!out.exists());
}

/// The data of the LASzip VLR of the LAZ file `bytes`.
fn laszip_vlr(bytes: &[u8]) -> usize {
    let u16_at = |at: usize| u16::from_le_bytes([bytes[at], bytes[at + 1]]) as usize;
    let mut at = u16_at(94);
    let count = u32::from_le_bytes(bytes[100..104].try_into().unwrap());
    for _ in 0..count {
        if bytes[at + 2..at + 16] == *b"laszip encoded" {
            return at + 54;
        }
        at += 54 + u16_at(at + 20);
    }
    panic!("no LASzip VLR")
}

/// `laz` panicked on a point-wise LAZ whose VLR gives its 20-byte item 19 bytes, and asked for
/// 3.85 GB on a chunked one whose VLR's chunk size is 3.85e9: both are format errors.
#[test]
fn a_laz_whose_vlr_contradicts_its_records_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut point_wise =
        std::fs::read(common::shared("las/point-version-1-point-wise.laz")).unwrap();
    let item = laszip_vlr(&point_wise) + 34 + 2;
    point_wise[item..item + 2].copy_from_slice(&19u16.to_le_bytes());
    let mut chunked = std::fs::read(common::shared("las/autzen_trim.laz")).unwrap();
    let size = laszip_vlr(&chunked) + 12;
    chunked[size..size + 4].copy_from_slice(&3_850_543_766u32.to_le_bytes());
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [0, 0, 0], max = [1, 1, 1] }\n",
    )
    .unwrap();
    for (name, bytes) in [("point-wise.laz", point_wise), ("chunked.laz", chunked)] {
        let input = dir.path().join(name);
        std::fs::write(&input, bytes).unwrap();
        let out = dir.path().join("out.las");
        let r = deform(&input, &out, &edit, &[]);
        assert_eq!(r.code, 3, "{name}: {}", r.stderr);
        assert!(r.stderr.contains(name), "{name}: {}", r.stderr);
        assert!(!r.stderr.contains("panicked"), "{name}: {}", r.stderr);
        assert!(!out.exists());
    }
}

/// Values past what the arithmetic holds: `--chunk 2⁶⁴−1` overflowed a reader's index (a
/// panic) and is now taken as the largest chunk; a cell size of 1e300 ended in an indefinite
/// solve (exit 1) and is now a parameter error.
#[test]
fn parameters_past_their_range_are_refused_or_capped() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, _) = bar(dir.path());
    let out = dir.path().join("o.ply");
    let r = deform(&input, &out, &edit, &["--chunk", "18446744073709551615"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    std::fs::remove_file(&out).unwrap();
    // A chunk of no samples is a parameter value out of its range, for both commands.
    let r = deform(&input, &out, &edit, &["--chunk", "0"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("--chunk 0"), "{}", r.stderr);
    assert!(!out.exists());
    let field = dir.path().join("s.field");
    let r = run(&[
        "solve",
        arg(&input),
        "--edit",
        arg(&edit),
        "--save-field",
        arg(&field),
        "--chunk",
        "0",
    ]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("--chunk 0"), "{}", r.stderr);
    assert!(!field.exists());
    for flag in ["--cell-size", "--min-cell-size"] {
        let r = deform(&input, &out, &edit, &[flag, "1e300"]);
        assert_eq!(r.code, 4, "{flag}: {}", r.stderr);
        assert!(r.stderr.contains("at most 1e15"), "{flag}: {}", r.stderr);
        assert!(!out.exists());
    }
}

/// Four samples on one plane, deformed with the dense RBF: its cells' centers are coplanar and
/// the exact system singular (exit 1 before). Now it solves, the handle's sample moves with it.
#[test]
fn the_rbf_of_a_flat_scan_is_solved() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("four.xyz");
    std::fs::write(&input, "0 1 1\n0 4 4\n0 1 4\n0 4 1\n").unwrap();
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [-1, 0.5, 0.5], max = [1, 1.5, 1.5] }\n\
         [[handle]]\nbox = { min = [-1, 3.5, 3.5], max = [1, 4.5, 4.5] }\ntranslate = [0, 0, 1]\n",
    )
    .unwrap();
    let out = dir.path().join("out.xyz");
    let r = deform(
        &input,
        &out,
        &edit,
        &["--cells", "400", "--transfer", "rbf"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let moved = std::fs::read_to_string(&out).unwrap();
    assert!(moved.lines().any(|l| l == "0 4 5"), "{moved}");
}

/// A LAS header whose z scale is 5e-324 (or negative, or 1e-300) left no output frame that
/// could hold the moved coordinates: exit 1 after the whole solve. Such a header is malformed.
#[test]
fn a_las_header_with_an_absurd_scale_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("terrain.las");
    data_gen::write_las_terrain(&good, 3000, false).unwrap();
    let edit = lift_spec(
        dir.path(),
        [499990.0, 500300.0, 501700.0, 502010.0],
        [4999990.0, 5002010.0],
    );
    // The z scale is the third f64 from byte 131; the x offset the first from 155.
    for (name, at, value) in [
        ("tiny.las", 147, 5e-324),
        ("negative.las", 147, -1.0),
        ("huge.las", 147, 1e300),
        ("tiny-x.las", 131, 1e-300),
        ("offset.las", 155, -f64::MAX),
    ] {
        let mut bytes = std::fs::read(&good).unwrap();
        bytes[at..at + 8].copy_from_slice(&value.to_le_bytes());
        let input = dir.path().join(name);
        std::fs::write(&input, bytes).unwrap();
        let out = dir.path().join("out.las");
        let r = deform(&input, &out, &edit, &["--cells", "300"]);
        assert_eq!(r.code, 3, "{name}: {}", r.stderr);
        assert!(r.stderr.contains("out of range"), "{name}: {}", r.stderr);
        assert!(!out.exists());
    }
}

/// A LAZ whose header gives 32,768-byte records for 26-byte LASzip items had `laz` ask for
/// 3.6 GB and abort; one whose header claims 603,353 extended VLRs failed only when the output
/// was written, and left the `--save-field` file behind. Both exit 3 and leave nothing.
#[test]
fn a_laz_header_that_contradicts_its_body_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read(common::shared("las/autzen_trim.laz")).unwrap();
    let mut record = good.clone();
    record[105..107].copy_from_slice(&32768u16.to_le_bytes());
    let mut evlrs = good.clone();
    evlrs[243..247].copy_from_slice(&603_353u32.to_le_bytes());
    let edit = lift_spec(
        dir.path(),
        [636000.0, 636300.0, 636900.0, 637200.0],
        [848900.0, 849600.0],
    );
    for (name, bytes) in [("record.laz", record), ("evlrs.laz", evlrs)] {
        let input = dir.path().join(name);
        std::fs::write(&input, bytes).unwrap();
        let out = dir.path().join("out.laz");
        let field = dir.path().join("s.field");
        let r = deform(
            &input,
            &out,
            &edit,
            &["--cells", "300", "--save-field", arg(&field)],
        );
        assert_eq!(r.code, 3, "{name}: {}", r.stderr);
        assert!(!out.exists() && !field.exists(), "{name}: a file was left");
    }
}

/// A layered LAZ (point format 7, LASzip v4) whose first chunk's first layer claims 4 GB had
/// `laz` resize a buffer to it and abort: the layer sizes of every chunk are checked against
/// the chunk's bytes first.
#[test]
fn a_layered_laz_chunk_whose_layers_claim_too_much_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = std::fs::read(common::shared("las/pdrf7-v4-1.4.laz")).unwrap();
    let points = u32::from_le_bytes(bytes[96..100].try_into().unwrap()) as usize;
    let record = u16::from_le_bytes([bytes[105], bytes[106]]) as usize;
    // Past the chunk table's offset: the first point raw, the point count, then the sizes.
    let first_size = points + 8 + record + 4;
    bytes[first_size..first_size + 4].copy_from_slice(&0xF000_0000u32.to_le_bytes());
    let input = dir.path().join("layers.laz");
    std::fs::write(&input, bytes).unwrap();
    let out = dir.path().join("cells.ply");
    let r = common::cells(&input, &out, &["-q"]);
    assert_eq!(r.code, 3, "{}", r.stderr);
    assert!(r.stderr.contains("layers claim"), "{}", r.stderr);
    assert!(!out.exists());
}

/// A scan moved whole by 1e15 (the largest the spec allows) lands where the writer needs a
/// frame of a huge offset and scale, which our own reader once refused: every output must read
/// back. A handle stretching z by 1e15 against a fixed end tears the scan apart and is refused.
#[test]
fn an_extreme_allowed_motion_writes_a_las_that_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("terrain.las");
    data_gen::write_las_terrain(&input, 3000, false).unwrap();
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[handle]]\nbox = { min = [499990, 4999990, -1000], max = [502010, 5002010, 1000] }\n\
         translate = [0, 0, 1e15]\n",
    )
    .unwrap();
    let out = dir.path().join("out.las");
    let r = deform(&input, &out, &edit, &["--cells", "300"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let r = run(&["info", arg(&out)]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r.stdout.contains("z [1000000000000"), "{}", r.stdout);
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [499990, 4999990, 0], max = [500300, 5002010, 1000] }\n\
         [[handle]]\nbox = { min = [501700, 4999990, 0], max = [502010, 5002010, 1000] }\n\
         matrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1e15, 0], [0, 0, 0, 1]]\n",
    )
    .unwrap();
    let r = deform(&input, &out, &edit, &["--cells", "300"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("times the cells' extent"), "{}", r.stderr);
}

/// A tiny `--refine-strain` split every cell round after round (minutes on the tube): the
/// refinement now stops at a bound and says which.
#[test]
fn refinement_with_a_tiny_threshold_stops_at_its_bound() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, _) = bar(dir.path());
    let out = dir.path().join("o.ply");
    let r = common::deform_verbose(
        &input,
        &out,
        &edit,
        &["--cell-size", "0.5", "--refine-strain", "1e-12"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r.stderr.contains("refinement stopped"), "{}", r.stderr);
    assert!(out.exists());
}

/// A LAZ whose chunk table claims 2³¹ − 1 chunks made `laz` ask for 34 GB and abort: a format
/// error, checked before `laz` reads the table, also when the header's point count is damaged
/// too (3.4e9 points let the chunk count through). One whose table pointer lies past the end is
/// a format error from the decoder.
#[test]
fn a_laz_with_a_damaged_chunk_table_is_a_format_error() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read(common::shared("las/autzen_trim.laz")).unwrap();
    let points = u32::from_le_bytes(good[96..100].try_into().unwrap()) as usize;
    let table = i64::from_le_bytes(good[points..points + 8].try_into().unwrap()) as usize;
    let mut count = good.clone();
    count[table + 4..table + 8].copy_from_slice(&0x7fff_ffffu32.to_le_bytes());
    let mut counts = count.clone();
    counts[107..111].copy_from_slice(&3_358_787_349u32.to_le_bytes());
    let mut pointer = good.clone();
    pointer[points..points + 8].copy_from_slice(&(1i64 << 40).to_le_bytes());
    for (name, bytes) in [
        ("count.laz", count),
        ("counts.laz", counts),
        ("pointer.laz", pointer),
    ] {
        let input = dir.path().join(name);
        std::fs::write(&input, bytes).unwrap();
        // `info` decodes every record for the centroid, so it meets the damage as `deform`
        // does: a format error.
        let r = run(&["info", arg(&input)]);
        assert_eq!(r.code, 3, "{name}: {}", r.stderr);
        assert!(r.stderr.contains(name), "{name}: {}", r.stderr);
        let out = dir.path().join("out.laz");
        let edit = dir.path().join("edit.toml");
        std::fs::write(
            &edit,
            "[[fixed]]\nbox = { min = [0, 0, 0], max = [1, 1, 1] }\n",
        )
        .unwrap();
        let r = deform(&input, &out, &edit, &[]);
        assert_eq!(r.code, 3, "{name}: {}", r.stderr);
        assert!(r.stderr.contains(name), "{name}: {}", r.stderr);
        if name != "pointer.laz" {
            assert!(r.stderr.contains("chunk table"), "{name}: {}", r.stderr);
        }
        assert!(!out.exists());
    }
}

/// A constraint sent far past the shape's size is refused at once, naming it (it would tear
/// the shape apart over a thousand load steps); a shape moved far as a whole is not torn, and
/// takes one step.
#[test]
fn motions_far_past_the_shapes_size_are_refused_unless_the_shape_moves_whole() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out, edit) = common::lifted_bar(dir.path(), 4.0);
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n\
         translate = [0, 0, 4294967295]\n",
    )
    .unwrap();
    let started = std::time::Instant::now();
    let r = deform(&input, &out, &edit, &["--cell-size", "0.5"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("handle #1 (line 3) of the edit spec moves")
            && r.stderr.contains("times the cells' extent"),
        "{}",
        r.stderr
    );
    assert!(
        started.elapsed().as_secs() < 5,
        "refused after {:?}",
        started.elapsed()
    );
    assert!(!out.exists());
    std::fs::write(
        &edit,
        "[[handle]]\nbox = { min = [-1, -1, -1], max = [11, 2, 2] }\n\
         translate = [1000000, 0, 0]\n",
    )
    .unwrap();
    let report = dir.path().join("r.json");
    let r = deform(
        &input,
        &out,
        &edit,
        &["--cell-size", "0.5", "--report", arg(&report)],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(json["load_steps"], 1, "{json}");
}

/// The work follows the occupied cells, whatever the extent: four samples 21 × 42 km apart at
/// 0.3 m cells, and 270 spread over 536 km at 0.5 m, deform in moments (the coarsest level of
/// the grid is not enumerated whole: 2.45e9 cells for the four).
#[test]
fn a_few_samples_over_a_huge_extent_cost_what_they_occupy() {
    let dir = tempfile::tempdir().unwrap();
    let four = dir.path().join("four.xyz");
    std::fs::write(&four, "0 0 0\n21000 0 0\n0 42000 0\n21000 42000 0\n").unwrap();
    let edit = dir.path().join("edit.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [-1, -1, -1], max = [1, 42001, 1] }\n\
         [[handle]]\nbox = { min = [20999, -1, -1], max = [21001, 42001, 1] }\n\
         translate = [0, 0, 10]\n",
    )
    .unwrap();
    let out = dir.path().join("out.xyz");
    let started = std::time::Instant::now();
    let r = deform(&four, &out, &edit, &["--cell-size", "0.3"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let spread = dir.path().join("spread.xyz");
    let text: String = (0..270)
        .map(|k| {
            let t = k as f64 / 269.0;
            format!(
                "{} {} {}\n",
                536_000.0 * t,
                536_000.0 * (t * 7.0).fract(),
                50.0 * t
            )
        })
        .collect();
    std::fs::write(&spread, text).unwrap();
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [-1, -1, -1], max = [100000, 600000, 100] }\n\
         [[handle]]\nbox = { min = [400000, -1, -1], max = [600000, 600000, 100] }\n\
         translate = [0, 0, 10]\n",
    )
    .unwrap();
    let r = deform(&spread, &out, &edit, &["--cell-size", "0.5"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        started.elapsed().as_secs() < 10,
        "took {:?}",
        started.elapsed()
    );
}
