//! Local-global iterations (`solve::minimize_local_global`, one factorization) against
//! Gauss-Newton/Newton (`solve::minimize`, a factorization per iteration) on one load step at
//! full load, from rest and from Newton's minimum at 95 % of the load (a warm start, as a drag's
//! next frame or a last load step starts): the time to factor, the time per iteration, and the iterations and
//! seconds each takes to come within 1e-3 and 1e-6 (relative) of Newton's minimum energy,
//! local-global plain and with Anderson acceleration (m = 5), and with the global step solved
//! by 4 and 16 subdomains (`solve::schwarz`, the solve spread over processes, here in one).
//!
//! `cargo run --release -p rigidcells-tools --bin local_global [scene …]`; scenes:
//! - `tube`: the closed 480k-vertex tube (`data_gen::tube`) at about 5,500 cells, its first
//!   metre fixed and its last bent by −90° about y and moved (the `solver` tool's bend);
//! - `bar`: the 10 × 1 × 1 bar at about 5,500 cells, its ends' tenths fixed and turned by 30°
//!   about y and lifted;
//! - `veg`: 300,000 samples of `data_gen::Terrain::vegetation` (1 km × 200 m) in cells of 4 m,
//!   the west 5 % fixed, the east 5 % lifted by 20 m and turned by 2°.

use std::time::Instant;

use rigidcells::Budget;
use rigidcells::internal::cells::{BuildParams, CellComplex, build};
use rigidcells::internal::rigid::{Motion, Vect};
use rigidcells::internal::solve::{self, LocalGlobalParams, SolveParams, SolverInfo};
use rigidcells::parse_spec;

/// Relative gaps to Newton's minimum that are timed.
const GAPS: [f64; 2] = [1e-3, 1e-6];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut scenes: Vec<String> = std::env::args().skip(1).collect();
    if scenes.is_empty() {
        scenes = vec!["tube".into(), "bar".into(), "veg".into()];
    }
    println!(
        "| scene | cells | free | method | factor s | ms/iteration | iterations to 1e-3 | s to 1e-3 \
         | iterations to 1e-6 | s to 1e-6 | iterations run | gap at end |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for scene in &scenes {
        let (pts, triangles, cells, spec, iterations) = match scene.as_str() {
            "tube" => {
                let mesh = data_gen::tube(10.0, 1.0, 0.8, 400, 599);
                let spec = "[[fixed]]\nbox = { min = [-1, -2, -2], max = [1, 2, 2] }\n\
                            [[handle]]\nbox = { min = [9, -2, -2], max = [11, 2, 2] }\n\
                            rotate = { axis = [0, 1, 0], degrees = -90 }\n\
                            translate = [-3, 0, 5]\n";
                (
                    points(&mesh),
                    mesh.triangles,
                    Cells::Target(5500),
                    spec.to_string(),
                    3000,
                )
            }
            "bar" => {
                let mesh = data_gen::bar([10.0, 1.0, 1.0], 12.0);
                let spec = data_gen::end_lift_spec([0.0; 3], [10.0, 1.0, 1.0], 0.1, 2.0, 30.0);
                (
                    points(&mesh),
                    mesh.triangles,
                    Cells::Target(5500),
                    spec,
                    3000,
                )
            }
            "veg" => {
                let n = 300_000u64;
                let mut terrain = data_gen::Terrain::vegetation(n);
                let pts = (0..n)
                    .map(|k| {
                        let (x, y, z, _) = terrain.sample(k);
                        Vect::<3>::new(x, y, z)
                    })
                    .collect::<Vec<_>>();
                let spec = data_gen::end_lift_spec(
                    [0.0, 0.0, 0.0],
                    [1000.0, 200.0, 300.0],
                    0.05,
                    20.0,
                    2.0,
                );
                (pts, vec![], Cells::Size(4.0), spec, 1500)
            }
            other => return Err(format!("unknown scene `{other}`").into()),
        };
        let params = match cells {
            Cells::Target(n) => BuildParams {
                target_cells: Some(n),
                ..Default::default()
            },
            Cells::Size(s) => BuildParams {
                cell_size: Some(s),
                ..Default::default()
            },
        };
        let complex = build(&pts, &triangles, &params, Budget::default())?.0;
        let spec = parse_spec::<3>(&spec, ".".as_ref(), "edit.toml".as_ref())?;
        let constraints = solve::resolve(&complex, &spec, &pts, None)?;
        let rest: Vec<Motion<3>> = complex
            .cells
            .iter()
            .map(|c| Motion::rest(&c.center))
            .collect();
        compare(scene, &complex, &constraints, &rest, iterations)?;
        // A warm start, as the next frame of a drag or the last load step starts: Newton's
        // minimum at 95 % of the load.
        let mut warm = rest;
        let mut info = SolverInfo::default();
        let params = SolveParams {
            tolerance: 1e-12,
            ..Default::default()
        };
        solve::minimize(&complex, &constraints, &mut warm, 0.95, &params, &mut info)?;
        compare(
            &format!("{scene}, warm"),
            &complex,
            &constraints,
            &warm,
            iterations,
        )?;
    }
    Ok(())
}

enum Cells {
    Target(usize),
    Size(f64),
}

fn points(mesh: &data_gen::Mesh) -> Vec<Vect<3>> {
    mesh.vertices.iter().map(|v| Vect::<3>::from(*v)).collect()
}

/// One scene's rows from `start`: Newton, then local-global plain and accelerated.
fn compare(
    scene: &str,
    complex: &CellComplex<3>,
    constraints: &solve::Constraints<3>,
    start: &[Motion<3>],
    iterations: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let free = constraints
        .roles
        .iter()
        .filter(|r| **r == solve::Role::Free)
        .count();
    // Newton to rounding: its last energy is the reference.
    let mut motions = start.to_vec();
    let mut info = SolverInfo::default();
    let params = SolveParams {
        max_iterations: 100,
        tolerance: 1e-15,
        move_tolerance: 0.0,
        ..Default::default()
    };
    let wall = Instant::now();
    solve::minimize(complex, constraints, &mut motions, 1.0, &params, &mut info)?;
    let wall = wall.elapsed().as_secs_f64();
    let best = *info.energies.last().unwrap();
    // Seconds at each energy: the analysis, then each iteration's assembly, factorization,
    // solve and line search.
    let mut seconds = vec![info.seconds_symbolic];
    for log in &info.log {
        let step = log.seconds_assembly + log.seconds_setup + log.seconds_linear;
        seconds.push(seconds.last().unwrap() + step + log.seconds_line_search);
    }
    let factor =
        info.log.iter().map(|l| l.seconds_setup).sum::<f64>() / info.log.len().max(1) as f64;
    row(
        scene,
        complex.len(),
        free,
        &format!("Newton (wall {wall:.2} s)"),
        factor,
        seconds.last().unwrap() / info.iterations.max(1) as f64,
        &info.energies,
        &seconds,
        best,
    );
    for (anderson, subdomains) in [(0, 0), (5, 0), (5, 4), (5, 16)] {
        let params = LocalGlobalParams {
            max_iterations: iterations,
            tolerance: 0.0,
            anderson,
            subdomains,
        };
        let (_, lg) = solve::minimize_local_global(complex, constraints, start, &params)?;
        let monotone = lg.energies.windows(2).all(|w| w[1] <= w[0]);
        let per = |s: f64| s * 1e3 / lg.iterations.max(1) as f64;
        let split = format!(
            "local {:.1}, global {:.1}, energy {:.1} ms/iteration",
            per(lg.seconds_local),
            per(lg.seconds_global),
            per(lg.seconds_energy)
        );
        let by = match subdomains {
            0 => String::new(),
            k => format!(", the global step by {k} subdomains"),
        };
        let name = match anderson {
            0 => format!("local-global ({split}{by})"),
            m => format!(
                "local-global + Anderson m={m} ({} kept; {split}{by})",
                lg.accelerated
            ),
        };
        row(
            scene,
            complex.len(),
            free,
            &format!("{name}{}", if monotone { "" } else { " NOT MONOTONE" }),
            lg.seconds_factor,
            lg.seconds_per_iteration,
            &lg.energies,
            &lg.seconds,
            best,
        );
    }
    Ok(())
}

/// A table row: when `energies` first come within each of [`GAPS`] of `best`.
#[allow(clippy::too_many_arguments)]
fn row(
    scene: &str,
    cells: usize,
    free: usize,
    method: &str,
    factor: f64,
    per_iteration: f64,
    energies: &[f64],
    seconds: &[f64],
    best: f64,
) {
    let mut cols = Vec::new();
    for gap in GAPS {
        match energies.iter().position(|&e| e <= best * (1.0 + gap)) {
            Some(k) => cols.extend([k.to_string(), format!("{:.3}", seconds[k])]),
            None => cols.extend(["–".to_string(), "–".to_string()]),
        }
    }
    let last = *energies.last().unwrap();
    println!(
        "| {scene} | {cells} | {free} | {method} | {factor:.4} | {:.2} | {} | {:.1e} |",
        per_iteration * 1e3,
        cols.join(" | ") + &format!(" | {}", energies.len() - 1),
        (last - best) / best
    );
}
