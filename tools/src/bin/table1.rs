//! The paper's Table 1, reproduced: the dragon at 5k, 50k and 480k vertices (the real scan in
//! `../shared/data/meshes`, decimated or subdivided by `data_gen`) at about 1.2k and 5.5k
//! cells, with the paper's columns — voxelization, one Gauss-Newton iteration, the per-frame
//! blend of the vertices and the final RBF deformation of the vertices — and the paper's
//! seconds (Mac Pro 2.66 GHz, 2007) with the ratio beside each.
//!
//! `cargo run --release -p rigidcells-tools --bin table1 [MODEL.ply]`
//!
//! The edit bends the model (`bend_spec`: the lowest 15 % fixed, the highest 15 % turned by 60°
//! and lifted). Every time is the median of 3 runs. "GN iteration" is the solve's seconds
//! over its iterations (the solve to convergence is shown too). "Blend" builds the blend for
//! the solved field (tiles filled as the vertices need them) and moves every vertex; "RBF"
//! factors the interpolation system and moves every vertex.

use std::time::Instant;

use rigidcells::Budget;
use rigidcells::Silent;
use rigidcells::Vect;
use rigidcells::internal::cells::{BuildParams, build};
use rigidcells::internal::field::{Deformer, Field, Transfer, apply};
use rigidcells::internal::solve::{self, SolveParams};
use rigidcells_tools::{bend_spec, cell_size_for, load_scan, resampled};

/// The paper's dragon rows: vertices, cells, voxelization, solve (one Newton iteration),
/// blend, RBF, in seconds.
const PAPER: [(usize, usize, f64, f64, f64, f64); 6] = [
    (5_000, 1_176, 0.57, 0.26, 0.005, 0.09),
    (5_000, 5_518, 0.58, 1.66, 0.005, 0.49),
    (50_000, 1_175, 0.72, 0.26, 0.072, 0.84),
    (50_000, 5_519, 0.73, 1.66, 0.072, 3.58),
    (480_000, 1_176, 1.62, 0.28, 0.981, 8.18),
    (480_000, 5_535, 1.63, 1.74, 0.981, 34.10),
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (_, scan) = load_scan("; seconds, paper's in parentheses, paper / ours after")?;
    println!(
        "| vertices | cells | voxel. | GN iteration | solve (iterations) | blend | RBF (factor + evaluate) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (vertices, cells, p_voxel, p_solve, p_blend, p_rbf) in PAPER {
        let mesh = resampled(&scan, vertices);
        let points: Vec<Vect<3>> = mesh.vertices.iter().map(|v| Vect::<3>::from(*v)).collect();
        let spec = bend_spec(&points)?;
        let params = BuildParams {
            cell_size: Some(cell_size_for(&points, &mesh.triangles, cells)?),
            ..Default::default()
        };
        // Medians of three runs: this machine's timings vary by ±20 % from run to run.
        let (complex, voxel) = median_of_3(|| {
            let t = Instant::now();
            let complex = build(&points, &mesh.triangles, &params, Budget::default())?.0;
            Ok::<_, rigidcells::Error>((complex, t.elapsed().as_secs_f64()))
        })?;
        let got_cells = complex.len();
        let (sol, iteration) = median_of_3(|| {
            let constraints = solve::resolve(&complex, &spec, &points, None)?;
            let sol = solve::solve(
                complex.clone(),
                constraints,
                &SolveParams::default(),
                Budget::default(),
                &Silent,
            )?;
            let iteration = sol.info.seconds_per_iteration();
            Ok::<_, rigidcells::Error>((sol, iteration))
        })?;
        let field = Field::from_solution(&sol);
        let timed = |transfer| -> Result<f64, rigidcells::Error> {
            let ((), seconds) = median_of_3(|| {
                let mut moved = points.clone();
                let t = Instant::now();
                let deformer = Deformer::new(&field, transfer)?;
                apply(&deformer, &field.origin, &mut moved);
                Ok::<_, rigidcells::Error>(((), t.elapsed().as_secs_f64()))
            })?;
            Ok(seconds)
        };
        let blend = timed(Transfer::Blend)?;
        let rbf = timed(Transfer::Rbf)?;
        let ratio = |paper: f64, ours: f64| match paper / ours {
            r if r < 10.0 => format!("{r:.1}×"),
            r => format!("{r:.0}×"),
        };
        println!(
            "| {} | {got_cells} | {voxel:.3} ({p_voxel}) {} | {iteration:.3} ({p_solve}) {} | {:.2} ({}) | {blend:.4} ({p_blend}) {} | {rbf:.2} ({p_rbf}) {} |",
            points.len(),
            ratio(p_voxel, voxel),
            ratio(p_solve, iteration),
            sol.info.seconds,
            sol.info.iterations,
            ratio(p_blend, blend),
            ratio(p_rbf, rbf),
        );
    }
    Ok(())
}

/// Runs `run` three times and keeps the run whose measure (the second of its pair) is the
/// median.
fn median_of_3<T, E>(mut run: impl FnMut() -> Result<(T, f64), E>) -> Result<(T, f64), E> {
    let mut runs = vec![run()?, run()?, run()?];
    runs.sort_by(|a, b| a.1.total_cmp(&b.1));
    Ok(runs.swap_remove(1))
}
