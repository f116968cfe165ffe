//! 2D image deformation from the CLI (paper Fig. 7): a gingerbread figure with its legs fixed
//! and its hands moved.

mod common;

use std::path::Path;

use common::run;
use rigidcells::internal::image::Raster;

/// `rigidcells image INPUT --edit EDIT -o OUTPUT` plus `extra` arguments.
fn image(input: &Path, edit: &Path, output: &Path, extra: &[&str]) -> common::Run {
    let mut args = vec![
        "image",
        input.to_str().unwrap(),
        "--edit",
        edit.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

/// The fixed legs keep their pixels, the hands' pixels move as sent, the foreground's area
/// stays within 5 %, and the output has no holes: with the blend and with the RBF.
#[test]
fn image_moves_the_hands_keeps_the_legs_and_leaves_no_holes() {
    moves_the_hands("blend");
    moves_the_hands("rbf");
}

fn moves_the_hands(transfer: &str) {
    let dir = tempfile::tempdir().unwrap();
    let (input, output, edit) = common::files(dir.path(), "figure.png", "bent.png");
    let (width, height, rgba) = data_gen::gingerbread();
    let figure = Raster {
        width,
        height,
        rgba,
    };
    figure.write_png(&input).unwrap();
    std::fs::write(&edit, data_gen::GINGERBREAD_SPEC).unwrap();
    let r = image(&input, &edit, &output, &["-q", "--transfer", transfer]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let out = Raster::read_png(&output).unwrap();
    assert_eq!((out.width, out.height), (width, height));

    // The fixed box (legs below y = 185), away from its border with the free cells.
    let mut checked = 0;
    for y in 195..240 {
        for x in 90..150 {
            assert_eq!(
                out.pixel(x, y),
                figure.pixel(x, y),
                "{transfer}: fixed pixel ({x}, {y})"
            );
            checked += figure.pixel(x, y)[3].min(1) as usize;
        }
    }
    assert!(checked > 1400, "{checked} fixed foreground pixels");

    // The hands, well inside their handle boxes: the left one raised by 30, the right one
    // lowered by 25.
    let mut moved = 0;
    for (xs, dy) in [(2..28, -30i64), (212..238, 25)] {
        for y in 92..118u32 {
            for x in xs.clone() {
                let want = figure.pixel(x, y);
                if want[3] == 0 {
                    continue;
                }
                let got = out.pixel(x, (y as i64 + dy) as u32);
                let diff = (0..4).map(|c| want[c].abs_diff(got[c])).max().unwrap();
                assert!(
                    diff <= 2,
                    "{transfer}: hand pixel ({x}, {y}): {want:?} → {got:?}"
                );
                moved += 1;
            }
        }
    }
    assert!(moved > 800, "{moved} hand pixels");

    // Area.
    let area = |r: &Raster| r.rgba.chunks_exact(4).filter(|p| p[3] > 0).count() as f64;
    let (before, after) = (area(&figure), area(&out));
    assert!(
        (after / before - 1.0).abs() <= 0.05,
        "area {before} → {after}"
    );

    // No holes: every transparent pixel is reached from the border through transparent ones.
    let (w, h) = (width as usize, height as usize);
    let clear = |i: usize| out.rgba[4 * i + 3] == 0;
    let mut seen = vec![false; w * h];
    let mut stack: Vec<usize> = (0..w * h)
        .filter(|&i| (i % w == 0 || i % w == w - 1 || i / w == 0 || i / w == h - 1) && clear(i))
        .collect();
    for &i in &stack {
        seen[i] = true;
    }
    while let Some(i) = stack.pop() {
        let (x, y) = (i % w, i / w);
        let near = [
            (x > 0).then(|| i - 1),
            (x + 1 < w).then(|| i + 1),
            (y > 0).then(|| i - w),
            (y + 1 < h).then(|| i + w),
        ];
        for j in near.into_iter().flatten() {
            if clear(j) && !seen[j] {
                seen[j] = true;
                stack.push(j);
            }
        }
    }
    let holes = (0..w * h).filter(|&i| clear(i) && !seen[i]).count();
    assert_eq!(
        holes, 0,
        "{holes} transparent pixels enclosed by the figure"
    );
}

/// An opaque picture needs its background named; a wrong file is refused with its name.
#[test]
fn image_refuses_what_it_cannot_read() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output, edit) = common::files(dir.path(), "opaque.png", "out.png");
    let opaque = Raster {
        width: 32,
        height: 32,
        rgba: [255, 255, 255, 255].repeat(32 * 32),
    };
    opaque.write_png(&input).unwrap();
    std::fs::write(&edit, data_gen::GINGERBREAD_SPEC).unwrap();
    let r = image(&input, &edit, &output, &[]);
    assert_ne!(r.code, 0);
    assert!(r.stderr.contains("--background"), "{}", r.stderr);
    assert!(!output.exists());
    std::fs::write(&input, b"not a png").unwrap();
    let r = image(&input, &edit, &output, &["--background", "255,255,255"]);
    assert_eq!(r.code, 3, "{}", r.stderr);
    assert!(r.stderr.contains("opaque.png"), "{}", r.stderr);
    assert!(!output.exists());
}

/// A 2D point set (`.xy`): the fixed end stays, the handle end moves as sent, comments and
/// extra columns are kept; a malformed line is refused with its file and line.
#[test]
fn deform_moves_a_2d_point_set() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output, edit) = common::files(dir.path(), "bar.xy", "out.xy");
    let mut text = String::from("# a 10 x 1 strip of points, with a label column\n");
    for i in 0..=100 {
        for j in 0..=10 {
            text.push_str(&format!(
                "{:.2} {:.2} p{i}_{j}\n",
                i as f64 * 0.1,
                j as f64 * 0.1
            ));
        }
    }
    std::fs::write(&input, &text).unwrap();
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [-0.1, -0.1], max = [0.5, 1.1] }\n\
         [[handle]]\nbox = { min = [9.5, -0.1], max = [10.1, 1.1] }\ntranslate = [0.0, 3.0]\n",
    )
    .unwrap();
    for transfer in ["blend", "pu"] {
        let r = common::deform(
            &input,
            &output,
            &edit,
            &["--cell-size", "0.25", "--transfer", transfer],
        );
        assert_eq!(r.code, 0, "{}", r.stderr);
        let out = std::fs::read_to_string(&output).unwrap();
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines[0], "# a 10 x 1 strip of points, with a label column");
        assert_eq!(lines.len(), 1 + 101 * 11);
        for (before, after) in text.lines().zip(&lines).skip(1) {
            let b: Vec<&str> = before.split(' ').collect();
            let a: Vec<&str> = after.split(' ').collect();
            assert_eq!(a[2], b[2], "the label column");
            let (x, y): (f64, f64) = (b[0].parse().unwrap(), b[1].parse().unwrap());
            let (x1, y1): (f64, f64) = (a[0].parse().unwrap(), a[1].parse().unwrap());
            if x <= 0.5 {
                assert_eq!(after, &before, "{transfer}: a fixed point's line");
            }
            if x >= 9.75 {
                assert!(
                    (x1 - x).abs() < 1e-9 && (y1 - y - 3.0).abs() < 1e-9,
                    "{before} → {after}"
                );
            }
            if (4.9..5.1).contains(&x) {
                assert!(
                    y1 - y > 0.5 && y1 - y < 2.5,
                    "the middle follows: {before} → {after}"
                );
            }
        }
    }
    std::fs::write(&input, "0 0\n1 one\n").unwrap();
    let bad = dir.path().join("bad.xy");
    let r = common::deform(&input, &bad, &edit, &[]);
    assert_eq!(r.code, 3, "{}", r.stderr);
    assert!(
        r.stderr.contains("bar.xy") && r.stderr.contains("line 2"),
        "{}",
        r.stderr
    );
    assert!(!bad.exists());
}
