//! Shared pieces of the harnesses: the default model and its resamplings to the paper's sizes,
//! the bend edit, cell complexes of a chosen size, and random samples on a model's surface.

use std::path::PathBuf;

use data_gen::{Mesh, decimate, split_to, subdivide};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rigidcells::Budget;
use rigidcells::Error;
use rigidcells::Vect;
use rigidcells::internal::cells::{BuildParams, CellComplex, build};
use rigidcells::{EditSpec, parse_spec};

/// The model of [`model_arg`] as a mesh, and its path; prints a line naming it with `what`
/// (the harness's units and conventions) after the vertex and thread counts.
pub fn load_scan(what: &str) -> Result<(PathBuf, Mesh), Box<dyn std::error::Error>> {
    let model = model_arg();
    let doc = rigidcells::internal::io::Document::read(&model)?;
    let scan = Mesh {
        vertices: doc.positions().iter().map(|p| [p.x, p.y, p.z]).collect(),
        triangles: doc.triangles().to_vec(),
    };
    println!(
        "model {} ({} vertices), {} threads{what}",
        model.display(),
        scan.vertices.len(),
        rayon::current_num_threads()
    );
    Ok((model, scan))
}

/// `scan` with about `vertices` vertices: decimated by vertex clustering, or subdivided and
/// split (the paper's Table 1 sizes from one real scan).
pub fn resampled(scan: &Mesh, vertices: usize) -> Mesh {
    if vertices < scan.vertices.len() {
        decimate(scan, vertices)
    } else {
        let mut m = scan.clone();
        while 4 * m.vertices.len() < vertices {
            m = subdivide(&m);
        }
        split_to(&m, vertices)
    }
}

/// The bend of the harnesses: the lowest 15 % of `points` along their longest axis is fixed,
/// the highest 15 % turns by 60° and lifts by a quarter of the length.
pub fn bend_spec(points: &[Vect<3>]) -> Result<EditSpec<3>, Error> {
    let (mut lo, mut hi) = (points[0], points[0]);
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let ext = hi - lo;
    let axis = ext.imax();
    let up = (axis + 1) % 3;
    let side = 3 - axis - up;
    let low = lo[axis] + 0.15 * ext[axis];
    let high = hi[axis] - 0.15 * ext[axis];
    let bounds = |a: f64, b: f64| {
        let mut min = lo - ext * 0.1;
        let mut max = hi + ext * 0.1;
        min[axis] = a;
        max[axis] = b;
        format!(
            "{{ min = {:?}, max = {:?} }}",
            min.as_slice(),
            max.as_slice()
        )
    };
    let mut rot_axis = [0.0; 3];
    rot_axis[side] = 1.0;
    let mut lift = [0.0; 3];
    lift[up] = 0.25 * ext[axis];
    let text = format!(
        "[[fixed]]\nbox = {}\n[[handle]]\nbox = {}\nrotate = {{ axis = {rot_axis:?}, degrees = 60.0 }}\ntranslate = {lift:?}\n",
        bounds(lo[axis] - ext[axis], low),
        bounds(high, hi[axis] + ext[axis])
    );
    parse_spec::<3>(
        &text,
        std::path::Path::new("."),
        std::path::Path::new("bend.toml"),
    )
}

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
    Ok(build(points, tris, &params, Budget::default())?.0)
}

/// The finest cell size that gives about `target` cells (the library's bisection).
pub fn cell_size_for(points: &[Vect<3>], tris: &[[u32; 3]], target: usize) -> Result<f64, Error> {
    rigidcells::internal::cells::cell_size_for(
        points,
        tris,
        &BuildParams::default(),
        target,
        Budget::default(),
    )
}

/// The solve of `spec` on `complex` with the default parameters and budget, the constraints
/// resolved on `points`.
pub fn solve_default(
    complex: CellComplex<3>,
    spec: &EditSpec<3>,
    points: &[Vect<3>],
) -> Result<rigidcells::internal::solve::Solution<3>, Error> {
    let constraints = rigidcells::internal::solve::resolve(&complex, spec, points, None)?;
    rigidcells::internal::solve::solve(
        complex,
        constraints,
        &rigidcells::internal::solve::SolveParams::default(),
        Budget::default(),
        &rigidcells::internal::progress::Silent,
    )
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
