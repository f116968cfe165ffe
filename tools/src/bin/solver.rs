//! The solve, iteration by iteration: where each Gauss-Newton iteration's time goes (assembly,
//! factor or hierarchy setup, the linear solve, the line search) and why the solver stopped
//! (the energy's relative decrease and the largest corner move, in finest cell sizes).
//!
//! `cargo build --release && cargo run --release -p rigidcells-tools --bin solver -- [SCENE...]`
//!
//! Scenes (all by default but `veg-1.25`, which takes minutes):
//! - `tube`: the closed 480k-vertex tube (`data_gen::tube`), its first metre fixed and its last
//!   turned by −90° about y and moved by (−3, 0, 5), `--cells 5500` (coarse to fine, by default
//!   from 2,000 cells);
//! - `tube-direct`: the same with `--solver direct`;
//! - `veg-2.5`, `veg-1.25`: 1 km × 200 m of rolling ground under up to 3 m of low vegetation
//!   (`gen vegetation`, 2M points: every cell a boundary cell), the west 100 m fixed and the
//!   east 100 m lifted by 20 m, cells of 2.5 m and 1.25 m;
//! - `bar`: the 10 × 1 × 1 bar of the demo (`data_gen::bar`), its end tenths fixed and lifted
//!   by 2 with a 30° turn, `--cells 4000`;
//! - `veg-4`: the vegetation scene at 4 m;
//! - `rough-2.5`, `rough-1.25`, `rough-4`: the same strip and edit over steep hills
//!   (`gen rough`: 50 m of relief, hills 100 m apart), the cells a corrugated sheet;
//! - any scene with `-rest` after its name: solved from rest (`--coarse-levels 0`);
//! - any scene with `-lg` after its name (before `-rest`): `--solver local-global`; with `-gn`:
//!   `--solver direct` (Gauss-Newton and Newton, factored);
//! - `both:SCENE`: the scene by Newton (`-gn`), by local-global (`-lg`) and by `auto`, one
//!   after the other, and a line comparing them (the solve's seconds, iterations by kind,
//!   energies against Newton's).
//!
//! Each scene is one `rigidcells deform --report` process (its peak memory its own); the
//! table comes from the report's `iteration_log` (with `--table`; a summary of each kind of
//! iteration otherwise).

use std::path::{Path, PathBuf};
use std::process::Command;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn main() -> Res<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let table = args.iter().any(|a| a == "--table");
    args.retain(|a| a != "--table");
    if args.is_empty() {
        args = ["tube", "tube-direct", "veg-2.5", "veg-2.5-rest"]
            .map(String::from)
            .to_vec();
    }
    let bin = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/release/rigidcells");
    if !bin.exists() {
        return Err("build the CLI first: cargo build --release".into());
    }
    let dir = std::env::temp_dir().join(format!("rigidcells-solver-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    println!("{} threads", rayon::current_num_threads());
    for scene in &args {
        let Some(scene) = scene.strip_prefix("both:") else {
            run(&bin, &dir, scene, table)?;
            continue;
        };
        let newton = run(&bin, &dir, &with_kind(scene, "gn"), table)?;
        let lg = run(&bin, &dir, &with_kind(scene, "lg"), table)?;
        let auto = run(&bin, &dir, scene, table)?;
        if let (Some(n), Some(l), Some(a)) = (newton, lg, auto) {
            println!("\n{scene}: the solve's seconds, total seconds, energy against Newton's:");
            for (name, s) in [("newton", &n), ("local-global", &l), ("auto", &a)] {
                println!(
                    "  {name}: {:.2} s ({:.2}× Newton's), total {:.2} s, {:+.1e} ({})",
                    s.solve,
                    n.solve / s.solve,
                    s.total,
                    (s.energy - n.energy) / n.energy,
                    s.kinds,
                );
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    Ok(())
}

/// `scene` with the solver suffix `kind` (`lg`, `gn`) before any `-rest`.
fn with_kind(scene: &str, kind: &str) -> String {
    match scene.strip_suffix("-rest") {
        Some(name) => format!("{name}-{kind}-rest"),
        None => format!("{scene}-{kind}"),
    }
}

/// What one run came to.
struct Summary {
    solve: f64,
    total: f64,
    energy: f64,
    /// Iterations by kind, in words.
    kinds: String,
}

/// One scene's `deform --report` process, its report printed.
fn run(bin: &Path, dir: &Path, scene: &str, table: bool) -> Res<Option<Summary>> {
    let (name, rest) = match scene.strip_suffix("-rest") {
        Some(name) => (name, true),
        None => (scene, false),
    };
    let (name, solver) = match (name.strip_suffix("-lg"), name.strip_suffix("-gn")) {
        (Some(name), _) => (name, Some("local-global")),
        (_, Some(name)) => (name, Some("direct")),
        _ => (name, None),
    };
    let (input, edit, mut args) = scene_files(dir, name)?;
    if let Some(solver) = solver {
        args.extend(["--solver", solver]);
    }
    if rest {
        args.extend(["--coarse-levels", "0"]);
    }
    let out = dir.join(format!(
        "out.{}",
        input.extension().unwrap_or_default().to_string_lossy()
    ));
    let report = dir.join("report.json");
    let status = Command::new(bin)
        .arg("deform")
        .arg(&input)
        .arg("--edit")
        .arg(&edit)
        .arg("-o")
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .args(&args)
        .arg("-q")
        .status()?;
    if !status.success() {
        println!("\n{scene}: deform failed ({status})");
        return Ok(None);
    }
    print_report(scene, &std::fs::read_to_string(&report)?, table).map(Some)
}

/// The input, the edit and the arguments of scene `name`, the files made in `dir` once.
fn scene_files(dir: &Path, name: &str) -> Res<(PathBuf, PathBuf, Vec<&'static str>)> {
    Ok(match name {
        "tube" | "tube-direct" => {
            let tube = dir.join("tube.ply");
            if !tube.exists() {
                let mesh = data_gen::tube(10.0, 1.0, 0.8, 400, 599);
                data_gen::write_ply(&tube, &mesh, true)?;
            }
            let edit = dir.join("bend.toml");
            std::fs::write(
                &edit,
                "[[fixed]]\nbox = { min = [-1, -2, -2], max = [1, 2, 2] }\n\
                 [[handle]]\nbox = { min = [9, -2, -2], max = [11, 2, 2] }\n\
                 rotate = { axis = [0, 1, 0], degrees = -90 }\ntranslate = [-3, 0, 5]\n",
            )?;
            let mut args = vec!["--cells", "5500"];
            if name == "tube-direct" {
                args.extend(["--solver", "direct"]);
            }
            (tube, edit, args)
        }
        "bar" => {
            let bar = dir.join("bar.ply");
            if !bar.exists() {
                data_gen::write_ply(&bar, &data_gen::bar([10.0, 1.0, 1.0], 40.0), true)?;
            }
            let edit = dir.join("bar.toml");
            std::fs::write(
                &edit,
                "[[fixed]]\nbox = { min = [-1, -1, -1], max = [1, 2, 2] }\n\
                 [[handle]]\nbox = { min = [9, -1, -1], max = [11, 2, 2] }\n\
                 rotate = { axis = [0, 1, 0], degrees = 30 }\ntranslate = [0, 0, 2]\n",
            )?;
            (bar, edit, vec!["--cells", "4000"])
        }
        "veg-2.5" | "veg-1.25" | "veg-4" | "rough-2.5" | "rough-1.25" | "rough-4" => {
            let (kind, size) = name.split_once('-').unwrap_or((name, "4"));
            let scan = dir.join(format!("{kind}.las"));
            if !scan.exists() {
                let n = 2_000_000;
                let terrain = if kind == "rough" {
                    data_gen::Terrain::rough(n, data_gen::Relief::new(50.0, 100.0, 1))
                } else {
                    data_gen::Terrain::vegetation(n)
                };
                data_gen::write_las(&scan, terrain, n, false)?;
            }
            let edit = dir.join("lift.toml");
            std::fs::write(
                &edit,
                "[[fixed]]\nbox = { min = [499990, 4999990, -100], \
                 max = [500100, 5000210, 1000] }\n\
                 [[handle]]\nbox = { min = [500900, 4999990, -100], \
                 max = [501010, 5000210, 1000] }\ntranslate = [0, 0, 20]\n",
            )?;
            let size = match size {
                "2.5" => "2.5",
                "1.25" => "1.25",
                _ => "4",
            };
            (scan, edit, vec!["--cell-size", size])
        }
        other => return Err(format!("unknown scene `{other}`").into()),
    })
}

/// The scene's totals, its iterations by kind, and (with `table`) its iteration table.
fn print_report(scene: &str, text: &str, table: bool) -> Res<Summary> {
    let r: serde_json::Value = serde_json::from_str(text)?;
    let t = &r["timings_s"];
    let secs = |v: &serde_json::Value| v.as_f64().unwrap_or(0.0);
    let peak = r["peak_memory_bytes"].as_f64().unwrap_or(0.0) / f64::from(1 << 20);
    let energy = r["energy"]
        .as_array()
        .and_then(|e| e.last())
        .map_or(0.0, secs);
    println!(
        "\n{scene}: {} cells, {} load steps, {} iterations, {} solver, energy {energy:.10e}; \
         total {:.2} s (read {:.2}, cells {:.2}, solve {:.2}, transfer {:.2}, write {:.2}), \
         peak {peak:.0} MiB",
        r["cells"],
        r["load_steps"],
        r["iterations"],
        r["linear_solver"].as_str().unwrap_or("?"),
        secs(&t["total"]),
        secs(&t["read"]),
        secs(&t["voxelize"]),
        secs(&t["solve"]),
        secs(&t["transfer"]),
        secs(&t["write"]),
    );
    let keys = [
        "seconds_assembly",
        "seconds_setup",
        "seconds_linear",
        "seconds_line_search",
    ];
    let log = r["iteration_log"].as_array().cloned().unwrap_or_default();
    // Iterations of each kind and their mean milliseconds, in the order the kinds came.
    let mut kinds: Vec<(String, usize, [f64; 4])> = Vec::new();
    for it in &log {
        let kind = it["method"].as_str().unwrap_or("?").to_string();
        let at = match kinds.iter().position(|k| k.0 == kind) {
            Some(at) => at,
            None => {
                kinds.push((kind, 0, [0.0; 4]));
                kinds.len() - 1
            }
        };
        kinds[at].1 += 1;
        for (s, k) in kinds[at].2.iter_mut().zip(keys) {
            *s += 1e3 * secs(&it[k]);
        }
    }
    for (kind, n, ms) in &kinds {
        let m = ms.map(|v| v / *n as f64);
        println!(
            "  {n} {kind}: mean ms assembly or local {:.1}, setup {:.1}, linear or global {:.1}, \
             line search or energy {:.1}",
            m[0], m[1], m[2], m[3]
        );
    }
    let words: Vec<String> = kinds.iter().map(|(k, n, _)| format!("{n} {k}")).collect();
    if table {
        print_table(&log);
    }
    Ok(Summary {
        solve: secs(&t["solve"]),
        total: secs(&t["total"]),
        energy,
        kinds: words.join(", "),
    })
}

/// Every iteration of a report's `iteration_log`, one row each.
fn print_table(log: &[serde_json::Value]) {
    let secs = |v: &serde_json::Value| v.as_f64().unwrap_or(0.0);
    println!(
        "| it | kind | step | cells | energy | decrease | largest move (cells) | step length | CG \
         | assembly ms | setup ms | linear ms | line search ms |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (i, it) in log.iter().enumerate() {
        println!(
            "| {} | {} | {} | {} | {:.10e} | {:.1e} | {:.1e} | {} | {} | {:.0} | {:.0} | {:.0} | {:.0} |",
            i + 1,
            it["method"].as_str().unwrap_or("?"),
            it["load_step"],
            it["cells"],
            secs(&it["energy"]),
            secs(&it["decrease"]),
            secs(&it["largest_move"]),
            secs(&it["step_length"]),
            it["linear_iterations"],
            1e3 * secs(&it["seconds_assembly"]),
            1e3 * secs(&it["seconds_setup"]),
            1e3 * secs(&it["seconds_linear"]),
            1e3 * secs(&it["seconds_line_search"]),
        );
    }
}
