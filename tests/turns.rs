//! Whole turns of bulky parts and half turns of long ones: a part turns by the angle written
//! or the run refuses, soon and in the user's words; the report carries the turn asked and the
//! turn taken, and the spec bounds the turn.

mod common;

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use common::{arg as s, deform};
use rigidcells::Error;
use rigidcells::Vect;
use rigidcells::internal::io::Document;
use rigidcells::internal::pipeline::{self, Options};
use rigidcells::internal::solve::TurnKind;
use rigidcells::parse_spec;
use rigidcells::{Observer, Silent};

/// A closed cylinder of diameter 1 and `height` along y, its base at y = 0, in `dir`.
fn cylinder(dir: &Path, height: f64) -> PathBuf {
    let path = dir.join(format!("cylinder{height}.ply"));
    let mesh = data_gen::cylinder(0.5, height, 48, (24.0 * height) as usize);
    data_gen::write_ply(&path, &mesh, true).unwrap();
    path
}

/// The cylinder's bottom tenth fixed, its top tenth turned by `degrees` about its axis.
fn twist(dir: &Path, height: f64, degrees: f64) -> PathBuf {
    let path = dir.join("twist.toml");
    std::fs::write(
        &path,
        format!(
            "[[fixed]]\nbox = {{ min = [-1, -1, -1], max = [1, 0.1, 1] }}\n\
             [[handle]]\nbox = {{ min = [-1, {}, -1], max = [1, {}, 1] }}\n\
             rotate = {{ axis = [0, 1, 0], degrees = {degrees} }}\n",
            height - 0.1,
            height + 1.0
        ),
    )
    .unwrap();
    path
}

/// The turn about +y of each of `n` slices of the cylinder's wall, from its base to its top,
/// unwrapped from slice to slice (each slice's turn is the circular mean of its vertices').
fn slice_turns(before: &[Vect<3>], after: &[Vect<3>], height: f64, n: usize) -> Vec<f64> {
    let mut sums = vec![(0.0f64, 0.0f64); n];
    for (p, q) in before.iter().zip(after) {
        if p.x.hypot(p.z) < 0.3 {
            continue;
        }
        let k = ((p.y / height * n as f64) as usize).min(n - 1);
        // A turn by θ about +y takes the angle atan2(z, x) to itself minus θ.
        let d = p.z.atan2(p.x) - q.z.atan2(q.x);
        sums[k].0 += d.sin();
        sums[k].1 += d.cos();
    }
    let (mut total, mut prev) = (0.0f64, 0.0f64);
    sums.iter()
        .map(|&(sin, cos)| {
            let angle = sin.atan2(cos).to_degrees();
            total += (angle - prev + 540.0).rem_euclid(360.0) - 180.0;
            prev = angle;
            total
        })
        .collect()
}

/// Deforms the cylinder of `height` by a turn of `degrees`: the exit code, stderr, the slices'
/// turns and the report's `handle_turns`.
fn turned(height: f64, degrees: f64, cell: &str) -> (i32, String, Vec<f64>, serde_json::Value) {
    turned_with(height, degrees, &["--cell-size", cell])
}

/// [`turned`] with the options `options`.
fn turned_with(
    height: f64,
    degrees: f64,
    options: &[&str],
) -> (i32, String, Vec<f64>, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let input = cylinder(dir.path(), height);
    let edit = twist(dir.path(), height, degrees);
    let (out, report) = (dir.path().join("out.ply"), dir.path().join("r.json"));
    let options: Vec<&str> = options
        .iter()
        .copied()
        .chain(["--report", s(&report)])
        .collect();
    let r = deform(&input, &out, &edit, &options);
    if r.code != 0 {
        assert!(!out.exists() && !report.exists(), "a refused run wrote");
        return (r.code, r.stderr, Vec::new(), serde_json::Value::Null);
    }
    let before = Document::read(&input).unwrap().positions().to_vec();
    let after = Document::read(&out).unwrap().positions().to_vec();
    let json = std::fs::read_to_string(&report).unwrap();
    let json: serde_json::Value = serde_json::from_str(&json).unwrap();
    (
        r.code,
        r.stderr,
        slice_turns(&before, &after, height, 20),
        json["handle_turns"].clone(),
    )
}

/// The report's one handle turn: asked and taken.
fn report_turn(turns: &serde_json::Value) -> (f64, f64) {
    let t = &turns.as_array().expect("handle_turns")[0];
    (
        t["turn_asked_degrees"].as_f64().unwrap(),
        t["turn_taken_degrees"].as_f64().unwrap(),
    )
}

/// A cylinder as long as it is wide turns by less than a half turn as asked (the slices add up
/// to the angle), and refuses whole turns instead of untwisting the short way round: the glue
/// between rigid cells cannot hold a twist of a whole turn over a span that short, whatever
/// the cell size or the load steps.
#[test]
fn a_part_as_short_as_it_is_wide_turns_by_half_a_turn_and_refuses_whole_turns() {
    let (code, stderr, slices, turns) = turned(1.0, 150.0, "0.1");
    assert_eq!(code, 0, "{stderr}");
    let end = *slices.last().unwrap();
    assert!(
        (end - 150.0).abs() < 0.15 * 150.0,
        "slices add up to {end}°"
    );
    let (asked, taken) = report_turn(&turns);
    assert_eq!(asked, 150.0);
    assert!((taken - 150.0).abs() < 15.0, "turn taken {taken}°");
    for degrees in [360.0, 720.0] {
        let (code, stderr, ..) = turned(1.0, degrees, "0.1");
        assert_eq!(code, 4, "{degrees}°: {stderr}");
        assert!(
            stderr.contains("line 3") && stderr.contains("gives way past"),
            "{degrees}°: {stderr}"
        );
    }
}

/// The closed `length × 1 × 1` box along x, each face a grid of `n` squares a unit, each
/// square split from its first corner, with the vertices numbered as met face by face.
fn box_mesh(length: f64, n: usize) -> data_gen::Mesh {
    let mut mesh = data_gen::Mesh::default();
    let mut index = std::collections::HashMap::new();
    let size = [length, 1.0, 1.0];
    for axis in 0..3 {
        let (u, w) = match axis {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        let (nu, nw) = ((size[u] * n as f64) as usize, (size[w] * n as f64) as usize);
        for side in [0.0, size[axis]] {
            for i in 0..nu {
                for j in 0..nw {
                    let mut q = [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(di, dj)| {
                        let mut p = [0.0; 3];
                        p[axis] = side;
                        p[u] = size[u] * (i + di) as f64 / nu as f64;
                        p[w] = size[w] * (j + dj) as f64 / nw as f64;
                        let key = p.map(|c| (c * 1e9).round() as i64);
                        *index.entry(key).or_insert_with(|| {
                            mesh.vertices.push(p);
                            (mesh.vertices.len() - 1) as u32
                        })
                    });
                    if side == 0.0 {
                        q.reverse();
                    }
                    mesh.triangles.push([q[0], q[1], q[2]]);
                    mesh.triangles.push([q[0], q[2], q[3]]);
                }
            }
        }
    }
    mesh
}

/// The multilevel path refuses a whole turn of a short bar as the factorization does. Its
/// small systems are one factored level, and where Newton's matrix is indefinite that factor's
/// step can be no descent direction: on this bar each load step from 180° on ended after one
/// such step with the cells where the predictor put them, carrying the whole turn, and the
/// cells themselves, started from there, untwisted with only a warning (exit 0).
#[test]
fn the_multilevel_path_refuses_a_whole_turn_of_a_short_bar_too() {
    let dir = tempfile::tempdir().unwrap();
    let (input, edit, out) = (
        dir.path().join("bar.ply"),
        dir.path().join("twist.toml"),
        dir.path().join("out.ply"),
    );
    data_gen::write_ply(&input, &box_mesh(2.0, 10), true).unwrap();
    let text = "[[fixed]]\nplane = { point = [0.1, 0, 0], normal = [1, 0, 0] }\n\
                [[handle]]\nplane = { point = [1.9, 0, 0], normal = [-1, 0, 0] }\n\
                rotate = { axis = [1, 0, 0], degrees = 360 }\n";
    std::fs::write(&edit, text).unwrap();
    for solver in ["direct", "multilevel"] {
        let r = deform(&input, &out, &edit, &["--solver", solver]);
        assert_eq!(r.code, 4, "{solver}: {}", r.stderr);
        assert!(
            r.stderr.contains("line 3") && r.stderr.contains("gives way past"),
            "{solver}: {}",
            r.stderr
        );
        assert!(!out.exists(), "{solver}: a refused run wrote");
    }
}

/// A cylinder eight times as long as it is wide turns by one and two whole turns: its slices
/// add up to the angle within 15 %, and the report's turn taken is the turn asked.
#[test]
fn a_long_part_turns_by_whole_turns() {
    for degrees in [360.0, 720.0] {
        let (code, stderr, slices, turns) = turned(8.0, degrees, "0.2");
        assert_eq!(code, 0, "{degrees}°: {stderr}");
        let end = *slices.last().unwrap();
        assert!(
            (end - degrees).abs() < 0.15 * degrees,
            "{degrees}°: slices add up to {end}°"
        );
        let (asked, taken) = report_turn(&turns);
        assert_eq!(asked, degrees);
        assert!(
            (taken - degrees).abs() < 0.1 * degrees,
            "{degrees}°: turn taken {taken}°"
        );
        assert!(!stderr.contains("did not turn"), "{stderr}");
    }
}

/// Ten whole turns are the most a handle may ask for: beyond, the spec names the line.
#[test]
fn more_than_ten_whole_turns_is_a_spec_error() {
    let spec = |degrees: &str| {
        format!(
            "[[fixed]]\nbox = {{ min = [0, 0, 0], max = [1, 1, 1] }}\n\
             [[handle]]\nbox = {{ min = [9, 0, 0], max = [10, 1, 1] }}\n\
             rotate = {{ axis = [1, 0, 0], degrees = {degrees} }}\n"
        )
    };
    for ok in ["3600", "-3600", "0.5"] {
        parse_spec::<3>(&spec(ok), Path::new("."), Path::new("t.toml")).expect(ok);
    }
    for bad in ["3600.5", "-3601", "1e5", "-1e308"] {
        let e = parse_spec::<3>(&spec(bad), Path::new("."), Path::new("t.toml")).unwrap_err();
        let text = e.to_string();
        assert_eq!(e.exit_code(), 4, "{bad}");
        assert!(
            text.contains("line 5") && text.contains("ten whole turns"),
            "{bad}: {text}"
        );
    }
}

/// The vertices and triangles of the `size` box bar, 10 vertices a unit.
fn bar(size: [f64; 3]) -> (Vec<Vect<3>>, Vec<[u32; 3]>) {
    let mesh = data_gen::bar(size, 10.0);
    let points = mesh.vertices.iter().map(|v| Vect::<3>::from(*v)).collect();
    (points, mesh.triangles)
}

/// The 10 × 1 × 1 bar's left end fixed and its right end moved by `motion` (spec lines).
fn u_bend(motion: &str) -> String {
    format!(
        "[[fixed]]\nbox = {{ min = [-0.1, -0.1, -0.1], max = [1.0, 1.1, 1.1] }}\n\
         [[handle]]\nbox = {{ min = [9.0, -0.1, -0.1], max = [10.1, 1.1, 1.1] }}\n{motion}\n"
    )
}

/// Where a handle's map sends a point.
type Map = dyn Fn(&Vect<3>) -> Vect<3>;

/// The 10 × 1 × 1 bar's right end turned by a half turn about z around (5, 2, 0), written as a
/// rotation and as matrices (exact, and rounded to single precision as Blender's are, which
/// makes it 179.99999° about −z): the bar bends into a U by 180°, its right end beside its
/// left, the handle's vertices where the map sends them and its middle between the arms; the
/// report says 180° asked and taken. So does 179°.
#[test]
fn a_bar_bends_into_a_u_by_a_half_turn_written_either_way() {
    let (points, triangles) = bar([10.0, 1.0, 1.0]);
    const SINGLE: f64 = 8.742277657347586e-8;
    let u = |x: &Vect<3>| Vect::<3>::new(10.0 - x.x, 4.0 - x.y, x.z);
    let rounded = |x: &Vect<3>| {
        Vect::<3>::new(
            -x.x + SINGLE * x.y + 9.999999825154447,
            -SINGLE * x.x - x.y + 4.000000437113883,
            x.z,
        )
    };
    let by_179 = |x: &Vect<3>| {
        let (s, c) = 179f64.to_radians().sin_cos();
        let (dx, dy) = (x.x - 5.0, x.y - 2.0);
        Vect::<3>::new(5.0 + c * dx - s * dy, 2.0 + s * dx + c * dy, x.z)
    };
    let cases: [(&str, f64, &Map); 4] = [
        (
            "rotate = { axis = [0, 0, 1], degrees = 180 }\npivot = [5, 2, 0]",
            180.0,
            &u,
        ),
        (
            "matrix = [[-1, 0, 0, 10], [0, -1, 0, 4], [0, 0, 1, 0], [0, 0, 0, 1]]",
            180.0,
            &u,
        ),
        (
            "matrix = [[-1, 8.742277657347586e-8, 0, 9.999999825154447], \
             [-8.742277657347586e-8, -1, 0, 4.000000437113883], [0, 0, 1, 0], [0, 0, 0, 1]]",
            180.0,
            &rounded,
        ),
        (
            "rotate = { axis = [0, 0, 1], degrees = 179 }\npivot = [5, 2, 0]",
            179.0,
            &by_179,
        ),
    ];
    let params = Options {
        cell_size: Some(0.5),
        ..Default::default()
    }
    .params()
    .unwrap();
    for (motion, degrees, map) in cases {
        let spec = parse_spec::<3>(&u_bend(motion), ".".as_ref(), "u.toml".as_ref()).unwrap();
        let (moved, _, info) = pipeline::deform(&points, &triangles, &spec, &params, &Silent)
            .unwrap_or_else(|e| panic!("{motion}: {e}"));
        let turn = &info.solver.turns[0];
        assert_eq!(turn.kind, TurnKind::Bend, "{motion}");
        assert_eq!(turn.asked_degrees, degrees, "{motion}");
        let taken = turn.taken_degrees.unwrap();
        assert!((taken - degrees).abs() < 1e-3, "{motion}: taken {taken}°");
        for (p, q) in points.iter().zip(&moved) {
            if p.x > 9.0 {
                assert!((q - map(p)).norm() < 1e-9, "{motion}: {p} went to {q}");
            }
            assert!(
                q.z > -0.05 && q.z < 1.05,
                "{motion}: {p} left the plane for {q}"
            );
        }
        let middle: Vec<&Vect<3>> = points
            .iter()
            .zip(&moved)
            .filter(|(p, _)| (p.x - 5.0).abs() < 0.01)
            .map(|(_, q)| q)
            .collect();
        let y = middle.iter().map(|q| q.y).sum::<f64>() / middle.len() as f64;
        assert!(y > 1.0 && y < 3.0, "{motion}: the middle at y = {y}");
    }
}

/// Counts what a solve spends: the runs of load steps from rest (`solving` stages, one for
/// each complex solved from rest), those that check a refusal on coarser cells, and the
/// Gauss-Newton iterations.
#[derive(Default)]
struct Spent(Mutex<(usize, usize, usize)>);

impl Observer for Spent {
    fn stage(&self, name: &str, _len: u64) {
        let mut spent = self.0.lock().unwrap();
        match name {
            "solving" => spent.0 += 1,
            n if n.starts_with("checking where the shape gives way") => spent.1 += 1,
            _ => {}
        }
    }
    fn message(&self, text: &str) {
        if text.starts_with("iteration ") {
            self.0.lock().unwrap().2 += 1;
        }
    }
}

/// A bar twice as long as it is thick twisted by a whole turn gives way on its coarse cells
/// past 200° or so, on cells coarser still near there too, and on the cells themselves as well
/// (`solve/coarse.rs`): the run is refused from the coarse cells' load steps, checked on the
/// coarser ones, never solving the cells themselves from rest, in the words of a twist, the
/// angle as typed and the spec's line.
#[test]
fn a_whole_turn_of_a_short_bar_is_refused_from_its_coarse_cells() {
    let (points, triangles) = bar([2.0, 1.0, 1.0]);
    let text = "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.2, 1.1, 1.1] }\n\
                [[handle]]\nbox = { min = [1.8, -0.1, -0.1], max = [2.1, 1.1, 1.1] }\n\
                rotate = { axis = [1, 0, 0], degrees = 360 }\n";
    let spec = parse_spec::<3>(text, ".".as_ref(), "twist.toml".as_ref()).unwrap();
    // A solid inside: the default soft one gives way sooner and starts over with a solid one
    // (`tests/exact.rs`), a second run from rest.
    let params = Options {
        cell_size: Some(0.2),
        coarse_levels: Some(1),
        interior_stiffness: 1.0,
        ..Default::default()
    }
    .params()
    .unwrap();
    let spent = Spent::default();
    let e = pipeline::deform(&points, &triangles, &spec, &params, &spent).unwrap_err();
    let (runs, checks, iterations) = *spent.0.lock().unwrap();
    let Error::TurnNotHeld(refusal) = &e else {
        panic!("{e}");
    };
    assert_eq!(
        (refusal.handle, refusal.line, refusal.kind),
        (0, 3, TurnKind::Twist)
    );
    assert_eq!(refusal.asked_degrees, 360.0);
    assert!(
        refusal.held_degrees > 150.0 && refusal.held_degrees < 300.0,
        "{e}"
    );
    assert_eq!(runs, 1, "the cells themselves were solved from rest: {e}");
    assert_eq!(
        checks, 1,
        "the refusal was not checked on coarser cells: {e}"
    );
    assert!(iterations < 90, "{iterations} iterations");
    let text = e.to_string();
    assert!(
        text.starts_with("handle #1 (line 3) twists by 360°, but")
            && text.contains(&format!("gives way past {}°", refusal.held_degrees))
            && text.contains("twist a longer span")
            && !text.contains("bend"),
        "{text}"
    );
}

/// A turn asked a little past where a short bar gives way, solved from rest on its cells (too
/// few for coarse stages): each load step that leaves the branch stops there and is taken
/// again in halves, instead of iterating on until the bar has untwisted, and the run is
/// refused in the words of a twist.
#[test]
fn a_step_that_leaves_its_branch_stops_there() {
    let (points, triangles) = bar([2.0, 1.0, 1.0]);
    let text = "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.2, 1.1, 1.1] }\n\
                [[handle]]\nbox = { min = [1.8, -0.1, -0.1], max = [2.1, 1.1, 1.1] }\n\
                rotate = { axis = [1, 0, 0], degrees = 250 }\n";
    let spec = parse_spec::<3>(text, ".".as_ref(), "twist.toml".as_ref()).unwrap();
    let params = Options {
        cell_size: Some(0.125),
        interior_stiffness: 1.0,
        ..Default::default()
    }
    .params()
    .unwrap();
    let spent = Spent::default();
    let e = pipeline::deform(&points, &triangles, &spec, &params, &spent).unwrap_err();
    let Error::TurnNotHeld(refusal) = &e else {
        panic!("{e}");
    };
    assert_eq!(refusal.kind, TurnKind::Twist);
    assert!(
        refusal.held_degrees > 150.0 && refusal.held_degrees < 250.0,
        "{e}"
    );
    let (runs, _, iterations) = *spent.0.lock().unwrap();
    assert_eq!(runs, 1, "{e}");
    // 28 where the steps stop as they leave the branch, 53 where they iterate on.
    assert!(iterations < 40, "{iterations} iterations");
}
