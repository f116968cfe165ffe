//! The blend's nearest-center search and transfer, measured and checked on a real scan.
//!
//! `cargo run --release -p rigidcells-tools --bin blend [MODEL.ply]` (default: the decimated
//! dragon). For about 1.2k and 5.5k cells, 480k random surface samples (the paper's largest
//! model) are queried by: a kiddo kd-tree (`k = 5`, the generic reference), the tiled search of
//! `rigidcells::internal::field::Nearest` (tiles filled on the way, as in a real run), and the whole blend
//! transfer in both weightings. The tiled search runs again on the samples sorted into a
//! spatially coherent order, as scans come. The tiled neighbors are compared with the brute-force scan on
//! 100k samples, and the transfer's bits with one thread against all threads.

use std::num::NonZero;
use std::time::Instant;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rayon::prelude::*;
use rigidcells::internal::field::{Deformer, Field, NEAR, Nearest, Transfer, apply};
use rigidcells::internal::io::Document;
use rigidcells::internal::rigid::{Dim, Motion, Rigid, Vect};
use rigidcells_tools::{build_at, cell_size_for, model_arg, surface_samples};

const SAMPLES: usize = 480_000;
const CHECKED: usize = 100_000;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let model = model_arg();
    let doc = Document::read(&model)?;
    let (points, tris) = (doc.positions(), doc.triangles());
    let samples = surface_samples(points, tris, SAMPLES, 5);
    println!(
        "model {} ({} vertices), {SAMPLES} surface samples, {} threads",
        model.display(),
        points.len(),
        rayon::current_num_threads()
    );
    println!(
        "| cells | kd-tree k=5 s | tiled s (filling tiles) | speed-up | tiled s (coherent order, \
         tiles filled) | tiles filled | mean candidates | blend s | blend-idw s | \
         tiled = brute force | 1 thread = all |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for target in [1200usize, 5500] {
        let size = cell_size_for(points, tris, target)?;
        let complex = build_at(points, tris, size)?;
        let field = random_field(&complex);
        let local: Vec<[f64; 3]> = samples.iter().map(|p| (p - field.origin).into()).collect();

        let t = Instant::now();
        let centers: Vec<[f64; 3]> = field.centers.iter().map(|c| (*c).into()).collect();
        let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&centers)?;
        let k = NonZero::new(NEAR).expect("NEAR > 0");
        let kd_sum: u64 = local
            .par_iter()
            .map(|x| {
                let near = tree
                    .query(x)
                    .nearest_n::<SquaredEuclidean<f64>>(k)
                    .execute();
                near.iter().map(|r| r.item as u64).sum::<u64>()
            })
            .sum();
        let t_kd = t.elapsed().as_secs_f64();

        let t = Instant::now();
        let nearest = Nearest::new(&field.centers, &field.halves)?;
        // A checksum of the neighbors found, so that the queries cannot be optimized away.
        let query = |points: &[[f64; 3]]| -> u64 {
            points
                .par_iter()
                .map(|x| {
                    let nb = nearest.find(x);
                    nb.cells[..nb.n].iter().map(|&c| c as u64).sum::<u64>()
                })
                .sum()
        };
        let tiled_sum = query(&local);
        let t_tiled = t.elapsed().as_secs_f64();
        // The same queries again in a spatially coherent order (as scans come), tiles filled.
        let mut coherent = local.clone();
        let q = size / 2.0;
        coherent.sort_by_key(|x| x.map(|v| (v / q).floor() as i64));
        let t = Instant::now();
        let coherent_sum = query(&coherent);
        let t_coherent = t.elapsed().as_secs_f64();
        let (_, filled) = nearest.tile_counts();

        let same_neighbors = local[..CHECKED]
            .par_iter()
            .all(|x| nearest.find(x) == nearest.brute_force(x));
        // Both sums count the same neighbor sets unless distances tie.
        let sums_agree = kd_sum == tiled_sum && coherent_sum == tiled_sum;

        let mut times = [0.0; 2];
        let mut moved_all = Vec::new();
        for (slot, transfer) in times.iter_mut().zip([Transfer::Blend, Transfer::BlendIdw]) {
            let t = Instant::now();
            let blend = Deformer::new(&field, transfer)?;
            let mut moved = samples.clone();
            apply(&blend, &field.origin, &mut moved);
            *slot = t.elapsed().as_secs_f64();
            if transfer == Transfer::Blend {
                moved_all = moved;
            }
        }
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
        let moved_one = one.install(|| -> Result<_, rigidcells::Error> {
            let blend = Deformer::new(&field, Transfer::Blend)?;
            let mut moved = samples.clone();
            apply(&blend, &field.origin, &mut moved);
            Ok(moved)
        })?;
        println!(
            "| {} | {t_kd:.4} | {t_tiled:.4} | {:.1}× | {t_coherent:.4} | {filled} | {:.1} | {:.4} | {:.4} | {} | {} |",
            field.centers.len(),
            t_kd / t_tiled,
            nearest.mean_candidates(),
            times[0],
            times[1],
            if same_neighbors {
                "identical"
            } else {
                "DIFFERENT"
            },
            if moved_one == moved_all {
                "identical"
            } else {
                "DIFFERENT"
            },
        );
        if !same_neighbors || !sums_agree || moved_one != moved_all {
            return Err("the tiled search disagrees with the reference".into());
        }
    }
    Ok(())
}

/// The complex's cells, each turned by a random rotation of up to 0.3 rad and shifted a little.
fn random_field(complex: &rigidcells::internal::cells::CellComplex<3>) -> Field<3> {
    let mut rng = StdRng::seed_from_u64(3);
    let h = complex.cells[0].half;
    Field {
        origin: complex.grid.origin,
        centers: complex.cells.iter().map(|c| c.center).collect(),
        halves: complex.cells.iter().map(|c| c.half).collect(),
        motions: complex
            .cells
            .iter()
            .map(|c| {
                let axis = Vect::<3>::from_fn(|_, _| rng.random_range(-1.0..1.0));
                Motion {
                    rot: <Dim<3> as Rigid<3>>::axis_angle(&axis, rng.random_range(0.0..0.3)),
                    pos: c.center + Vect::<3>::from_fn(|_, _| rng.random_range(-h..h)),
                }
            })
            .collect(),
        prescribed: Default::default(),
        heights_kept: false,
        trend: Default::default(),
    }
}
