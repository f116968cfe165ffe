//! A Rust caller's view of the library: each workflow of the crate root's facade — a spec made
//! in code, points in memory, files with a saved field applied again, a live session, errors
//! rendered in the caller's own words — written with the root's names alone, as a dependent
//! crate would write it. Nothing here reaches into `internal` (the last test checks).

use rigidcells::said::{Opt, Terms};
use rigidcells::{
    ApplyParams, EditSpec, Entry, Error, HandleMotion, Live, Options, Outputs, Region, Report,
    SavedField, Silent, Vect, apply_file, deform, deform_file_with, read_spec,
};

/// A 4 × 0.5 × 0.5 bar of points, 0.1 apart along it and 0.125 across.
fn bar() -> Vec<Vect<3>> {
    (0..=40)
        .flat_map(|i| (0..=4).flat_map(move |j| (0..=4).map(move |k| (i, j, k))))
        .map(|(i, j, k)| Vect::<3>::new(0.1 * i as f64, 0.125 * j as f64, 0.125 * k as f64))
        .collect()
}

fn slab(from: f64, to: f64) -> Region<3> {
    Region::Box {
        min: Vect::<3>::new(from, -1.0, -1.0),
        max: Vect::<3>::new(to, 2.0, 2.0),
    }
}

/// The left end fixed, the right end turned by `degrees` about the bar's axis.
fn twist(degrees: f64) -> EditSpec<3> {
    let axis = Vect::<3>::new(1.0, 0.0, 0.0);
    let turn = HandleMotion::turning(axis, degrees, 1.0, None, Vect::<3>::zeros()).unwrap();
    EditSpec {
        fixed: vec![Entry {
            region: slab(-1.0, 0.45),
            value: (),
            line: 0,
        }],
        handles: vec![Entry {
            region: slab(3.55, 5.0),
            value: turn,
            line: 0,
        }],
        ..Default::default()
    }
}

fn options() -> Options {
    Options {
        cell_size: Some(0.125),
        ..Default::default()
    }
}

/// A spec made in code deforms points in memory: the fixed end keeps its coordinates bit for
/// bit, the turned end follows its turn about its centroid exactly, and the middle turns part
/// of the way.
#[test]
fn a_spec_made_in_code_deforms_points_in_memory() {
    let points = bar();
    let spec = twist(60.0);
    spec.validate().unwrap();
    let params = options().params().unwrap();
    let (moved, solution, info) = deform(&points, &[], &spec, &params, &Silent).unwrap();
    assert!(info.solver.converged && !solution.motions.is_empty());
    let handle: Vec<usize> = (0..points.len()).filter(|&i| points[i].x > 3.55).collect();
    let centroid = handle.iter().map(|&i| points[i]).sum::<Vect<3>>() / handle.len() as f64;
    let turned = |p: Vect<3>, degrees: f64| {
        let (s, c) = degrees.to_radians().sin_cos();
        let d = p - centroid;
        centroid + Vect::<3>::new(d.x, c * d.y - s * d.z, s * d.y + c * d.z)
    };
    for (p, q) in points.iter().zip(&moved) {
        if p.x < 0.45 {
            assert_eq!(p, q, "a fixed sample moved");
        } else if p.x > 3.55 {
            assert!((turned(*p, 60.0) - q).norm() < 1e-9, "{p} went to {q}");
        }
    }
    // The middle slice turned part of the way about the axis.
    let middle: Vec<usize> = (0..points.len())
        .filter(|&i| (points[i].x - 2.0).abs() < 1e-9 && points[i].y > 0.4)
        .collect();
    let angle = |i: usize| {
        let (d, e) = (points[i] - centroid, moved[i] - centroid);
        (e.z.atan2(e.y) - d.z.atan2(d.y)).to_degrees()
    };
    for &i in &middle {
        assert!(
            (10.0..50.0).contains(&angle(i)),
            "the middle turned {}°",
            angle(i)
        );
    }
}

/// A file run saves its field and report beside the output; the saved field, applied to the
/// same input, writes the same bytes; the returned report is the one written.
#[test]
fn a_saved_field_applied_again_writes_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bar.xyz");
    let text: String = bar()
        .iter()
        .map(|p| format!("{:.3} {:.3} {:.3}\n", p.x, p.y, p.z))
        .collect();
    std::fs::write(&input, text).unwrap();
    let (output, field, report) = (
        dir.path().join("out.xyz"),
        dir.path().join("bar.field"),
        dir.path().join("run.json"),
    );
    let outputs = Outputs {
        save_field: Some(&field),
        report: Some(&report),
        ..Default::default()
    };
    let params = options().params().unwrap();
    let (_, info, returned) =
        deform_file_with(&input, &output, &twist(45.0), &params, &outputs, &Silent).unwrap();
    assert_eq!(info.samples, 41 * 25);
    // Both read back through one parser, which may round a float's last bit either way.
    let read = |json: &[u8]| serde_json::from_slice::<serde_json::Value>(json).unwrap();
    let returned_json = serde_json::to_vec(&returned as &Report).unwrap();
    assert_eq!(read(&std::fs::read(&report).unwrap()), read(&returned_json));

    let saved = SavedField::<3>::load(&field).unwrap();
    assert!(!saved.is_window());
    let again = dir.path().join("again.xyz");
    apply_file(
        &field,
        &input,
        &again,
        &ApplyParams::default(),
        1 << 16,
        &Silent,
    )
    .unwrap();
    assert_eq!(
        std::fs::read(&again).unwrap(),
        std::fs::read(&output).unwrap()
    );
}

/// A live session builds its cells once and follows pose after pose; a pose turned further
/// moves the free end further.
#[test]
fn a_live_session_follows_pose_after_pose() {
    let points = bar();
    let params = options().params().unwrap();
    let mut live = Live::new(points.clone(), &[], Vec::new(), params).unwrap();
    let step = live
        .solve(twist(30.0), 200, &Silent)
        .unwrap()
        .expect("the spec constrains");
    assert!(step.from_rest && step.solver.converged);
    let first = live.preview().unwrap();
    let axis = Vect::<3>::new(1.0, 0.0, 0.0);
    let further = HandleMotion::turning(axis, 50.0, 1.0, None, Vect::<3>::zeros()).unwrap();
    let step = live.pose(&[further], &[], &[], 200).unwrap();
    assert!(!step.from_rest);
    let second = live.preview().unwrap();
    let corner = points
        .iter()
        .position(|p| p.x == 4.0 && p.y == 0.5 && p.z == 0.5)
        .unwrap();
    let angle = |q: &Vect<3>| (q.z - 0.25).atan2(q.y - 0.25).to_degrees() - 45.0;
    assert!(
        (angle(&first[corner]) - 30.0).abs() < 0.5,
        "{}",
        angle(&first[corner])
    );
    assert!(
        (angle(&second[corner]) - 50.0).abs() < 0.5,
        "{}",
        angle(&second[corner])
    );
}

/// A caller renders the library's messages in its own terms: the options as data, not text to
/// parse. A refused value and a missing spec file carry the command line's exit codes.
#[test]
fn errors_speak_in_the_callers_terms() {
    struct Keywords;
    impl Terms for Keywords {
        fn option(&self, o: Opt) -> String {
            o.keyword().to_string()
        }
        fn set(&self, o: Opt, value: &str) -> String {
            format!("{}={value}", o.keyword())
        }
    }
    let refused = Options {
        cell_size: Some(-0.5),
        ..Default::default()
    }
    .params()
    .unwrap_err();
    assert_eq!(refused.exit_code(), 4);
    let said = Keywords.render(&refused.said());
    assert!(said.contains("cell_size=-0.5"), "{said}");
    assert!(
        refused.to_string().contains("--cell-size -0.5"),
        "{refused}"
    );

    let missing = read_spec::<3>(std::path::Path::new("no/such/edit.toml")).unwrap_err();
    assert!(matches!(missing, Error::Spec { .. }), "{missing:?}");
    assert_eq!(missing.exit_code(), 4);
}

/// The workflows above name nothing past the facade.
#[test]
fn this_caller_uses_the_root_alone() {
    let source = include_str!("facade.rs");
    let past = concat!("rigidcells", "::", "internal");
    assert!(
        !source.contains(past),
        "a caller's test reaches past the facade"
    );
}
