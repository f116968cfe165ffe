//! What the exact-constraint layer ([`rigidcells::internal::field::FieldMap`]) costs: the blend and
//! the RBF alone against the same transfers with fixed and handle samples made exact and the
//! domain checked, on the same samples in the same run (medians of 5 alternating runs).
//!
//! `cargo run --release -p rigidcells-tools --bin constrained [MODEL.ply]`; the default model is
//! the decimated Stanford dragon, bent by `bend_spec` (lowest 15% fixed, highest 15% turned),
//! at about 5.5k cells, with 480k samples on its surface (the paper's largest model's size).

use std::time::Instant;

use rigidcells::Vect;
use rigidcells::internal::field::{Deformer, Field, FieldMap, Outside, Transfer, Warp, apply};
use rigidcells::internal::io::Document;
use rigidcells_tools::{bend_spec, build_at, cell_size_for, model_arg, surface_samples};

fn seconds(warp: &impl Warp<3>, origin: &Vect<3>, samples: &[Vect<3>]) -> f64 {
    let mut moved = samples.to_vec();
    let t = Instant::now();
    apply(warp, origin, &mut moved);
    t.elapsed().as_secs_f64()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let model = model_arg();
    let doc = Document::read(&model)?;
    let (points, tris) = (doc.positions(), doc.triangles());
    let spec = bend_spec(points)?;
    let samples = surface_samples(points, tris, 480_000, 7);
    let size = cell_size_for(points, tris, 5500)?;
    let complex = build_at(points, tris, size)?;
    let sol = rigidcells_tools::solve_default(complex, &spec, points)?;
    let field = Field::from_solution(&sol);
    let exact = field
        .prescribed
        .cells
        .iter()
        .filter(|&&m| m != u32::MAX)
        .count();
    println!(
        "model {}: {} cells ({exact} fixed or handle), {} samples, {} threads",
        model.display(),
        field.centers.len(),
        samples.len(),
        rayon::current_num_threads()
    );
    println!("| transfer | alone s | exact + domain s | ratio | layer build s |");
    println!("|---|---|---|---|---|");
    for transfer in [Transfer::Blend, Transfer::Rbf] {
        let alone = Deformer::new(&field, transfer)?;
        let inner = Deformer::new(&field, transfer)?;
        let t = Instant::now();
        let layered = FieldMap::new(&field, inner, Outside::Refuse)?;
        let build = t.elapsed().as_secs_f64();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for _ in 0..5 {
            a.push(seconds(&alone, &field.origin, &samples));
            b.push(seconds(&layered, &field.origin, &samples));
        }
        let (a, b) = (median(a), median(b));
        println!(
            "| {transfer:?} | {a:.3} | {b:.3} | {:.2} | {build:.4} |",
            b / a
        );
    }
    Ok(())
}
