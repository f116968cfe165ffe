//! The partition-of-unity RBF against the dense RBF on the same field: fit and evaluation
//! times, and how far apart the two maps are (as a fraction of the largest displacement).
//!
//! `cargo run --release -p rigidcells-tools --bin pu [MODEL.ply]`: the dragon bent by
//! `bend_spec` at about 1.2k and 5.5k cells, 480k samples on its surface (on random triangles,
//! and again in the order of a scan), 2 threads; then the
//! PU alone on synthetic terrain fields of 10k to 1M cells (two layers of unit cells under a
//! rolling surface, moved by a smooth bend), fit time and evaluation of 1M points in the order
//! of a scan. `pu --terrain [N]` runs the terrain table alone, or its
//! row of about N cells (for profiling the evaluation).

use std::time::Instant;

use rigidcells::internal::field::{Deformer, Field, PuRbf, Rbf, Warp, apply};
use rigidcells::internal::io::Document;
use rigidcells::internal::rigid::{Dim, Motion, Rigid, Vect};
use rigidcells_tools::{bend_spec, build_at, cell_size_for, model_arg, surface_samples};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    if std::env::args().nth(1).as_deref() == Some("--terrain") {
        return terrain_scale();
    }
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
        "| cells | patches | dense fit s | dense eval s | PU fit s | PU eval s | PU Mpts/s | in scan order | max gap / max displacement |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for target in [1200usize, 5500] {
        let size = cell_size_for(points, tris, target)?;
        let complex = build_at(points, tris, size)?;
        let sol = rigidcells_tools::solve_default(complex, &spec, points)?;
        let field = Field::from_solution(&sol);
        let t = Instant::now();
        let dense = Deformer::Rbf(Rbf::new(&field)?);
        let dense_fit = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let pu = PuRbf::new(&field)?;
        let pu_fit = t.elapsed().as_secs_f64();
        let patches = pu.patch_count();
        let pu = Deformer::Pu(Box::new(pu));
        let mut a = samples.clone();
        let t = Instant::now();
        apply(&dense, &field.origin, &mut a);
        let dense_eval = t.elapsed().as_secs_f64();
        let mut b = samples.clone();
        let t = Instant::now();
        apply(&pu, &field.origin, &mut b);
        let pu_eval = t.elapsed().as_secs_f64();
        // The same samples in the order of a scan (strips a cell wide, each along x), as a
        // file's samples come; the order above (random triangles) is the worst case.
        let mut scan = samples.clone();
        scan.sort_by(|p, q| {
            ((p.y / size).floor(), (p.z / size).floor(), p.x)
                .partial_cmp(&((q.y / size).floor(), (q.z / size).floor(), q.x))
                .expect("finite")
        });
        let t = Instant::now();
        apply(&pu, &field.origin, &mut scan);
        let pu_scan = t.elapsed().as_secs_f64();
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
            "| {} | {patches} | {dense_fit:.2} | {dense_eval:.3} | {pu_fit:.3} | {pu_eval:.3} | {:.1} | {:.1} | {:.4} (at the centers {:.1e}) |",
            field.centers.len(),
            samples.len() as f64 / pu_eval / 1e6,
            samples.len() as f64 / pu_scan / 1e6,
            gap / largest,
            at_centers / largest,
        );
    }
    terrain_scale()?;
    Ok(())
}

/// A terrain field of about `n` unit cells: a `w × w` sheet two cells thick following a rolling
/// surface, bent smoothly (each cell turned about y by an angle growing along x and lifted).
fn terrain(n: usize) -> Field<3> {
    let w = ((n / 2) as f64).sqrt().round() as i64;
    let mut centers = Vec::new();
    for i in 0..w {
        for j in 0..w {
            let ground = (0.05 * i as f64).sin() * 3.0 + (0.07 * j as f64).cos() * 2.0;
            for k in 0..2 {
                centers.push(Vect::<3>::new(
                    i as f64 + 0.5,
                    j as f64 + 0.5,
                    ground.floor() + k as f64 + 0.5,
                ));
            }
        }
    }
    let motions = centers
        .iter()
        .map(|c| {
            let t = c.x / w as f64;
            let rot = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::y(), -0.3 * t);
            Motion {
                rot,
                pos: c + Vect::<3>::new(0.0, 0.0, 20.0 * t * t),
            }
        })
        .collect();
    Field {
        origin: Vect::<3>::zeros(),
        halves: vec![0.5; centers.len()],
        centers,
        motions,
        prescribed: Default::default(),
        heights_kept: false,
        trend: Default::default(),
    }
}

fn terrain_scale() -> Result<(), Box<dyn std::error::Error>> {
    println!();
    println!("| terrain cells | patches | PU fit s | eval 1M points s | M points/s |");
    println!("|---|---|---|---|---|");
    // `pu --terrain N`: the field of about N cells alone.
    let sizes: Vec<usize> = match std::env::args().nth(2) {
        Some(n) => vec![n.parse()?],
        None => vec![10_000, 100_000, 1_000_000],
    };
    for n in sizes {
        let field = terrain(n);
        let t = Instant::now();
        let pu = PuRbf::new(&field)?;
        let fit = t.elapsed().as_secs_f64();
        let patches = pu.patch_count();
        let w = ((n / 2) as f64).sqrt();
        let mut points: Vec<Vect<3>> = (0..1_000_000u64)
            .map(|i| {
                let s = i as f64;
                let (x, y) = (
                    (s * 0.6180339887).fract() * w,
                    (s * 0.7548776662).fract() * w,
                );
                let ground = (0.05 * x).sin() * 3.0 + (0.07 * y).cos() * 2.0;
                Vect::<3>::new(x, y, ground.floor() + 1.0)
            })
            .collect();
        // In the order of a scan: strips 4 cells wide, each along x (the golden-ratio order
        // above jumps across the whole field from one point to the next).
        points.sort_by(|a, b| {
            ((a.y / 4.0) as i64, a.x)
                .partial_cmp(&((b.y / 4.0) as i64, b.x))
                .expect("finite")
        });
        let t = Instant::now();
        apply(&Deformer::Pu(Box::new(pu)), &field.origin, &mut points);
        let eval = t.elapsed().as_secs_f64();
        println!(
            "| {} | {patches} | {fit:.2} | {eval:.3} | {:.1} |",
            field.centers.len(),
            1.0 / eval
        );
    }
    Ok(())
}
