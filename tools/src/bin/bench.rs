//! Measures the engine on a real scan: the solve (seconds per Gauss-Newton iteration and
//! iterations to converge) at about 1.2k and 5.5k cells, and the blend and RBF transfers to
//! 50k points — the quantities of the paper's Table 1.
//!
//! `cargo run --release -p rigidcells-tools --bin bench [MODEL.ply]`; the default model is the
//! decimated Stanford dragon in `../shared/data/meshes`. The edit bends the model: the lowest
//! 15% along its longest axis is fixed, the highest 15% turns by 60° and lifts.

use std::time::Instant;

use rigidcells::internal::field::{Deformer, Field, Transfer, apply};
use rigidcells::internal::io::Document;
use rigidcells_tools::{bend_spec, build_at, cell_size_for, model_arg, surface_samples};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let model = model_arg();
    let doc = Document::read(&model)?;
    let (points, tris) = (doc.positions(), doc.triangles());
    let spec = bend_spec(points)?;
    println!(
        "model {} ({} vertices, {} triangles), {} threads",
        model.display(),
        points.len(),
        tris.len(),
        rayon::current_num_threads()
    );

    // 50k query points: random points on the model's triangles.
    let samples = surface_samples(points, tris, 50_000, 5);

    println!(
        "| cells | build s | unknowns | load steps | GN iterations | s/iteration | solve s | blend 50k s | RBF factor s | RBF eval 50k s |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for target in [1200usize, 5500] {
        let size = cell_size_for(points, tris, target)?;
        let t = Instant::now();
        let complex = build_at(points, tris, size)?;
        let t_build = t.elapsed().as_secs_f64();
        let cells = complex.len();
        let sol = rigidcells_tools::solve_default(complex, &spec, points)?;
        let field = Field::from_solution(&sol);
        let t = Instant::now();
        let blend = Deformer::new(&field, Transfer::Blend)?;
        let mut moved = samples.clone();
        apply(&blend, &field.origin, &mut moved);
        let t_blend = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let rbf = Deformer::new(&field, Transfer::Rbf)?;
        let t_factor = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mut moved = samples.clone();
        apply(&rbf, &field.origin, &mut moved);
        let t_eval = t.elapsed().as_secs_f64();
        let info = &sol.info;
        println!(
            "| {cells} | {t_build:.3} | {} | {} | {} | {:.4} | {:.2} | {t_blend:.3} | {t_factor:.2} | {t_eval:.2} |",
            info.unknowns,
            info.load_steps,
            info.iterations,
            info.seconds_per_iteration(),
            info.seconds,
        );
    }
    Ok(())
}
