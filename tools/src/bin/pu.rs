//! The partition-of-unity RBF against the dense RBF on the same field: fit and evaluation
//! times, and how far apart the two maps are (as a fraction of the largest displacement).
//!
//! `cargo run --release -p rigidcells-tools --bin pu [MODEL.ply]`: the dragon bent by
//! `bend_spec` at about 1.2k and 5.5k cells, 480k samples on its surface, 2 threads.

use std::time::Instant;

use rigidcells::field::{Deformer, Field, PuRbf, Rbf, Warp, apply};
use rigidcells::io::Document;
use rigidcells::progress::Silent;
use rigidcells::solve::{self, SolveParams};
use rigidcells_tools::{bend_spec, build_at, cell_size_for, model_arg, surface_samples};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let model = model_arg();
    let doc = Document::read(&model)?;
    let (points, tris) = (doc.positions(), doc.triangles());
    let spec = bend_spec(points)?;
    let samples = surface_samples(points, tris, 480_000, 11);
    println!(
        "model {}, {} samples, {} threads",
        model.display(),
        samples.len(),
        rayon::current_num_threads()
    );
    println!(
        "| cells | patches | dense fit s | dense eval s | PU fit s | PU eval s | PU Mpts/s | max gap / max displacement |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for target in [1200usize, 5500] {
        let size = cell_size_for(points, tris, target)?;
        let complex = build_at(points, tris, size)?;
        let constraints = solve::resolve(&complex, &spec, points, None)?;
        let sol = solve::solve(complex, constraints, &SolveParams::default(), &Silent)?;
        let field = Field::from_solution(&sol);
        let t = Instant::now();
        let dense = Deformer::Rbf(Rbf::new(&field)?);
        let dense_fit = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let pu = PuRbf::new(&field)?;
        let pu_fit = t.elapsed().as_secs_f64();
        let patches = pu.patch_count();
        let pu = Deformer::Pu(pu);
        let mut a = samples.clone();
        let t = Instant::now();
        apply(&dense, &field.origin, &mut a);
        let dense_eval = t.elapsed().as_secs_f64();
        let mut b = samples.clone();
        let t = Instant::now();
        apply(&pu, &field.origin, &mut b);
        let pu_eval = t.elapsed().as_secs_f64();
        let largest = samples
            .iter()
            .zip(&a)
            .map(|(p, q)| (q - p).norm())
            .fold(0.0, f64::max);
        let gap = a
            .iter()
            .zip(&b)
            .map(|(p, q)| (p - q).norm())
            .fold(0.0, f64::max);
        // And at the centers, where both interpolate.
        let at_centers = field
            .centers
            .iter()
            .zip(&field.motions)
            .map(|(c, m)| (pu.warp(c) - m.pos).norm())
            .fold(0.0, f64::max);
        println!(
            "| {} | {patches} | {dense_fit:.2} | {dense_eval:.3} | {pu_fit:.3} | {pu_eval:.3} | {:.1} | {:.4} (at the centers {:.1e}) |",
            field.centers.len(),
            samples.len() as f64 / pu_eval / 1e6,
            gap / largest,
            at_centers / largest,
        );
    }
    Ok(())
}
