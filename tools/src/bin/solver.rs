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
//! - any scene with `-rest` after its name: solved from rest (`--coarse-levels 0`).
//!
//! Each scene is one `rigidcells deform --report` process (its peak memory its own); the
//! table comes from the report's `iteration_log`.

use std::path::Path;
use std::process::Command;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut scenes: Vec<String> = std::env::args().skip(1).collect();
    if scenes.is_empty() {
        scenes = ["tube", "tube-direct", "veg-2.5", "veg-2.5-rest"]
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
    for scene in &scenes {
        let (name, rest) = match scene.strip_suffix("-rest") {
            Some(name) => (name, true),
            None => (scene.as_str(), false),
        };
        let (input, edit, mut args): (_, _, Vec<&str>) = match name {
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
            "veg-2.5" | "veg-1.25" => {
                let scan = dir.join("vegetation.las");
                if !scan.exists() {
                    let n = 2_000_000;
                    data_gen::write_las(&scan, data_gen::Terrain::vegetation(n), n, false)?;
                }
                let edit = dir.join("lift.toml");
                std::fs::write(
                    &edit,
                    "[[fixed]]\nbox = { min = [499990, 4999990, -100], \
                     max = [500100, 5000210, 1000] }\n\
                     [[handle]]\nbox = { min = [500900, 4999990, -100], \
                     max = [501010, 5000210, 1000] }\ntranslate = [0, 0, 20]\n",
                )?;
                let size = if name == "veg-2.5" { "2.5" } else { "1.25" };
                (scan, edit, vec!["--cell-size", size])
            }
            other => return Err(format!("unknown scene `{other}`").into()),
        };
        if rest {
            args.extend(["--coarse-levels", "0"]);
        }
        let out = dir.join(format!(
            "out.{}",
            input.extension().unwrap_or_default().to_string_lossy()
        ));
        let report = dir.join("report.json");
        let status = Command::new(&bin)
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
            continue;
        }
        print_report(scene, &std::fs::read_to_string(&report)?)?;
    }
    std::fs::remove_dir_all(&dir).ok();
    Ok(())
}

/// The scene's totals and its iteration table.
fn print_report(scene: &str, text: &str) -> Result<(), Box<dyn std::error::Error>> {
    let r: serde_json::Value = serde_json::from_str(text)?;
    let t = &r["timings_s"];
    let secs = |v: &serde_json::Value| v.as_f64().unwrap_or(0.0);
    let peak = r["peak_memory_bytes"].as_f64().unwrap_or(0.0) / f64::from(1 << 20);
    println!(
        "\n{scene}: {} cells, {} load steps, {} iterations, {} solver, energy {:.10e}; \
         total {:.2} s (read {:.2}, cells {:.2}, solve {:.2}, transfer {:.2}, write {:.2}), \
         peak {peak:.0} MiB",
        r["cells"],
        r["load_steps"],
        r["iterations"],
        r["linear_solver"].as_str().unwrap_or("?"),
        r["energy"]
            .as_array()
            .and_then(|e| e.last())
            .map_or(0.0, secs),
        secs(&t["total"]),
        secs(&t["read"]),
        secs(&t["voxelize"]),
        secs(&t["solve"]),
        secs(&t["transfer"]),
        secs(&t["write"]),
    );
    println!(
        "| it | step | cells | energy | decrease | largest move (cells) | step length | CG \
         | assembly ms | setup ms | linear ms | line search ms |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut sums = [0.0; 4];
    let keys = [
        "seconds_assembly",
        "seconds_setup",
        "seconds_linear",
        "seconds_line_search",
    ];
    let log = r["iteration_log"].as_array().cloned().unwrap_or_default();
    for (i, it) in log.iter().enumerate() {
        let ms: Vec<f64> = keys.iter().map(|k| 1e3 * secs(&it[*k])).collect();
        for (s, m) in sums.iter_mut().zip(&ms) {
            *s += m;
        }
        println!(
            "| {} | {} | {} | {:.10e} | {:.1e} | {:.1e} | {} | {} | {:.0} | {:.0} | {:.0} | {:.0} |",
            i + 1,
            it["load_step"],
            it["cells"],
            secs(&it["energy"]),
            secs(&it["decrease"]),
            secs(&it["largest_move"]),
            secs(&it["step_length"]),
            it["linear_iterations"],
            ms[0],
            ms[1],
            ms[2],
            ms[3],
        );
    }
    let n = log.len().max(1) as f64;
    println!(
        "| mean | | | | | | | | {:.0} | {:.0} | {:.0} | {:.0} |",
        sums[0] / n,
        sums[1] / n,
        sums[2] / n,
        sums[3] / n
    );
    Ok(())
}
