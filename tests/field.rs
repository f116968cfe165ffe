//! The transfers against their definitions: the RBF interpolates the cell-center
//! displacements; blend weights sum to one over the true 4 nearest centers.

use rand::{Rng, SeedableRng, rngs::StdRng};
use rigidcells::field::{Blend, Field, Rbf, Warp};
use rigidcells::rigid::{Dim, Motion, Rigid, Vect};

fn field(n: usize, seed: u64) -> Field<3> {
    let mut rng = StdRng::seed_from_u64(seed);
    // Centers on a jittered lattice (like octree centers, several sizes) with smooth motions.
    let centers: Vec<Vect<3>> = (0..n)
        .map(|i| {
            let s = if i % 3 == 0 { 0.25 } else { 0.125 };
            Vect::<3>::new(
                ((i * 7) % 23) as f64 * s,
                ((i * 5) % 17) as f64 * s + 0.01 * (i % 5) as f64,
                (i / 391) as f64 * 0.3 + 0.001 * i as f64,
            )
        })
        .collect();
    let motions = centers
        .iter()
        .map(|c| {
            let rot = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::new(0.0, 1.0, 0.2), 0.3 * c.x);
            Motion {
                rot,
                pos: c + Vect::<3>::new(
                    0.1 * c.y,
                    (0.5 * c.x).sin(),
                    rng.random_range(-0.05..0.05),
                ),
            }
        })
        .collect();
    Field {
        origin: Vect::<3>::new(5e6, -2e6, 100.0),
        halves: vec![0.0625; n],
        centers,
        motions,
    }
}

#[test]
fn rbf_reproduces_every_center_displacement() {
    let f = field(2000, 1);
    let rbf = Rbf::new(&f).unwrap();
    let extent = 6.0;
    let worst = f
        .centers
        .iter()
        .zip(&f.motions)
        .map(|(c, m)| (rbf.warp(c) - m.pos).norm() / extent)
        .fold(0.0, f64::max);
    assert!(worst <= 1e-9, "worst relative error {worst:e}");
}

#[test]
fn blend_weights_sum_to_one_over_the_nearest_centers() {
    let f = field(1500, 2);
    let blend = Blend::new(&f).unwrap();
    let mut rng = StdRng::seed_from_u64(9);
    for _ in 0..500 {
        let x = Vect::<3>::new(
            rng.random_range(-0.5..6.0),
            rng.random_range(-0.5..4.5),
            rng.random_range(-0.2..1.5),
        );
        let (w, n) = blend.weights(&x);
        assert_eq!(n, 4);
        let sum: f64 = w[..n].iter().map(|p| p.1).sum();
        assert!((sum - 1.0).abs() < 1e-12);
        // The blended cells are the 4 nearest (brute force).
        let mut d: Vec<(f64, usize)> = f
            .centers
            .iter()
            .enumerate()
            .map(|(i, c)| ((c - x).norm(), i))
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        let far = w[..n]
            .iter()
            .map(|p| (f.centers[p.0] - x).norm())
            .fold(0.0, f64::max);
        assert!(
            far <= d[3].0 * (1.0 + 1e-12),
            "a blended cell is not among the 4 nearest"
        );
        // Closer cells weigh more.
        for a in &w[..n] {
            for b in &w[..n] {
                let (da, db) = ((f.centers[a.0] - x).norm(), (f.centers[b.0] - x).norm());
                if da < db {
                    assert!(a.1 >= b.1);
                }
            }
        }
    }
    // At a center the sample takes that cell's motion.
    let c = f.centers[17];
    let got = blend.warp(&(c + Vect::<3>::repeat(1e-16)));
    assert!((got - f.motions[17].pos).norm() < 1e-9);
}

/// Under one rigid motion of every cell, both transfers turn normals by its rotation, and the
/// fused position-and-normal evaluation agrees with the separate ones bit for bit.
#[test]
fn normals_turn_with_a_rigid_field() {
    let mut f = field(600, 4);
    let rot = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::new(0.3, -1.0, 0.5), 0.7);
    let shift = Vect::<3>::new(0.2, -0.1, 0.4);
    for (c, m) in f.centers.iter().zip(&mut f.motions) {
        *m = Motion {
            rot,
            pos: rot * c + shift,
        };
    }
    let blend = Blend::new(&f).unwrap();
    let rbf = Rbf::new(&f).unwrap();
    let mut rng = StdRng::seed_from_u64(9);
    for _ in 0..200 {
        let x = Vect::<3>::from_fn(|_, _| rng.random_range(0.0..4.0));
        let n = Vect::<3>::from_fn(|_, _| rng.random_range(-1.0..1.0)).normalize();
        let want = rot * n;
        for (name, warp) in [
            ("blend", &blend as &dyn Warp<3>),
            ("rbf", &rbf as &dyn Warp<3>),
        ] {
            let (y, m) = warp.warp_with_normal(&x, &n);
            assert!((m - want).norm() < 1e-6, "{name}: normal {m:?} vs {want:?}");
            assert_eq!(y, warp.warp(&x), "{name}: fused position");
            assert_eq!(m, warp.warp_normal(&x, &n), "{name}: fused normal");
        }
    }
}
