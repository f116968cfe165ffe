//! Voxelization (building the cell complex) of the dragon at the paper's Table 1 sizes: 5k, 50k
//! and 480k vertices (the real scan in `../shared/data/meshes`, decimated by vertex clustering
//! or subdivided and split by `data_gen`), at about 1.2k and 5.5k cells, with the paper's
//! column (Mac Pro 2.66 GHz, 2007) and the ratio beside each. The time covers triangle–cell
//! overlap, the winding-number BVH and inside classification, and emitting the octree leaves
//! (median of 3 runs).
//!
//! `cargo run --release -p rigidcells-tools --bin voxel [MODEL.ply]`

use std::time::Instant;

use rigidcells::Budget;
use rigidcells::Vect;
use rigidcells::internal::cells::{BuildParams, build};
use rigidcells_tools::{cell_size_for, load_scan, resampled};

/// The paper's rows: vertices, cells, voxelization seconds.
const PAPER: [(usize, usize, f64); 6] = [
    (5_000, 1_176, 0.57),
    (5_000, 5_518, 0.58),
    (50_000, 1_175, 0.72),
    (50_000, 5_519, 0.73),
    (480_000, 1_176, 1.62),
    (480_000, 5_535, 1.63),
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (_, scan) = load_scan("")?;
    println!(
        "| vertices | triangles | cells | interior | voxelization s | paper s | paper / ours |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (vertices, cells, paper) in PAPER {
        let mesh = resampled(&scan, vertices);
        let points: Vec<Vect<3>> = mesh.vertices.iter().map(|v| Vect::<3>::from(*v)).collect();
        let size = cell_size_for(&points, &mesh.triangles, cells)?;
        let params = BuildParams {
            cell_size: Some(size),
            ..Default::default()
        };
        let mut times = Vec::new();
        let mut info = None;
        for _ in 0..3 {
            let t = Instant::now();
            let (complex, i) = build(&points, &mesh.triangles, &params, Budget::default())?;
            times.push(t.elapsed().as_secs_f64());
            info = Some((complex.len(), i.interior_cells));
        }
        times.sort_by(f64::total_cmp);
        let (got, interior) = info.expect("three runs");
        println!(
            "| {} | {} | {got} | {interior} | {:.3} | {paper:.2} | {:.0}× |",
            points.len(),
            mesh.triangles.len(),
            times[1],
            paper / times[1]
        );
    }
    Ok(())
}
