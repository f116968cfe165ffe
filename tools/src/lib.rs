//! Shared pieces of the harnesses: the default model, cell complexes of a chosen size, and
//! random samples on a model's surface.

use std::path::PathBuf;

use rand::{Rng, SeedableRng, rngs::StdRng};
use rigidcells::Error;
use rigidcells::cells::{BuildParams, CellComplex, build};
use rigidcells::rigid::Vect;

/// The decimated Stanford dragon in `../shared/data/meshes`, or the model named by the first
/// argument.
pub fn model_arg() -> PathBuf {
    std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../../shared/data/meshes/dragon_11k_binary.ply")
        })
}

/// The cell complex with finest cells of `size`.
pub fn build_at(points: &[Vect<3>], tris: &[[u32; 3]], size: f64) -> Result<CellComplex<3>, Error> {
    let params = BuildParams {
        cell_size: Some(size),
        ..Default::default()
    };
    Ok(build(points, tris, &params)?.0)
}

/// The finest cell size that gives about `target` cells (the library's bisection).
pub fn cell_size_for(points: &[Vect<3>], tris: &[[u32; 3]], target: usize) -> Result<f64, Error> {
    rigidcells::cells::cell_size_for(points, tris, &BuildParams::default(), target)
}

/// `n` random points on the triangles (uniform per triangle, triangles chosen uniformly).
pub fn surface_samples(points: &[Vect<3>], tris: &[[u32; 3]], n: usize, seed: u64) -> Vec<Vect<3>> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let t = tris[rng.random_range(0..tris.len())];
            let (mut u, mut v) = (rng.random::<f64>(), rng.random::<f64>());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let [a, b, c] = t.map(|i| points[i as usize]);
            a + (b - a) * u + (c - a) * v
        })
        .collect()
}
