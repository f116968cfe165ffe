//! Pictures that show the result: the vertical axis from the file, zoom, the axis
//! triad and scale bar, previews of meshes as triangles with pins, targets and a strain legend
//! in one framing, and `render` in a `cells` PLY's colors.

mod common;

use common::{arg, deform, run, shared};
use rigidcells::internal::image::Raster;
use rigidcells::internal::render::{heat, up_of};

fn picture(path: &std::path::Path) -> Raster {
    Raster::read_png(path).unwrap()
}

fn count(r: &Raster, f: impl Fn([u8; 4]) -> bool) -> usize {
    r.rgba
        .chunks_exact(4)
        .filter(|p| f([p[0], p[1], p[2], p[3]]))
        .count()
}

fn has(r: &Raster, c: [u8; 3]) -> bool {
    count(r, |p| p[..3] == c) > 0
}

fn foreground(r: &Raster) -> usize {
    count(r, |p| p[..3] != [255, 255, 255])
}

#[test]
fn the_vertical_axis_comes_from_the_file() {
    assert_eq!(up_of(&shared("meshes/spot.obj")), 1);
    assert_eq!(up_of(&shared("meshes/bun_zipper.ply")), 1);
    assert_eq!(up_of(&shared("las/autzen_trim.laz")), 2);
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("a.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 1.0\ncomment Z_UP\nelement vertex 0\nend_header\n",
    )
    .unwrap();
    assert_eq!(up_of(&ply), 2);
    // A mesh renders y-up by default: the same picture as --up y, not as --up z.
    let out = |name: &str| dir.path().join(name);
    let input = shared("meshes/spot.obj");
    for (name, extra) in [
        ("d.png", vec![]),
        ("y.png", vec!["--up", "y"]),
        ("z.png", vec!["--up", "z"]),
    ] {
        let mut args = vec!["render", arg(&input), "-o"];
        let o = out(name);
        args.push(arg(&o));
        args.extend(extra);
        let r = run(&args);
        assert_eq!(r.code, 0, "{}", r.stderr);
    }
    let (d, y, z) = (
        picture(&out("d.png")),
        picture(&out("y.png")),
        picture(&out("z.png")),
    );
    assert_eq!(d.rgba, y.rgba);
    assert_ne!(d.rgba, z.rgba);
}

#[test]
fn zoom_triad_and_scale_bar() {
    let dir = tempfile::tempdir().unwrap();
    let input = shared("meshes/spot.obj");
    let (one, two) = (dir.path().join("1.png"), dir.path().join("2.png"));
    assert_eq!(run(&["render", arg(&input), "-o", arg(&one)]).code, 0);
    assert_eq!(
        run(&["render", arg(&input), "-o", arg(&two), "--zoom", "2"]).code,
        0
    );
    let (a, b) = (picture(&one), picture(&two));
    // Twice the magnification: about four times the pixels of the cow (less what is cut off).
    assert!(
        foreground(&b) > 2 * foreground(&a),
        "{} {}",
        foreground(&a),
        foreground(&b)
    );
    // The triad's axes in their colors, the scale bar's ink.
    for c in [[220, 40, 40], [30, 160, 30], [40, 70, 230], [40, 40, 40]] {
        assert!(has(&a, c), "{c:?}");
    }
    let r = run(&["render", arg(&input), "-o", arg(&one), "--zoom", "0"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
}

#[test]
fn previews_draw_triangles_mark_pins_and_targets_and_carry_a_legend() {
    let dir = tempfile::tempdir().unwrap();
    let r = run(&["demo", "--out", arg(dir.path()), "-q"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let edit = dir.path().join("pin.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[pin]]\npoint = [10.0, 0.5, 1.0]\nto = [9.0, 0.5, 3.0]\n\
         [[target]]\nfrom = [5.0, 0.5, 1.0]\nto = [5.0, 0.5, 1.8]\nweight = 5\n",
    )
    .unwrap();
    let png = dir.path().join("p.png");
    let r = deform(
        &dir.path().join("bar.ply"),
        &dir.path().join("o.ply"),
        &edit,
        &["--preview", arg(&png), "--strain", "--size", "320x240"],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let p = picture(&png);
    assert_eq!((p.width, p.height), (3 * 320 + 2 * 2, 240));
    let panel = |k: u32, f: &dyn Fn([u8; 3]) -> bool| {
        let mut n = 0;
        for y in 0..p.height {
            for x in k * 322..k * 322 + 320 {
                let q = p.pixel(x, y);
                n += usize::from(f([q[0], q[1], q[2]]));
            }
        }
        n
    };
    // Pins magenta, targets orange, in the input and the output panels.
    for k in 0..2 {
        assert!(
            panel(k, &|c| c == rigidcells::internal::pipeline::preview::PIN) > 10,
            "panel {k}"
        );
        assert!(
            panel(k, &|c| c == rigidcells::internal::pipeline::preview::TARGET) > 10,
            "panel {k}"
        );
    }
    // The legend's ends in the strain panel.
    assert!(panel(2, &|c| c == heat(1.0)) >= 8 && panel(2, &|c| c == heat(0.0)) >= 8);
    // A coarse mesh (one vertex per unit) is drawn closed, by its faces: its vertices alone,
    // as a point cloud, light a fraction of the pixels.
    let coarse = data_gen::bar([10.0, 1.0, 1.0], 1.0);
    let mesh = dir.path().join("coarse.ply");
    data_gen::write_ply(&mesh, &coarse, true).unwrap();
    let xyz: String = coarse
        .vertices
        .iter()
        .map(|v| format!("{} {} {}\n", v[0], v[1], v[2]))
        .collect();
    let cloud = dir.path().join("coarse.xyz");
    std::fs::write(&cloud, xyz).unwrap();
    let lift = dir.path().join("lift.toml");
    std::fs::write(
        &lift,
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n\
         translate = [0, 0, 2]\n",
    )
    .unwrap();
    let mut lit = Vec::new();
    for (input, out) in [(&mesh, "o.ply"), (&cloud, "o.xyz")] {
        let r = deform(
            input,
            &dir.path().join(out),
            &lift,
            &["--preview", arg(&png), "--size", "320x240", "--up", "z"],
        );
        assert_eq!(r.code, 0, "{}", r.stderr);
        lit.push(foreground(&picture(&png)));
    }
    assert!(
        lit[0] > 3 * lit[1],
        "mesh {} vs its vertices {}",
        lit[0],
        lit[1]
    );
}

#[test]
fn render_uses_the_cells_colors() {
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(run(&["demo", "--out", arg(dir.path()), "-q"]).code, 0);
    let cells = dir.path().join("cells.ply");
    let r = run(&[
        "cells",
        arg(&dir.path().join("bar.ply")),
        "-o",
        arg(&cells),
        "--edit",
        arg(&dir.path().join("bend.toml")),
        "-q",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let png = dir.path().join("c.png");
    assert_eq!(run(&["render", arg(&cells), "-o", arg(&png)]).code, 0);
    let p = picture(&png);
    // Strain colors: reds where the bend strains the cells, blues at the ends.
    let c32 = |c: [u8; 4]| c.map(u32::from);
    let red = count(&p, |c| {
        let c = c32(c);
        c[0] > 120 && c[0] > 2 * c[2] && c[1] < 60
    });
    let blue = count(&p, |c| {
        let c = c32(c);
        c[2] > 120 && c[2] > 2 * c[0] && c[1] < 100
    });
    assert!(red > 1000 && blue > 300, "red {red}, blue {blue}");
}

/// A triangle that spans the fixed end and the handle is drawn in both regions' colors,
/// interpolated from its corners, not all in its first corner's.
#[test]
fn preview_colors_follow_the_regions_across_a_triangle() {
    let dir = tempfile::tempdir().unwrap();
    // A 10 × 1 × 1 box of 12 triangles: every long triangle has corners at both ends.
    let mut obj = String::new();
    for x in [0.0, 10.0] {
        for y in [0.0, 1.0] {
            for z in [0.0, 1.0] {
                obj += &format!("v {x} {y} {z}\n");
            }
        }
    }
    for [a, b, c, d] in [
        [1, 2, 4, 3],
        [5, 7, 8, 6],
        [1, 5, 6, 2],
        [3, 4, 8, 7],
        [1, 3, 7, 5],
        [2, 6, 8, 4],
    ] {
        obj += &format!("f {a} {b} {c}\nf {a} {c} {d}\n");
    }
    let input = dir.path().join("box.obj");
    std::fs::write(&input, obj).unwrap();
    // The bar's lift: its ends hold the box's ends.
    let (_, _, edit) = common::lifted_bar(dir.path(), 1.0);
    let png = dir.path().join("p.png");
    let r = deform(
        &input,
        &dir.path().join("o.obj"),
        &edit,
        &[
            "--preview",
            arg(&png),
            "--size",
            "320x240",
            "--cell-size",
            "0.25",
        ],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let p = picture(&png);
    // Shading scales a color, so blue over green tells the region: 1 for the fixed gray, 0.15
    // for the handle's yellow, in between where the two blend.
    let ratio = |c: [u8; 3]| c[2] as f64 / c[1].max(1) as f64;
    let (fixed, handle) = (
        ratio(rigidcells::internal::pipeline::preview::FIXED),
        ratio(rigidcells::internal::pipeline::preview::HANDLE),
    );
    let mut blended = 0;
    for y in 0..p.height {
        for x in 0..320 {
            let q = p.pixel(x, y);
            let c = [q[0], q[1], q[2]];
            if c[1] > 40 && c != [255, 255, 255] && q[0] > q[2] {
                let r = ratio(c);
                blended += usize::from(r > handle + 0.15 && r < fixed - 0.15);
            }
        }
    }
    assert!(blended > 500, "{blended} pixels blend the two regions");
}

/// A scan colored by intensity is shown by most of its intensities, not by its brightest
/// return: one return at 65,535 among a thousand at 200–400 leaves the rest light gray, not
/// black (the editor's proxy and `render` share these colors).
#[test]
fn intensity_is_scaled_by_the_scan_not_its_brightest_return() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("intensity.las");
    let mut builder = las::Builder::from((1, 2));
    builder.point_format = las::point::Format::new(1).unwrap();
    let mut writer = las::Writer::from_path(&path, builder.into_header().unwrap()).unwrap();
    for i in 0..1000u16 {
        let point = las::Point {
            x: f64::from(i % 40),
            y: f64::from(i / 40),
            z: 0.0,
            intensity: if i == 500 { u16::MAX } else { 200 + i % 200 },
            gps_time: Some(0.0),
            ..Default::default()
        };
        writer.write_point(point).unwrap();
    }
    writer.close().unwrap();
    let shown =
        rigidcells::internal::render::colored_points(&path, 10_000, &rigidcells::Silent).unwrap();
    let mut grays: Vec<u8> = shown.colors.iter().map(|c| c[0]).collect();
    grays.sort_unstable();
    assert!(
        grays[500] > 120,
        "the median intensity is shown at {}",
        grays[500]
    );
    assert_eq!(grays[999], 255);
    // Brighter returns stay brighter, up to white.
    let at = |k: usize| shown.colors[k][0];
    assert!(at(399) > at(200), "{} vs {}", at(399), at(200));
}
