//! Streaming speed against the peer: `rigidcells apply` (the default transfer and `blend`) and
//! `rigidcells deform` against a chunked laspy rewrite (`tools/python/affine.py`: read a million
//! points, turn and lift them with numpy, write) of the same file, in one run, with the ratios.
//!
//! `cargo run --release -p rigidcells-tools --bin apply_speed -- [--runs N] [--cells N] FILE...`
//!
//! Every file (LAS or LAZ; the output has the input's format) gets the field solved once on the
//! first file (`rigidcells solve`, default edit: the western 15 % fixed, the eastern 15 %
//! lifted and turned, `--cells 6500`), then alternating runs of each command; medians are
//! printed, with CPU / wall and the peak anonymous memory (`RssAnon`, polled) of the run. Pass
//! a file in no spatial order first and the same records sorted second: the last column gives
//! the first file's `apply` time over each file's (how much slower the first order is). laspy
//! runs in `$RIGIDCELLS_PYTHON`, else `target/ci-venv/bin/python` where it exists, else
//! `python3`; it needs `laspy` and `lazrs`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// One run of a command: wall seconds, CPU seconds (user + system), peak anonymous memory.
#[derive(Clone, Copy, Default)]
struct Run {
    wall: f64,
    cpu: f64,
    anon: u64,
}

/// Runs `cmd` to its end, polling its anonymous memory every 10 ms.
// The child is reaped by `wait4`, which also gives its CPU time (`Child::wait` does not).
#[allow(clippy::zombie_processes)]
fn run(cmd: &mut Command) -> Run {
    let start = Instant::now();
    let child = cmd
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("the command starts");
    let pid = child.id() as libc::pid_t;
    let mut anon = 0u64;
    let status_path = format!("/proc/{pid}/status");
    let (mut status, mut usage) = (0, unsafe { std::mem::zeroed::<libc::rusage>() });
    loop {
        if let Ok(text) = std::fs::read_to_string(&status_path)
            && let Some(kb) = text
                .lines()
                .find(|l| l.starts_with("RssAnon:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        {
            anon = anon.max(kb << 10);
        }
        // SAFETY: wait4 writes the status and the usage it is given.
        let done = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if done == pid {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let wall = start.elapsed().as_secs_f64();
    assert!(
        libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0,
        "{cmd:?} failed"
    );
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    Run {
        wall,
        cpu: seconds(usage.ru_utime) + seconds(usage.ru_stime),
        anon,
    }
}

fn median(runs: &[Run]) -> Run {
    let mut walls: Vec<usize> = (0..runs.len()).collect();
    walls.sort_by(|&a, &b| runs[a].wall.total_cmp(&runs[b].wall));
    let mut r = runs[walls[runs.len() / 2]];
    r.anon = runs.iter().map(|r| r.anon).max().unwrap_or(0);
    r
}

fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("RIGIDCELLS_PYTHON") {
        return p.into();
    }
    let venv = Path::new("target/ci-venv/bin/python");
    if venv.exists() {
        return venv.into();
    }
    "python3".into()
}

fn main() {
    let mut args = std::env::args().skip(1).peekable();
    let (mut runs, mut cells, mut files) = (3usize, 6500usize, Vec::new());
    while let Some(a) = args.next() {
        match a.as_str() {
            "--runs" => runs = args.next().and_then(|v| v.parse().ok()).expect("--runs N"),
            "--cells" => cells = args.next().and_then(|v| v.parse().ok()).expect("--cells N"),
            _ => files.push(PathBuf::from(a)),
        }
    }
    assert!(
        !files.is_empty(),
        "usage: apply_speed [--runs N] [--cells N] FILE..."
    );
    let exe = std::env::current_exe().expect("the harness's path");
    let rigidcells = exe.with_file_name("rigidcells");
    assert!(
        rigidcells.exists(),
        "{} is missing: cargo build --release first",
        rigidcells.display()
    );
    let affine = Path::new(env!("CARGO_MANIFEST_DIR")).join("python/affine.py");
    let dir = std::env::temp_dir().join(format!("rigidcells-apply-speed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();

    let header = rigidcells::internal::io::LasHeader::read(&files[0]).unwrap();
    let w = header.max[0] - header.min[0];
    let edit = dir.join("edit.toml");
    std::fs::write(
        &edit,
        data_gen::end_lift_spec(header.min, header.max, 0.15, 0.025 * w, -10.0),
    )
    .unwrap();
    let field = dir.join("f.field");
    let cells_arg = cells.to_string();
    let solve = run(Command::new(&rigidcells).args([
        "solve".as_ref(),
        files[0].as_os_str(),
        "--edit".as_ref(),
        edit.as_os_str(),
        "--cells".as_ref(),
        cells_arg.as_ref(),
        "--save-field".as_ref(),
        field.as_os_str(),
        "-q".as_ref(),
    ]));
    println!(
        "field: `solve --cells {cells}` on {} in {:.2} s; {} threads, medians of {runs} alternating runs",
        files[0].display(),
        solve.wall,
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "\n| file | points | run | wall s | CPU s | CPU / wall | peak anon MiB | laspy / run | first file / this |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut first_apply = None;
    for input in &files {
        let ext = input.extension().unwrap().to_string_lossy().to_string();
        let out = dir.join(format!("out.{ext}"));
        let n = rigidcells::internal::io::LasHeader::read(input)
            .unwrap()
            .count;
        let apply = |transfer: Option<&str>| {
            let mut c = Command::new(&rigidcells);
            c.arg("apply").arg(&field).arg(input).arg("-o").arg(&out);
            if let Some(t) = transfer {
                c.args(["--transfer", t]);
            }
            c.arg("-q");
            c
        };
        let mut commands: Vec<(&str, Command)> = vec![
            ("laspy (chunked affine)", {
                let mut c = Command::new(python());
                c.arg(&affine).arg(input).arg(&out);
                c
            }),
            ("apply", apply(None)),
            ("apply --transfer blend", apply(Some("blend"))),
            ("deform (same edit)", {
                let mut c = Command::new(&rigidcells);
                c.arg("deform")
                    .arg(input)
                    .arg("--edit")
                    .arg(&edit)
                    .args(["--cells", &cells_arg])
                    .arg("-o")
                    .arg(&out)
                    .arg("-q");
                c
            }),
        ];
        let mut times: Vec<Vec<Run>> = vec![Vec::new(); commands.len()];
        for _ in 0..runs {
            for (k, (_, c)) in commands.iter_mut().enumerate() {
                times[k].push(run(c));
                let _ = std::fs::remove_file(&out);
            }
        }
        let medians: Vec<Run> = times.iter().map(|t| median(t)).collect();
        let laspy = medians[0].wall;
        for ((name, _), m) in commands.iter().zip(&medians) {
            let against_first = match (*name, first_apply) {
                ("apply", Some(f)) => format!("{:.2}×", f / m.wall),
                _ => String::new(),
            };
            println!(
                "| {} | {n} | {name} | {:.2} | {:.2} | {:.2} | {:.0} | {:.2}× | {against_first} |",
                input.file_name().unwrap().to_string_lossy(),
                m.wall,
                m.cpu,
                m.cpu / m.wall,
                m.anon as f64 / 1048576.0,
                laspy / m.wall,
            );
        }
        if first_apply.is_none() {
            first_apply = Some(medians[1].wall);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
