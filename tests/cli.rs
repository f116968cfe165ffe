//! The CLI on real files: deform, then check the geometry of what was written.

mod common;

use common::{deform, run};

use rigidcells::internal::io::Document;
use rigidcells::{Dim, Rigid, Vect};

fn edges(tris: &[[u32; 3]]) -> Vec<(u32, u32)> {
    let mut e: Vec<(u32, u32)> = tris
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))))
        .collect();
    e.sort_unstable();
    e.dedup();
    e
}

fn volume(p: &[Vect<3>], tris: &[[u32; 3]]) -> f64 {
    let v: Vec<[f64; 3]> = p.iter().map(|x| [x.x, x.y, x.z]).collect();
    data_gen::signed_volume(&v, tris)
}

/// Bends or twists the 10×1×1 bar from the CLI and checks the output's geometry. `handle` maps
/// a rest point of the handle to where it was sent.
fn bar_edit(
    transfer: &str,
    rotate: &str,
    translate: [f64; 3],
    handle: impl Fn(&Vect<3>) -> Vect<3>,
) -> (Vec<Vect<3>>, Vec<Vect<3>>) {
    let dir = tempfile::tempdir().unwrap();
    let (input, output, edit) = common::files(dir.path(), "bar.ply", "out.ply");
    data_gen::write_ply(&input, &data_gen::bar([10.0, 1.0, 1.0], 8.0), true).unwrap();
    std::fs::write(
        &edit,
        format!(
            "[[fixed]]\nbox = {{ min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }}\n\
             [[handle]]\nbox = {{ min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }}\n\
             rotate = {rotate}\npivot = [9.75, 0.5, 0.5]\ntranslate = {translate:?}\n"
        ),
    )
    .unwrap();
    let r = deform(
        &input,
        &output,
        &edit,
        &["--cell-size", "0.25", "--transfer", transfer],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let before = Document::read(&input).unwrap();
    let after = Document::read(&output).unwrap();
    let (p0, p1) = (before.positions().to_vec(), after.positions().to_vec());
    let tris = before.triangles();
    assert_eq!(tris, after.triangles(), "faces must be copied through");
    assert!(p1.iter().all(|p| p.iter().all(|v| v.is_finite())));

    let ratio = volume(&p1, tris) / volume(&p0, tris);
    assert!(
        (ratio - 1.0).abs() <= 0.05,
        "{transfer}: volume ratio {ratio}"
    );
    let thickness = 1.0;
    let fixed = p0
        .iter()
        .zip(&p1)
        .filter(|(a, _)| a.x <= 0.5)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    assert!(
        fixed <= 0.02 * thickness,
        "{transfer}: fixed end moved {fixed}"
    );
    let miss = p0
        .iter()
        .zip(&p1)
        .filter(|(a, _)| a.x >= 9.5)
        .map(|(a, b)| (handle(a) - b).norm())
        .fold(0.0, f64::max);
    assert!(
        miss <= 0.06 * thickness,
        "{transfer}: handle is {miss} from where it was sent"
    );
    let stretch = edges(tris)
        .iter()
        .map(|&(a, b)| {
            let (a, b) = (a as usize, b as usize);
            (p1[a] - p1[b]).norm() / (p0[a] - p0[b]).norm()
        })
        .fold((f64::MAX, 0.0f64), |(lo, hi), r| (lo.min(r), hi.max(r)));
    assert!(
        stretch.0 > 0.5 && stretch.1 < 1.6,
        "{transfer}: edge length ratios in {stretch:?}"
    );
    eprintln!(
        "{transfer} {rotate}: volume ratio {ratio:.4}, fixed {fixed:.2e}, handle {miss:.2e}, edges {stretch:.3?}"
    );
    (p0, p1)
}

fn bend(transfer: &str) {
    // The centerline from the end of the fixed region (x = 0.5) to the handle's center (9.75)
    // becomes a quarter circle of the same length.
    let radius = 9.25 / std::f64::consts::FRAC_PI_2;
    let end = Vect::<3>::new(0.5 + radius, 0.5, 0.5 + radius);
    let pivot = Vect::<3>::new(9.75, 0.5, 0.5);
    let t = end - pivot;
    let r = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::y(), -90f64.to_radians());
    bar_edit(
        transfer,
        "{ axis = [0.0, 1.0, 0.0], degrees = -90.0 }",
        [t.x, t.y, t.z],
        |x| r * (x - pivot) + pivot + t,
    );
}

#[test]
fn bend_bar_90_degrees_blend() {
    bend("blend");
    bend("blend-idw");
}

#[test]
fn bend_bar_90_degrees_rbf() {
    bend("rbf");
}

fn twist(transfer: &str) {
    let pivot = Vect::<3>::new(9.75, 0.5, 0.5);
    let r = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::x(), 180f64.to_radians());
    let (p0, p1) = bar_edit(
        transfer,
        "{ axis = [1.0, 0.0, 0.0], degrees = 180.0 }",
        [0.0; 3],
        |x| r * (x - pivot) + pivot,
    );
    // The ring in the middle turns by about half the twist.
    let (mut sum, mut n) = (0.0, 0);
    for (a, b) in p0.iter().zip(&p1) {
        if (a.x - 5.0).abs() < 0.07 && ((a.y - 0.5).abs() > 0.3 || (a.z - 0.5).abs() > 0.3) {
            let u = (a.y - 0.5).atan2(a.z - 0.5);
            let v = (b.y - 0.5).atan2(b.z - 0.5);
            let mut d = (v - u).to_degrees();
            while d < 0.0 {
                d += 360.0;
            }
            sum += d.min(360.0 - d);
            n += 1;
        }
    }
    let turn = sum / n as f64;
    assert!(
        (turn - 90.0).abs() < 15.0,
        "{transfer}: middle turned {turn}°"
    );
}

#[test]
fn twist_bar_180_degrees_blend() {
    twist("blend");
    twist("blend-idw");
}

#[test]
fn twist_bar_180_degrees_rbf() {
    twist("rbf");
}

#[test]
fn refuses_to_overwrite_the_input_and_reports_spec_lines() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bar.ply");
    data_gen::write_ply(&input, &data_gen::bar([2.0, 1.0, 1.0], 4.0), false).unwrap();
    let before = std::fs::read(&input).unwrap();
    let edit = dir.path().join("e.toml");
    std::fs::write(
        &edit,
        "[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [0.5, 1.0, 1.0] }\n",
    )
    .unwrap();
    let r = deform(&input, &input, &edit, &[]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(r.stderr.contains("overwrite"), "{}", r.stderr);
    assert_eq!(std::fs::read(&input).unwrap(), before);

    std::fs::write(&edit, "[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [0.5, 1.0, 1.0] }\n\n[[handle]]\nsphere = { center = [2.0, 0.5], radius = 0.3 }\n").unwrap();
    let out = dir.path().join("o.ply");
    let r = deform(&input, &out, &edit, &[]);
    assert_eq!(r.code, 4);
    // The line of the bad value, not of its entry.
    assert!(r.stderr.contains("line 5"), "{}", r.stderr);

    // Fixed and handle regions sharing a cell.
    std::fs::write(&edit, "[[fixed]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n[[handle]]\nbox = { min = [0.9, 0.0, 0.0], max = [2.0, 1.0, 1.0] }\ntranslate = [0.0, 0.0, 1.0]\n").unwrap();
    let r = deform(&input, &out, &edit, &["--cell-size", "0.25"]);
    assert_eq!(r.code, 4);
    assert!(r.stderr.contains("both claim"), "{}", r.stderr);
    assert!(!out.exists());
}

#[test]
fn demo_writes_inputs_and_results() {
    let dir = tempfile::tempdir().unwrap();
    let r = run(&["demo", "--out", dir.path().to_str().unwrap(), "-q"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    for f in [
        "bar.ply",
        "soup.ply",
        "bar_bent.ply",
        "soup_bent.ply",
        "bend.toml",
    ] {
        assert!(dir.path().join(f).exists(), "{f} missing");
    }
    let a = Document::read(&dir.path().join("soup.ply")).unwrap();
    let b = Document::read(&dir.path().join("soup_bent.ply")).unwrap();
    assert_eq!(a.positions().len(), b.positions().len());
}

/// `--report`: the stable keys are there and agree with the file and the run.
#[test]
fn deform_writes_a_report_with_the_stable_keys() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output, edit) = lifted_bar(dir.path(), 2.0);
    let report = dir.path().join("report.json");
    let mesh = data_gen::bar([10.0, 1.0, 1.0], 8.0);
    let r = deform(
        &input,
        &output,
        &edit,
        &[
            "--cell-size",
            "0.25",
            "--transfer",
            "blend",
            "--report",
            report.to_str().unwrap(),
        ],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(json["points"].as_u64(), Some(mesh.vertices.len() as u64));
    let cells = json["cells"].as_u64().unwrap();
    assert!(cells > 100, "{cells} cells");
    assert_eq!(json["cells_initial"].as_u64(), Some(cells));
    let levels: u64 = json["cell_levels"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_u64().unwrap())
        .sum();
    assert_eq!(levels, cells);
    let iterations = json["iterations"].as_u64().unwrap() as usize;
    let energy: Vec<f64> = json["energy"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(iterations > 0 && energy.len() > iterations);
    assert!(energy.last().unwrap() < &energy[1]);
    // One log entry per iteration (no load step is taken again here), ending on one of the two
    // stopping tests.
    let log = json["iteration_log"].as_array().unwrap();
    assert_eq!(log.len(), iterations);
    let last = log.last().unwrap();
    let figure = |k: &str| {
        last[k]
            .as_f64()
            .unwrap_or_else(|| panic!("iteration_log.{k}"))
    };
    assert_eq!(figure("energy"), *energy.last().unwrap());
    assert!(
        figure("decrease") <= 1e-6
            || (figure("step_length") >= 1.0 && figure("largest_move") <= 1e-3),
        "{last}"
    );
    assert!(figure("seconds_setup") >= 0.0 && figure("seconds_assembly") >= 0.0);
    // Samples deep in a region follow it exactly; those in its boundary cells blend with free
    // neighbors and miss by a fraction of a cell (0.03 here, cells of 0.25).
    let residual = json["residual_max"].as_f64().unwrap();
    assert!(json["residual_samples"].as_u64().unwrap() > 100);
    assert!((0.0..0.125).contains(&residual), "residual {residual}");
    assert_eq!(json["foldovers"].as_u64(), Some(0));
    // The options as given, by the Python package's keywords: every one of them, the ones
    // left to the run null, so that the spec and these run it again.
    let options = json["options"].as_object().unwrap();
    let mut names: Vec<String> = rigidcells::internal::pipeline::OPTION_NAMES
        .iter()
        .map(|n| n.replace('-', "_"))
        .collect();
    names.sort();
    assert_eq!(options.keys().cloned().collect::<Vec<_>>(), names);
    assert_eq!(options["cell_size"].as_f64(), Some(0.25));
    assert_eq!(options["transfer"].as_str(), Some("blend"));
    assert_eq!(
        options["interior_stiffness"].as_f64(),
        Some(rigidcells::DEFAULT_INTERIOR_STIFFNESS)
    );
    assert!(options["cells"].is_null() && options["memory_limit"].is_null());
    let t = &json["timings_s"];
    let stage = |k: &str| t[k].as_f64().unwrap_or_else(|| panic!("timings_s.{k}"));
    let parts: f64 = ["read", "voxelize", "solve", "transfer", "write"]
        .iter()
        .map(|k| stage(k))
        .sum();
    assert!(parts > 0.0 && stage("total") >= parts * 0.99, "{t}");
}

/// `render` on the real dragon: a PNG with the model in its middle and the corners empty; a
/// LAS with RGB renders in its colors. `deform --preview` draws before and after side by side,
/// and the handle's yellow moves with the edit.
#[test]
fn render_and_preview_draw_what_was_there() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("dragon.png");
    let dragon = common::shared("meshes/dragon_11k_binary.ply");
    let r = render(&dragon, &png, &["--size", "320x240"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let image = read_png(&png);
    assert_eq!((image.width, image.height), (320, 240));
    let fg = |x: u32, y: u32| image.pixel(x, y) != rigidcells::internal::render::BACKGROUND;
    assert!(
        fg(160, 120) || fg(150, 120) || fg(170, 120),
        "the model's middle"
    );
    assert!(!fg(0, 0) && !fg(319, 239));
    assert!(
        image.foreground() > 320 * 240 / 20,
        "{} pixels",
        image.foreground()
    );

    let las = common::shared("las/autzen_trim.las");
    let las_png = dir.path().join("autzen.png");
    let r = render(&las, &las_png, &["--elevation", "90"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let colored = read_png(&las_png)
        .rgb
        .chunks_exact(3)
        .filter(|p| p[0] != p[1] || p[1] != p[2])
        .count();
    assert!(colored > 1000, "{colored} colored pixels");

    // A bad size is refused, and nothing is written.
    let bad = dir.path().join("bad.png");
    let r = render(&dragon, &bad, &["--size", "big"]);
    assert_eq!(r.code, 4, "{}", r.stderr);
    assert!(!bad.exists());

    let (input, output, edit) = lifted_bar(dir.path(), 4.0);
    let preview = dir.path().join("preview.png");
    let r = deform(
        &input,
        &output,
        &edit,
        &[
            "--cell-size",
            "0.25",
            "--preview",
            preview.to_str().unwrap(),
            "--size",
            "300x200",
            "--strain",
        ],
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let image = read_png(&preview);
    assert_eq!((image.width, image.height), (904, 200));
    // The strain panel: the bent middle red, the rigid ends blue.
    let (mut red, mut blue) = (0, 0);
    for y in 0..200 {
        for x in 604..904 {
            let [r, _, b] = image.pixel(x, y).map(i32::from);
            red += (r > b + 60) as usize;
            blue += (b > r + 60) as usize;
        }
    }
    assert!(red > 200 && blue > 50, "{red} red, {blue} blue pixels");
    // The yellow handle's mean row, left (before) and right (after): lifted means higher up.
    let yellow_row = |x0: u32, x1: u32| {
        let (mut sum, mut n) = (0.0, 0);
        for y in 0..image.height {
            for x in x0..x1 {
                let [r, g, b] = image.pixel(x, y);
                // The handle's yellow [240, 200, 30], shaded by depth; gray and blue have b ≥ 67.
                if b < 60 && r > 100 && g > 80 {
                    sum += y as f64;
                    n += 1;
                }
            }
        }
        assert!(n > 20, "{n} yellow pixels");
        sum / n as f64
    };
    let (before, after) = (yellow_row(0, 300), yellow_row(302, 602));
    assert!(after < before - 20.0, "handle rows {before} → {after}");
}

/// A PNG as the renderer's RGB image (read by the library's reader).
/// `rigidcells render INPUT -o OUTPUT` plus `extra` arguments.
fn render(input: &std::path::Path, output: &std::path::Path, extra: &[&str]) -> common::Run {
    let mut args = vec![
        "render",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

fn read_png(path: &std::path::Path) -> rigidcells::internal::render::Image {
    let raster = rigidcells::internal::image::Raster::read_png(path).unwrap();
    assert!(
        raster.rgba.chunks_exact(4).all(|p| p[3] == 255),
        "renders are opaque"
    );
    rigidcells::internal::render::Image {
        width: raster.width,
        height: raster.height,
        rgb: raster
            .rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect(),
    }
}

/// The 10×1×1 bar written to `dir` with an edit that fixes its left end and lifts its right end
/// by `lift`: `(input, output, edit)` paths.
fn lifted_bar(
    dir: &std::path::Path,
    lift: f64,
) -> (std::path::PathBuf, std::path::PathBuf, std::path::PathBuf) {
    let (input, output, edit) = common::files(dir, "bar.ply", "out.ply");
    data_gen::write_ply(&input, &data_gen::bar([10.0, 1.0, 1.0], 8.0), true).unwrap();
    std::fs::write(
        &edit,
        format!(
            "[[fixed]]\nbox = {{ min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }}\n\
             [[handle]]\nbox = {{ min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }}\n\
             translate = [0.0, 0.0, {lift}]\n"
        ),
    )
    .unwrap();
    (input, output, edit)
}

/// `--rbf-tolerance`: the output stays within the tolerance of the exact RBF's (on the bar the
/// far field never applies, so it is the same), and the option is refused with a blend or a
/// tolerance that is not a length, leaving no output.
#[test]
fn rbf_tolerance_is_checked_and_kept() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output, edit) = lifted_bar(dir.path(), 2.0);
    let rbf = ["--cell-size", "0.25", "--transfer", "rbf"];
    let r = deform(&input, &output, &edit, &rbf);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let far = dir.path().join("far.ply");
    let r = deform(
        &input,
        &far,
        &edit,
        &[&rbf[..], &["--rbf-tolerance", "1e-3"]].concat(),
    );
    assert_eq!(r.code, 0, "{}", r.stderr);
    let (a, b) = (
        Document::read(&output).unwrap(),
        Document::read(&far).unwrap(),
    );
    for (p, q) in a.positions().iter().zip(b.positions()) {
        assert!((p - q).amax() <= 1e-3, "{p} vs {q}");
    }
    let refused = dir.path().join("refused.ply");
    for extra in [
        &["--transfer", "blend", "--rbf-tolerance", "1e-3"][..],
        &["--transfer", "pu", "--rbf-tolerance", "1e-3"][..],
        &["--transfer", "rbf", "--rbf-tolerance=-1"][..],
        &["--transfer", "rbf", "--rbf-tolerance", "nan"][..],
    ] {
        let r = deform(&input, &refused, &edit, extra);
        assert_ne!(r.code, 0, "{extra:?}");
        assert!(r.stderr.contains("--rbf-tolerance"), "{}", r.stderr);
        assert!(!refused.exists());
    }
}

/// The summary's figures are for people, in plain notation: the residuals to a thousandth of
/// the finest cell, the energy to three digits, a time per iteration only when there was one.
#[test]
fn the_summary_prints_plain_figures() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output, edit) = common::lifted_bar(dir.path(), 4.0);
    let summary = |edit: &str| {
        std::fs::write(dir.path().join("edit.toml"), edit).unwrap();
        let _ = std::fs::remove_file(&output);
        let r = common::deform_verbose(
            &input,
            &output,
            &dir.path().join("edit.toml"),
            &["--cell-size", "0.25"],
        );
        assert_eq!(r.code, 0, "{}", r.stderr);
        let line = |key: &str| {
            let l = r.stdout.lines().find(|l| l.contains(key));
            l.unwrap_or_else(|| panic!("no {key} in {}", r.stdout))
                .to_string()
        };
        (line("solve:"), line("constraints:"))
    };
    let plain = |text: &str, after: &str| -> f64 {
        let figure = text
            .split(after)
            .nth(1)
            .unwrap()
            .split([',', ' '])
            .next()
            .unwrap();
        assert!(!figure.contains('e'), "{text}");
        figure
            .parse()
            .unwrap_or_else(|_| panic!("{figure} in {text}"))
    };
    let (solve, constraints) = summary(&std::fs::read_to_string(&edit).unwrap());
    assert!(plain(&solve, "energy ") > 0.0, "{solve}");
    assert!(
        plain(&solve, "(") > 0.0 && solve.contains("ms/iteration"),
        "{solve}"
    );
    assert!(
        plain(&constraints, "fixed samples within ") < 0.25,
        "{constraints}"
    );
    assert!(
        plain(&constraints, "handle samples within ") < 0.25,
        "{constraints}"
    );
    // The whole bar moved by one handle: no iteration, nothing off.
    let (solve, constraints) = summary(
        "[[handle]]\nbox = { min = [-1, -1, -1], max = [11, 2, 2] }\ntranslate = [0, 0, 1]\n",
    );
    assert!(
        solve.contains(" 0 Gauss-Newton iterations, energy 0, "),
        "{solve}"
    );
    assert!(!solve.contains("ms/iteration"), "{solve}");
    assert!(
        constraints.contains("handle samples within 0 of where they were sent"),
        "{constraints}"
    );
}

/// Every option the library's messages name ([`rigidcells::said::Opt`]) is a flag of some
/// command, spelled as the messages spell it.
#[test]
fn every_option_the_messages_name_is_a_flag() {
    let mut flags = Vec::new();
    for command in [
        "deform", "apply", "cells", "render", "image", "solve", "grid", "info", "edit", "demo",
    ] {
        let help = run(&[command, "--help"]);
        assert_eq!(help.code, 0, "{}", help.stderr);
        flags.extend(
            help.stdout
                .lines()
                .filter_map(|l| l.trim_start().split("--").nth(1))
                .map(|l| {
                    l.split([' ', '<', '=', ','])
                        .next()
                        .unwrap_or("")
                        .to_string()
                }),
        );
    }
    for o in rigidcells::said::Opt::ALL {
        assert!(
            flags.iter().any(|f| f == o.name()),
            "--{} is no command's flag",
            o.name()
        );
    }
}

/// Every option of the library's list is a flag of `deform`, spelled as the list spells it.
#[test]
fn deform_takes_every_option_of_the_librarys_list() {
    let help = run(&["deform", "--help"]);
    assert_eq!(help.code, 0, "{}", help.stderr);
    let flags: Vec<&str> = help
        .stdout
        .lines()
        .filter_map(|l| l.trim_start().strip_prefix("--"))
        .map(|l| l.split([' ', '<', '=']).next().unwrap_or(""))
        .collect();
    for name in rigidcells::internal::pipeline::OPTION_NAMES {
        assert!(
            flags.contains(&name),
            "--{name} is not a flag of deform: {flags:?}"
        );
    }
}

/// Options the cells leave without effect are said, in the report's warnings: a winding-number
/// inside asked of points without normals (the flood fill found it instead), and an inside's
/// stiffness with no cell inside to scale; where the flood fill closes an inside, the
/// stiffness scales it without a word.
#[test]
fn options_the_cells_leave_without_effect_are_said() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, _, edit) = common::lifted_bar(dir.path(), 6.0);
    let points = dir.path().join("bar.xyz");
    let text: String = Document::read(&mesh)
        .unwrap()
        .positions()
        .iter()
        .map(|p| format!("{} {} {}\n", p.x, p.y, p.z))
        .collect();
    std::fs::write(&points, text).unwrap();
    let report = dir.path().join("report.json");
    let warnings = |extra: &[&str]| -> Vec<String> {
        let mut args = extra.to_vec();
        args.extend(["--report", report.to_str().unwrap()]);
        let r = deform(&points, &dir.path().join("out.xyz"), &edit, &args);
        assert_eq!(r.code, 0, "{extra:?}: {}", r.stderr);
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        json["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w.as_str().unwrap().to_string())
            .collect()
    };
    let said = warnings(&["--cell-size", "0.25", "--inside", "winding"]);
    assert!(
        said.iter().any(|w| w
            .starts_with("--inside winding needs a mesh's triangles or the points' normals")
            && w.ends_with("found by --inside flood")),
        "{said:?}"
    );
    // Two cells across the bar: every one holds points, none lies inside.
    let said = warnings(&["--cell-size", "0.6", "--interior-stiffness", "0.1"]);
    assert!(
        said.iter().any(|w| w
            == "--interior-stiffness 0.1 scales nothing: no cell lies inside the shape (a \
                flood fill from outside found none: an open surface, points with gaps wider \
                than a cell, or a shape no thicker than two cells)"),
        "{said:?}"
    );
    let said = warnings(&["--cell-size", "0.25", "--interior-stiffness", "0.1"]);
    assert!(
        said.iter().all(|w| !w.contains("scales nothing")),
        "{said:?}"
    );
}

/// Numbers in refusals are said as the user typed them, a negative value reaches the check of
/// its option (not the command line's syntax), and a level count past the octree's is refused
/// by the flag's name.
#[test]
fn refused_numbers_are_said_as_typed() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output, edit) = lifted_bar(dir.path(), 2.0);
    for (args, said) in [
        (
            &["--cell-size", "-1"][..],
            "--cell-size -1 must be positive",
        ),
        (&["--cell-size=-1"][..], "--cell-size -1 must be positive"),
        (
            &["--cell-size", "1e-300"][..],
            "the cell size 1e-300 gives more than 1e38",
        ),
        (
            &["--max-level", "60"][..],
            "--max-level 60: at most 20 levels",
        ),
        (
            &["--memory-limit", "0"][..],
            "--memory-limit under a byte: no run fits in it",
        ),
        (
            &["--memory-limit", "0.5"][..],
            "--memory-limit under a byte: no run fits in it",
        ),
    ] {
        let r = deform(&input, &output, &edit, args);
        assert_eq!(r.code, 4, "{args:?}: {}", r.stderr);
        assert!(r.stderr.contains(said), "{args:?}: {}", r.stderr);
        assert!(!r.stderr.contains("000000000"), "{args:?}: {}", r.stderr);
    }
}
