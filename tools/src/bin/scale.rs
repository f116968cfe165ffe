//! The deformation at scale: one large-extent scan, deformed whole at cell counts
//! from 6k to 1M, each run a separate `rigidcells deform` process so that its peak memory is
//! its own. Prints voxelize, solve, transfer (fit and evaluation of every point) and total
//! seconds and the peak RSS from each run's `--report`; a run the memory budget refuses says so.
//!
//! `cargo build --release && cargo run --release -p rigidcells-tools --bin scale [POINTS]`:
//! writes a synthetic 2 × 2 km terrain of POINTS points (default 10M; `data_gen`) to a temporary
//! folder, fixes its west 300 m and lifts its east 300 m by 20 m, with the default transfer
//! (the partition-of-unity RBF).

use std::path::Path;
use std::process::Command;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let points: u64 = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(10_000_000);
    let bin = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/release/rigidcells");
    if !bin.exists() {
        return Err("build the CLI first: cargo build --release".into());
    }
    let dir = std::env::temp_dir().join(format!("rigidcells-scale-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let scan = dir.join("terrain.las");
    data_gen::write_las_terrain(&scan, points, false)?;
    let edit = dir.join("lift.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [499990, 4999990, 0], max = [500300, 5002010, 1000] }\n\
         [[handle]]\nbox = { min = [501700, 4999990, 0], max = [502010, 5002010, 1000] }\n\
         translate = [0, 0, 20]\n",
    )?;
    println!(
        "terrain of {points} points (2 × 2 km), {} threads",
        rayon::current_num_threads()
    );
    println!(
        "| cells asked | cells | cell size m | voxelize s | solve s | transfer s | total s | peak RSS |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for target in [6_000usize, 30_000, 100_000, 300_000, 1_000_000] {
        // The terrain's cells are its surface: about (2000 / size)² of them.
        let size = 2000.0 / (target as f64).sqrt();
        let out = dir.join("out.las");
        let report = dir.join("report.json");
        let run = Command::new(&bin)
            .args([
                "deform",
                scan.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ])
            .args(["--edit", edit.to_str().unwrap(), "-q"])
            .args(["--cell-size", &format!("{size:.3}")])
            .args(["--report", report.to_str().unwrap()])
            .output()?;
        if !run.status.success() {
            let why = String::from_utf8_lossy(&run.stderr);
            println!("| {target} | — | {size:.2} | refused: {} |", why.trim());
            continue;
        }
        let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report)?)?;
        let t = &r["timings_s"];
        println!(
            "| {target} | {} | {size:.2} | {:.2} | {:.1} | {:.2} | {:.1} | {:.2} GB |",
            r["cells"],
            t["voxelize"].as_f64().unwrap_or(0.0),
            t["solve"].as_f64().unwrap_or(0.0),
            t["transfer"].as_f64().unwrap_or(0.0) + t["write"].as_f64().unwrap_or(0.0),
            t["total"].as_f64().unwrap_or(0.0),
            r["peak_memory_bytes"].as_f64().unwrap_or(0.0) / 1e9,
        );
    }
    std::fs::remove_dir_all(&dir)?;
    Ok(())
}
