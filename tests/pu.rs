//! The partition-of-unity RBF: it interpolates the centers, reproduces one rigid
//! motion exactly, agrees with the dense RBF where that is feasible, and is smooth across the
//! borders of its patches.

use std::path::Path;

use rigidcells::Silent;
use rigidcells::internal::field::{Field, Outside, PuRbf, Rbf, SavedField, Transfer, Warp};
use rigidcells::internal::pipeline::{self, Options};
use rigidcells::internal::rigid::{Dim, Motion, Rigid, Vect};
use rigidcells::parse_spec;

/// The 10×1×1 bar bent by 90° (fixed left end, turned right end) at `cell` cells: a solved
/// field with cells of several sizes.
fn bent_bar(cell: f64) -> Field<3> {
    let bar = data_gen::bar([10.0, 1.0, 1.0], 8.0);
    let points: Vec<Vect<3>> = bar.vertices.iter().map(|v| Vect::<3>::from(*v)).collect();
    let spec = parse_spec::<3>(
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n\
         rotate = { axis = [0.0, 1.0, 0.0], degrees = -90.0 }\ntranslate = [-3.4, 0.0, 5.9]\n",
        Path::new("."),
        Path::new("edit.toml"),
    )
    .unwrap();
    let params = Options {
        cell_size: Some(cell),
        ..Default::default()
    }
    .params()
    .unwrap();
    let (_, solution, _) =
        pipeline::deform(&points, &bar.triangles, &spec, &params, &Silent).unwrap();
    Field::from_solution(&solution)
}

/// The largest distance of a rest center's image from where its cell's motion sends it.
fn center_error(pu: &PuRbf<3>, f: &Field<3>) -> f64 {
    f.centers
        .iter()
        .zip(&f.motions)
        .map(|(c, m)| (pu.warp(c) - m.pos).norm())
        .fold(0.0, f64::max)
}

#[test]
fn interpolates_the_centers() {
    let f = bent_bar(0.25);
    let pu = PuRbf::new(&f).unwrap();
    assert!(pu.patch_count() > 4, "{} patches", pu.patch_count());
    let worst = center_error(&pu, &f);
    assert!(worst < 1e-9, "a center is {worst} off");
}

#[test]
fn reproduces_one_rigid_motion_exactly() {
    let mut f = bent_bar(0.25);
    let rot = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::new(1.0, -2.0, 0.5), 0.7);
    let t = Vect::<3>::new(3.0, -1.0, 2.0);
    for (c, m) in f.centers.iter().zip(&mut f.motions) {
        *m = Motion {
            rot,
            pos: rot * c + t,
        };
    }
    let pu = PuRbf::new(&f).unwrap();
    let mut worst = 0.0f64;
    for i in 0..2000 {
        let s = i as f64;
        let x = Vect::<3>::new(
            (s * 0.6180339887).fract() * 10.0 - 5.0,
            (s * 0.7548776662).fract() - 0.5,
            (s * 0.5698402910).fract() - 0.5,
        );
        worst = worst.max((pu.warp(&x) - (rot * x + t)).norm());
    }
    assert!(worst < 1e-9, "off the rigid motion by {worst}");
}

#[test]
fn agrees_with_the_dense_rbf() {
    let f = bent_bar(0.25);
    let (dense, pu) = (Rbf::new(&f).unwrap(), PuRbf::new(&f).unwrap());
    let (mut gap, mut largest) = (0.0f64, 0.0f64);
    for i in 0..5000 {
        let s = i as f64;
        let x = Vect::<3>::new(
            (s * 0.6180339887).fract() * 10.0 - 5.0,
            (s * 0.7548776662).fract() - 0.5,
            (s * 0.5698402910).fract() - 0.5,
        );
        let d = dense.warp(&x);
        largest = largest.max((d - x).norm());
        gap = gap.max((pu.warp(&x) - d).norm());
    }
    assert!(
        gap <= 0.01 * largest,
        "{gap} against a largest displacement of {largest}"
    );
}

/// Second differences along lines through many patch borders shrink about 4× when the step
/// halves, as for a C² map (a kink would give 2, a seam 1).
#[test]
fn is_smooth_across_patch_borders() {
    let f = bent_bar(0.125);
    let pu = PuRbf::new(&f).unwrap();
    let edge = pu.patch_edge();
    assert!(edge < 2.0, "patches of {edge} are too few to cross");
    let second = |h: f64| {
        let mut worst = 0.0f64;
        let mut x = -4.5;
        while x < 4.5 {
            for (y, z) in [(0.0, 0.0), (0.31, -0.2), (-0.45, 0.45)] {
                let p = Vect::<3>::new(x, y, z);
                let e = Vect::<3>::new(h, 0.37 * h, 0.21 * h);
                let d2 = pu.warp(&(p + e)) - 2.0 * pu.warp(&p) + pu.warp(&(p - e));
                worst = worst.max(d2.norm());
            }
            x += 0.0137;
        }
        worst
    };
    let (a, b) = (second(2e-3), second(1e-3));
    let ratio = a / b;
    assert!(
        ratio > 3.5 && ratio < 4.5,
        "second differences {a:e} → {b:e}: ratio {ratio}"
    );
}

/// The closed-form Jacobian (the fold-over check's and the normals') is the map's: central
/// differences agree with it along lines through many patch borders, where the weights' slopes
/// matter, and far from every cell, where the nearest patch's fit alone moves space.
#[test]
fn the_jacobian_in_closed_form_is_the_maps() {
    let f = bent_bar(0.125);
    let pu = PuRbf::new(&f).unwrap();
    let h = 1e-5 * pu.patch_edge();
    let mut worst = 0.0f64;
    let mut slopes = 0.0f64;
    let mut points = vec![Vect::<3>::new(40.0, 30.0, -20.0)];
    let mut x = -4.5;
    while x < 4.5 {
        for (y, z) in [(0.0, 0.0), (0.31, -0.2), (-0.45, 0.45), (1.3, 0.9)] {
            points.push(Vect::<3>::new(x, y, z));
        }
        x += 0.0137;
    }
    for p in &points {
        let closed = pu.jacobian(p);
        let central = rigidcells::internal::field::central_jacobian(&pu, p, h);
        worst = worst.max((closed - central).norm() / central.norm());
        slopes = slopes.max((closed - nalgebra::Matrix3::identity()).norm());
    }
    assert!(worst < 1e-6, "closed form and differences {worst:e} apart");
    assert!(slopes > 0.5, "the bend should turn space: {slopes}");
}

/// Runs of samples (four at a time through each patch) give the bits of one sample at a time.
#[test]
fn runs_give_the_bits_of_single_samples() {
    let f = bent_bar(0.25);
    let pu = PuRbf::new(&f).unwrap();
    let origin = Vect::<3>::new(1e5, -3e5, 20.0);
    let points: Vec<Vect<3>> = (0..3001)
        .map(|i| {
            let s = i as f64;
            origin + Vect::<3>::new(s * 3.3e-3 - 5.0, (s * 0.01).sin() * 0.5, 0.3)
        })
        .collect();
    let mut out = vec![Vect::<3>::zeros(); points.len()];
    pu.warp_run(&origin, &points, &mut out);
    for (p, o) in points.iter().zip(&out) {
        assert_eq!(*o, pu.warp(&(p - origin)) + origin);
    }
}

/// Cells far apart (each patch holds one center in its support) still give patches of the
/// nearest centers, fitted without a search over all cells per patch, interpolating each center.
#[test]
fn sparse_cells_far_apart_are_fitted() {
    let centers: Vec<Vect<3>> = (0..3000)
        .map(|i| {
            Vect::<3>::new(
                (i % 30) as f64 * 40.0,
                (i / 30 % 10) as f64 * 40.0,
                (i / 300) as f64 * 40.0,
            )
        })
        .collect();
    let motions = centers
        .iter()
        .map(|c| Motion {
            rot: <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::z(), 1e-3 * c.x),
            pos: c + Vect::<3>::new(0.0, 0.01 * c.x, 0.002 * c.y),
        })
        .collect();
    let f = Field {
        origin: Vect::<3>::zeros(),
        halves: vec![0.5; centers.len()],
        centers,
        motions,
        prescribed: Default::default(),
        heights_kept: false,
        trend: Default::default(),
    };
    let pu = PuRbf::new(&f).unwrap();
    let worst = center_error(&pu, &f);
    assert!(worst < 1e-8, "a center is {worst} off");
}

/// Fitted on demand, the PU fits only the patches that samples reach (a tile of the
/// field), with the bits of the PU fitted whole.
#[test]
fn fits_on_demand_only_the_patches_a_tile_reaches() {
    let f = bent_bar(0.25);
    let (whole, tile) = (PuRbf::new(&f).unwrap(), PuRbf::lazy(&f).unwrap());
    assert_eq!(tile.fits().0, 0);
    // Samples near the fixed end only: x within [0, 2] of the bar's 10.
    let origin = Vect::<3>::new(1e5, -3e5, 20.0);
    let points: Vec<Vect<3>> = (0..2000)
        .map(|i| {
            let s = i as f64;
            origin + Vect::<3>::new(s * 1e-3 - 4.9, (s * 0.01).sin() * 0.5, 0.3)
        })
        .collect();
    let (mut a, mut b) = (
        vec![Vect::<3>::zeros(); 2000],
        vec![Vect::<3>::zeros(); 2000],
    );
    whole.warp_run(&origin, &points, &mut a);
    tile.warp_run(&origin, &points, &mut b);
    assert_eq!(a, b);
    let (made, all, failed) = tile.fits();
    assert_eq!((whole.fits().0, failed), (all, 0));
    assert!(made > 0 && 4 * made < all, "fitted {made} of {all}");
}

/// A PU field saved and applied to a tile reads only the cells the tile needs (the file's
/// window section) and gives every sample of the tile the whole field's bits, across the fixed
/// end's border too; a sample outside the tile's box is counted, so `apply` can start again.
#[test]
fn a_window_of_a_saved_field_gives_the_whole_fields_bits() {
    let f = bent_bar(0.25);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bar.field");
    SavedField::new(f.clone(), Transfer::Pu, None)
        .save(&path)
        .unwrap();
    let whole = SavedField::<3>::load(&path)
        .unwrap()
        .tile_deformer(None, None, Outside::Keep)
        .unwrap();
    // A tile over the fixed end and its border: x in [-0.2, 1] of the bar's [0, 10].
    let o = f.origin;
    let points: Vec<Vect<3>> = (0..3000)
        .map(|i| {
            let s = i as f64;
            o + Vect::<3>::new(
                -0.2 + s * 4e-4,
                0.5 + 0.45 * (s * 0.37).sin(),
                0.5 + 0.45 * (s * 0.11).cos(),
            )
        })
        .collect();
    let lo = points.iter().fold(points[0], |a, p| a.inf(p));
    let hi = points.iter().fold(points[0], |a, p| a.sup(p));
    let window = SavedField::<3>::load_window(&path, (lo, hi)).unwrap();
    assert!(window.is_window());
    let (part, all) = (window.field.centers.len(), f.centers.len());
    assert!(2 * part < all, "read {part} of {all} cells");
    let tile = window.tile_deformer(None, None, Outside::Keep).unwrap();
    let (mut a, mut b) = (
        vec![Vect::<3>::zeros(); points.len()],
        vec![Vect::<3>::zeros(); points.len()],
    );
    whole.warp_run(&o, &points, &mut a);
    tile.warp_run(&o, &points, &mut b);
    assert!(a.iter().zip(&points).any(|(q, p)| q != p), "nothing moved");
    assert_eq!(a, b);
    assert_eq!(tile.beyond_window(), 0);
    tile.warp_run(&o, &[o + Vect::<3>::new(5.0, 0.5, 0.5)], &mut b[..1]);
    assert_eq!(tile.beyond_window(), 1);
}
