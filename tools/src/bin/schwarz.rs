//! The global step solved by subdomains (`solve::schwarz`) against the one-process factor:
//! conjugate-gradient iterations and seconds from 4 to 16 subdomains, and with one more layer
//! of overlap, on the corridor strips.
//!
//! `cargo run --release -p rigidcells-tools --bin schwarz [scene …]`; scenes `rough-2.5`,
//! `rough-1.25` (the `solver` tool's hilly 1 km × 200 m strip, 2M points, its west 5 % fixed and
//! east 5 % lifted by 20 m), `veg-2.5` (its vegetation strip). Each line: the free cells, the
//! subdomains, the overlap (layers of neighbors) and the aggregate size of the coarse space,
//! the coarse unknowns, the largest subdomain block (rows), the setup's seconds (every block and
//! the coarse problem factored), the iterations to a residual of 1e-8 of a random right-hand
//! side with three columns, their seconds, and the largest difference from the factored
//! solution relative to its largest entry. The first line of a scene is the factor itself.

use std::time::Instant;

use rand::{Rng, SeedableRng, rngs::StdRng};
use rigidcells::Budget;
use rigidcells::internal::cells::{BuildParams, build};
use rigidcells::internal::rigid::Vect;
use rigidcells::internal::solve::{self, laplacian, schwarz};
use rigidcells::parse_spec;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut scenes: Vec<String> = std::env::args().skip(1).collect();
    if scenes.is_empty() {
        scenes = vec!["rough-2.5".into()];
    }
    println!(
        "| scene | free cells | subdomains | overlap | aggregate | coarse | largest block | setup s \
         | iterations | solve s | difference |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for scene in &scenes {
        let (kind, size) = scene
            .split_once('-')
            .ok_or("scene: rough-2.5, rough-1.25 or veg-2.5")?;
        let size: f64 = size.parse()?;
        let n = 2_000_000u64;
        let mut terrain = match kind {
            "rough" => data_gen::Terrain::rough(n, data_gen::Relief::new(50.0, 100.0, 1)),
            "veg" => data_gen::Terrain::vegetation(n),
            other => return Err(format!("unknown scene `{other}`").into()),
        };
        let pts: Vec<Vect<3>> = (0..n)
            .map(|k| {
                let (x, y, z, _) = terrain.sample(k);
                Vect::<3>::new(x, y, z)
            })
            .collect();
        let spec =
            data_gen::end_lift_spec([0.0, 0.0, -100.0], [1000.0, 200.0, 300.0], 0.05, 20.0, 0.0);
        let params = BuildParams {
            cell_size: Some(size),
            ..Default::default()
        };
        let complex = build(&pts, &[], &params, Budget::default())?.0;
        drop(pts);
        let spec = parse_spec::<3>(&spec, ".".as_ref(), "edit.toml".as_ref())?;
        let constraints = solve::resolve(&complex, &spec, &[], None)?;
        let (l, row) = laplacian::Laplacian::of(&complex, &constraints);
        let rows = l.n;
        let mut rng = StdRng::seed_from_u64(1);
        let b: Vec<f64> = (0..3 * rows).map(|_| rng.random_range(-1.0..1.0)).collect();

        let start = Instant::now();
        let direct = schwarz::Factored::new(&l).ok_or("the matrix is singular")?;
        let setup = start.elapsed().as_secs_f64();
        let start = Instant::now();
        let exact = direct
            .solve(&b)
            .ok_or("the right-hand side is not whole columns")?;
        let seconds = start.elapsed().as_secs_f64();
        drop(direct);
        println!(
            "| {scene} | {rows} | 1 (factor) | | | | {rows} | {setup:.2} | | {seconds:.3} | |"
        );
        let scale = exact.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        let aggregate = schwarz::aggregate_size(rows);
        for (k, overlap) in [
            (4, schwarz::OVERLAP),
            (8, schwarz::OVERLAP),
            (16, schwarz::OVERLAP),
            (4, schwarz::OVERLAP + 1),
            (16, schwarz::OVERLAP + 1),
        ] {
            let start = Instant::now();
            let sub = schwarz::Subdomains::split(&complex, &row, k);
            let m = schwarz::Schwarz::new(&l, &sub, overlap, aggregate, None)?
                .ok_or("a block is singular")?;
            let setup = start.elapsed().as_secs_f64();
            let start = Instant::now();
            let mut x = vec![0.0; 3 * rows];
            let solved = schwarz::solve(&l, &m, &b, &mut x, 1e-8, 2000)?;
            let seconds = start.elapsed().as_secs_f64();
            let difference = x
                .iter()
                .zip(&exact)
                .map(|(x, e)| (x - e).abs())
                .fold(0.0, f64::max)
                / scale;
            println!(
                "| {scene} | {rows} | {k} | {overlap} | {aggregate} | {} | {} | {setup:.2} | {} | \
                 {seconds:.2} | {difference:.1e} |",
                m.coarse_len(),
                m.largest_block(),
                solved.iterations,
            );
        }
    }
    Ok(())
}
