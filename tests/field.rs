//! The transfers against their definitions: the RBF interpolates the cell-center
//! displacements; blend weights sum to one over the true 4 nearest centers.

use rand::{Rng, SeedableRng, rngs::StdRng};
use rigidcells::internal::field::{
    Anchor, Blend, Deformer, Field, Nearest, Rbf, Transfer, Warp, Weights, foldovers,
};
use rigidcells::internal::rigid::{Dim, Motion, Rigid, Vect};

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
        prescribed: Default::default(),
        heights_kept: false,
        trend: Default::default(),
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
    // Cholesky on the projected system with one refinement step: 7.2e-11 here with the
    // portable kernel, 8.8e-11 with AVX-512's (LU on the saddle-point system gave 1.2e-10).
    assert!(worst <= 1e-10, "worst relative error {worst:e}");
}

#[test]
fn blend_weights_sum_to_one_over_the_nearest_centers() {
    let f = field(1500, 2);
    let blend = Blend::new(&f, Weights::InverseDistance).unwrap();
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
    let blend = Blend::new(&f, Weights::InverseDistance).unwrap();
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

/// Cells of an octree: a 10×8×6 lattice of unit cells whose first 2×2×2 blocks along x < 4 are
/// merged into cells of edge 2, so queries see two sizes and exact ties on the lattice.
fn octree_field() -> Field<3> {
    let mut rng = StdRng::seed_from_u64(21);
    let (mut centers, mut halves) = (Vec::new(), Vec::new());
    for k in 0..6 {
        for j in 0..8 {
            for i in 0..10 {
                if i < 4 {
                    if i % 2 == 0 && j % 2 == 0 && k % 2 == 0 {
                        centers.push(Vect::<3>::new(
                            i as f64 + 1.0,
                            j as f64 + 1.0,
                            k as f64 + 1.0,
                        ));
                        halves.push(1.0);
                    }
                } else {
                    centers.push(Vect::<3>::new(
                        i as f64 + 0.5,
                        j as f64 + 0.5,
                        k as f64 + 0.5,
                    ));
                    halves.push(0.5);
                }
            }
        }
    }
    let motions = centers
        .iter()
        .map(|c| Motion {
            rot: <Dim<3> as Rigid<3>>::axis_angle(
                &Vect::<3>::new(rng.random(), rng.random(), 1.0),
                rng.random_range(0.0..0.4),
            ),
            pos: c + Vect::<3>::from_fn(|_, _| rng.random_range(-0.2..0.2)),
        })
        .collect();
    Field {
        origin: Vect::<3>::zeros(),
        centers,
        halves,
        motions,
        prescribed: Default::default(),
        heights_kept: false,
        trend: Default::default(),
    }
}

/// The tiled search finds exactly the brute-force neighbors, ties included (the order is
/// distance, then cell index): at random points, on the lattice (where many centers tie) and
/// outside the cells.
#[test]
fn tiled_nearest_centers_equal_brute_force() {
    let f = octree_field();
    let nearest = Nearest::new(&f.centers, &f.halves).unwrap();
    let mut rng = StdRng::seed_from_u64(4);
    let mut queries: Vec<[f64; 3]> = (0..20_000)
        .map(|_| std::array::from_fn(|a| rng.random_range(-1.0..[11.0, 9.0, 7.0][a])))
        .collect();
    for i in 0..=20 {
        for j in 0..=16 {
            for k in 0..=12 {
                queries.push([i as f64 * 0.5, j as f64 * 0.5, k as f64 * 0.5]);
            }
        }
    }
    let mut ties = 0;
    for q in &queries {
        let (got, want) = (nearest.find(q), nearest.brute_force(q));
        assert_eq!(got, want, "at {q:?}");
        ties += usize::from(got.d2[3] == got.d2[4]);
    }
    assert!(
        ties > 1000,
        "the lattice queries must exercise ties ({ties})"
    );
}

/// Along scan-like paths (small steps, some along lattice lines where centers tie, and jumps),
/// reusing an anchor's neighbors gives exactly the brute-force neighbors, and the blend of a run
/// of samples equals the blend of each sample alone, bit for bit.
#[test]
fn reused_neighbors_equal_brute_force_along_scans() {
    let f = octree_field();
    let nearest = Nearest::new(&f.centers, &f.halves).unwrap();
    let mut rng = StdRng::seed_from_u64(9);
    let mut path: Vec<[f64; 3]> = Vec::new();
    let mut x = [5.0, 4.0, 3.0];
    for i in 0..40_000 {
        if i % 5_000 == 0 {
            x = std::array::from_fn(|a| rng.random_range(0.0..[10.0, 8.0, 6.0][a]));
        }
        if i % 10_000 < 2_000 {
            // Along a lattice line, where many centers are equidistant.
            x = [x[0] + 0.003, 4.0, 3.0];
        } else {
            for a in 0..3 {
                x[a] += rng.random_range(-0.01..0.01);
            }
        }
        path.push(x);
    }
    let mut anchor = Anchor::default();
    let mut reused = 0;
    for q in &path {
        reused += usize::from(anchor.covers(q));
        let got = nearest.find_reusing(q, &mut anchor);
        assert_eq!(got, nearest.brute_force(q), "at {q:?}");
    }
    assert!(
        reused > path.len() / 4,
        "the paths must exercise reuse ({reused} of {})",
        path.len()
    );
    let blend = Blend::new(&f, Weights::Continuous).unwrap();
    let points: Vec<Vect<3>> = path.iter().map(|q| Vect::<3>::from(*q)).collect();
    let mut run = vec![Vect::<3>::zeros(); points.len()];
    blend.warp_run(&f.origin, &points, &mut run);
    for (p, r) in points.iter().zip(&run) {
        assert_eq!(blend.warp(p), *r, "at {p:?}");
    }
}

/// The continuous blend has no seam where the 4-nearest set changes: across such a boundary,
/// found by bisection to 1e-13, it moves by less than 1e-9 of the extent; the paper's
/// inverse-distance blend jumps there (which shows the boundaries are found).
#[test]
fn continuous_blend_has_no_seams() {
    let f = octree_field();
    let continuous = Blend::new(&f, Weights::Continuous).unwrap();
    let idw = Blend::new(&f, Weights::InverseDistance).unwrap();
    let set = |x: &Vect<3>| {
        let mut s = continuous.weights(x).0.map(|p| p.0);
        s.sort();
        s
    };
    let mut rng = StdRng::seed_from_u64(8);
    let (mut crossings, mut worst, mut idw_jump) = (0, 0.0f64, 0.0f64);
    while crossings < 200 {
        let a = Vect::<3>::from_fn(|i, _| rng.random_range(0.5..[9.5, 7.5, 5.5][i]));
        let mut b = a + Vect::<3>::from_fn(|_, _| rng.random_range(-0.3..0.3));
        let mut a = a;
        if set(&a) == set(&b) {
            continue;
        }
        for _ in 0..60 {
            let m = (a + b) * 0.5;
            if set(&m) == set(&a) { a = m } else { b = m }
        }
        if (a - b).norm() > 1e-13 {
            continue;
        }
        crossings += 1;
        worst = worst.max((continuous.warp(&a) - continuous.warp(&b)).norm());
        idw_jump = idw_jump.max((idw.warp(&a) - idw.warp(&b)).norm());
    }
    let extent = 10.0;
    assert!(worst / extent < 1e-9, "continuous blend jumps by {worst:e}");
    assert!(
        idw_jump / extent > 1e-4,
        "the paper's blend should jump ({idw_jump:e})"
    );
}

/// Where every blended cell is at rest the blend leaves a sample exactly where it was, bit for
/// bit (fixed regions keep their coordinates), and its normal too; where they share one rigid
/// motion, the sample follows it.
#[test]
fn samples_among_cells_at_rest_keep_their_bits() {
    let mut f = octree_field();
    for (m, c) in f.motions.iter_mut().zip(&f.centers) {
        *m = Motion::rest(c);
    }
    let blend = Blend::new(&f, Weights::Continuous).unwrap();
    let mut rng = StdRng::seed_from_u64(12);
    let n = Vect::<3>::new(0.36, 0.48, 0.8);
    for _ in 0..10_000 {
        let x = Vect::<3>::from_fn(|a, _| rng.random_range(0.0..[10.0, 8.0, 6.0][a]));
        assert_eq!(blend.warp(&x), x);
        assert_eq!(blend.warp_with_normal(&x, &n), (x, n));
    }
    let r = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::new(1.0, 2.0, 3.0), 0.7);
    let t = Vect::<3>::new(5.0, -1.0, 2.0);
    for (m, c) in f.motions.iter_mut().zip(&f.centers) {
        *m = Motion {
            rot: r,
            pos: r * c + t,
        };
    }
    let blend = Blend::new(&f, Weights::Continuous).unwrap();
    for _ in 0..10_000 {
        let x = Vect::<3>::from_fn(|a, _| rng.random_range(0.0..[10.0, 8.0, 6.0][a]));
        assert!((blend.warp(&x) - (r * x + t)).amax() < 1e-12);
    }
}

/// The fold-over check finds none where the cells are at rest or share one rotation, and finds
/// every sample where the cells' order along x is reversed (the map turns space inside out),
/// through both transfers.
#[test]
fn foldovers_are_counted_where_space_turns_inside_out() {
    let mut f = octree_field();
    let mut rng = StdRng::seed_from_u64(13);
    let samples: Vec<Vect<3>> = (0..2_000)
        .map(|_| Vect::<3>::from_fn(|a, _| rng.random_range(1.0..[9.0, 7.0, 5.0][a])))
        .collect();
    let count = |f: &Field<3>, transfer| {
        let d = Deformer::new(f, transfer).unwrap();
        foldovers(&d, &f.origin, &samples, 1e-4).len()
    };
    for (m, c) in f.motions.iter_mut().zip(&f.centers) {
        *m = Motion::rest(c);
    }
    assert_eq!(count(&f, Transfer::Blend), 0);
    assert_eq!(count(&f, Transfer::Rbf), 0);
    let r = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::new(0.0, 0.0, 1.0), 0.5);
    for (m, c) in f.motions.iter_mut().zip(&f.centers) {
        *m = Motion { rot: r, pos: r * c };
    }
    assert_eq!(count(&f, Transfer::Blend), 0);
    assert_eq!(count(&f, Transfer::Rbf), 0);
    // Mirror the centers' x: each cell keeps its orientation but the cells' order is reversed.
    for (m, c) in f.motions.iter_mut().zip(&f.centers) {
        *m = Motion {
            rot: nalgebra::Matrix3::identity(),
            pos: Vect::<3>::new(10.0 - c.x, c.y, c.z),
        };
    }
    assert_eq!(count(&f, Transfer::Rbf), samples.len());
    let blended = count(&f, Transfer::Blend);
    assert!(
        blended > samples.len() / 2,
        "{blended} of {}",
        samples.len()
    );
}
