//! Two builds of `rigidcells` give the same bytes on every file of the shared data: the check
//! that a change meant to keep behaviour (a refactor) kept it.
//!
//! `cargo run --release -p rigidcells-tools --bin same_bytes -- --before OLD_BIN --after NEW_BIN
//! [--data DIR]` deforms every file of `DIR/las` and `DIR/meshes` (default `../shared/data`)
//! with both binaries — the west fifth of the file's box fixed, the east fifth turned by 20°
//! about the vertical axis and lifted by a tenth of the box, `--cells 2000` — and also runs
//! `info` on each, then compares exit codes, stdout (timings aside), stderr and every output
//! byte. Exit status 0 when every file gives the same, 1 otherwise.

use std::path::{Path, PathBuf};
use std::process::Command;

use rigidcells::internal::info;

fn main() {
    let mut before = None;
    let mut after = None;
    let mut data = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data"));
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--before" => before = args.next().map(PathBuf::from),
            "--after" => after = args.next().map(PathBuf::from),
            "--data" => data = args.next().map(PathBuf::from).unwrap_or(data),
            _ => {
                eprintln!("usage: same_bytes --before BIN --after BIN [--data DIR]");
                std::process::exit(2);
            }
        }
    }
    let (Some(before), Some(after)) = (before, after) else {
        eprintln!("usage: same_bytes --before BIN --after BIN [--data DIR]");
        std::process::exit(2);
    };
    let work = std::env::temp_dir().join(format!("same-bytes-{}", std::process::id()));
    let mut files: Vec<PathBuf> = ["las", "meshes"]
        .iter()
        .flat_map(|d| std::fs::read_dir(data.join(d)).into_iter().flatten())
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    files.sort();
    let (mut same, mut differ) = (0, 0);
    println!("| file | exit codes | same |");
    println!("|---|---|---|");
    for input in &files {
        let name = input
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let runs = [&before, &after].map(|bin| run(bin, input, &work.join(&name)));
        let verdict = if runs[0] == runs[1] {
            same += 1;
            "yes".to_string()
        } else {
            differ += 1;
            format!("**no**: {}", first_difference(&runs[0], &runs[1]))
        };
        println!("| {name} | {} | {verdict} |", runs[1].codes);
    }
    let _ = std::fs::remove_dir_all(&work);
    println!("\n{same} files the same, {differ} different");
    std::process::exit(i32::from(differ > 0));
}

/// What one binary did with one file.
#[derive(PartialEq)]
struct Outcome {
    codes: String,
    stdout: String,
    stderr: String,
    bytes: Vec<u8>,
}

/// Runs `info` and `deform` of `input` with `bin` in `dir`.
fn run(bin: &Path, input: &Path, dir: &Path) -> Outcome {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).expect("a work folder");
    let name = input.file_name().unwrap_or_default().to_string_lossy();
    let output = dir.join(format!("out-{name}"));
    let edit = dir.join("edit.toml");
    std::fs::write(&edit, spec(input)).expect("the edit spec");
    let info = Command::new(bin).arg("info").arg(input).output();
    let deform = Command::new(bin)
        .arg("deform")
        .arg(input)
        .arg("-o")
        .arg(&output)
        .arg("--edit")
        .arg(&edit)
        .args(["--cells", "2000"])
        .output();
    let (Ok(info), Ok(deform)) = (info, deform) else {
        return Outcome {
            codes: "did not run".into(),
            stdout: String::new(),
            stderr: String::new(),
            bytes: Vec::new(),
        };
    };
    // Timings and memory vary from run to run; everything else is compared.
    let steady = |text: &[u8]| -> String {
        String::from_utf8_lossy(text)
            .lines()
            .map(steady_line)
            .collect::<Vec<_>>()
            .join("\n")
    };
    Outcome {
        codes: format!(
            "info {}, deform {}",
            info.status.code().unwrap_or(-1),
            deform.status.code().unwrap_or(-1)
        ),
        stdout: format!("{}\n{}", steady(&info.stdout), steady(&deform.stdout)),
        stderr: steady(&deform.stderr),
        bytes: std::fs::read(&output).unwrap_or_default(),
    }
}

/// A line with every duration and memory figure replaced by `#`: a number followed by `s`,
/// `MB`-like units or `ms/iteration`.
fn steady_line(line: &str) -> String {
    const UNITS: [&str; 7] = ["s", "ms", "kB", "KB", "MB", "GB", "TB"];
    let tokens: Vec<&str> = line.split(' ').collect();
    let bare = |t: &str| t.trim_matches(|c: char| "(),;:".contains(c)).to_string();
    let numeric = |t: &str| !bare(t).is_empty() && bare(t).parse::<f64>().is_ok();
    let mut out = Vec::with_capacity(tokens.len());
    for (i, t) in tokens.iter().enumerate() {
        let unit_follows = tokens
            .get(i + 1)
            .is_some_and(|n| UNITS.contains(&bare(n).as_str()) || n.starts_with("ms/"));
        if numeric(t) && unit_follows {
            out.push("#".to_string());
        } else {
            out.push(t.to_string());
        }
    }
    out.join(" ")
}

/// The edit of a file: its box's west fifth fixed, its east fifth turned by 20° about z and
/// lifted by a tenth of the box (half-spaces, so that a flat scan is selected as well as a
/// mesh).
fn spec(input: &Path) -> String {
    let Ok(i) = info::describe(input, &rigidcells::internal::progress::Silent) else {
        return "[[fixed]]\nsphere = { center = [0, 0, 0], radius = 1 }\n".into();
    };
    let Some((lo, hi)) = i.bounds else {
        return "[[fixed]]\nsphere = { center = [0, 0, 0], radius = 1 }\n".into();
    };
    let w: Vec<f64> = lo.iter().zip(&hi).map(|(a, b)| b - a).collect();
    let size = w.iter().cloned().fold(0.0f64, f64::max).max(1e-9);
    format!(
        "[[fixed]]\nplane = {{ point = [{}, {}, {}], normal = [1, 0, 0] }}\n\
         [[handle]]\nplane = {{ point = [{}, {}, {}], normal = [-1, 0, 0] }}\n\
         rotate = {{ axis = [0, 0, 1], degrees = 20 }}\ntranslate = [0, 0, {}]\n",
        lo[0] + 0.2 * w[0],
        lo[1],
        lo[2],
        hi[0] - 0.2 * w[0],
        lo[1],
        lo[2],
        0.1 * size
    )
}

/// Where two outcomes first differ, in words.
fn first_difference(a: &Outcome, b: &Outcome) -> String {
    if a.codes != b.codes {
        return format!("exit codes {} against {}", a.codes, b.codes);
    }
    for (what, x, y) in [
        ("stdout", &a.stdout, &b.stdout),
        ("stderr", &a.stderr, &b.stderr),
    ] {
        if x != y {
            let line = x
                .lines()
                .zip(y.lines())
                .find(|(p, q)| p != q)
                .map(|(p, q)| format!("{p:?} against {q:?}"))
                .unwrap_or_else(|| "a line more or less".into());
            return format!("{what}: {line}");
        }
    }
    match a.bytes.iter().zip(&b.bytes).position(|(p, q)| p != q) {
        Some(i) => format!("output byte {i} of {}", a.bytes.len()),
        None => format!("output {} against {} bytes", a.bytes.len(), b.bytes.len()),
    }
}
