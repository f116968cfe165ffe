//! A live deformation (`pipeline::Live`): poses dragged a short solver step at a time,
//! previewed by the blend, and released onto what `deform` gives for the last pose.

use std::path::Path;

use rigidcells::LooseParts;
use rigidcells::Silent;
use rigidcells::Vect;
use rigidcells::internal::pipeline::{self, DeformParams, Live, Options};
use rigidcells::internal::spec::{EditSpec, parse_poses, parse_spec};

/// A 10 × 1 × 1 bar's vertices and triangles.
fn bar() -> (Vec<Vect<3>>, Vec<[u32; 3]>) {
    let bar = data_gen::bar([10.0, 1.0, 1.0], 8.0);
    let points = bar
        .vertices
        .iter()
        .map(|p| Vect::<3>::new(p[0], p[1], p[2]))
        .collect();
    (points, bar.triangles)
}

/// The bar's left end fixed and its right end lifted by `lift` and turned by `degrees` about
/// y, both as index lists.
fn spec(points: &[Vect<3>], lift: f64, degrees: f64) -> EditSpec<3> {
    let list = |keep: &dyn Fn(&Vect<3>) -> bool| {
        let indices: Vec<String> = (0..points.len())
            .filter(|&i| keep(&points[i]))
            .map(|i| i.to_string())
            .collect();
        format!("[{}]", indices.join(", "))
    };
    let text = format!(
        "[[fixed]]\nindices = {}\n[[handle]]\nindices = {}\ntranslate = [0.0, 0.0, {lift:?}]\n\
         rotate = {{ axis = [0.0, 1.0, 0.0], degrees = {degrees:?} }}\npivot = [10.0, 0.5, 0.5]\n",
        list(&|p| p.x < 2.0),
        list(&|p| p.x > 8.0),
    );
    parse_spec::<3>(&text, Path::new("."), Path::new("live.toml")).unwrap()
}

fn params() -> DeformParams {
    Options {
        cell_size: Some(0.25),
        ..Default::default()
    }
    .params()
    .unwrap()
}

fn farthest(a: &[Vect<3>], b: &[Vect<3>]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q).norm())
        .fold(0.0, f64::max)
}

#[test]
fn a_drag_of_small_steps_ends_where_deform_does() {
    let (points, triangles) = bar();
    let params = params();
    let mut live = Live::new(points.clone(), &triangles, Vec::new(), params).unwrap();
    // Nothing constrained: nothing to solve, and the preview is the rest.
    assert!(
        live.solve(EditSpec::default(), 1, &Silent)
            .unwrap()
            .is_none()
    );
    assert_eq!(live.preview().unwrap(), points);

    let first = live
        .solve(spec(&points, 0.0, 0.0), 1, &Silent)
        .unwrap()
        .unwrap();
    assert!(first.from_rest && first.solver.converged);
    assert!(farthest(&live.preview().unwrap(), &points) < 1e-9);
    let cells = live.complex().len();

    // Twelve poses, one iteration each: warm steps on the same cells, never from rest.
    let mut previews = Vec::new();
    for k in 1..=12 {
        let f = f64::from(k) / 12.0;
        let step = live
            .solve(spec(&points, 3.0 * f, -30.0 * f), 1, &Silent)
            .unwrap()
            .unwrap();
        assert!(!step.from_rest, "pose {k} was solved from rest");
        // One Gauss-Newton iteration, or a drag's few local-global ones.
        let most = rigidcells::internal::solve::DRAG_LOCAL_GLOBAL;
        assert!(
            step.solver.iterations <= most,
            "pose {k}: {:?}",
            step.solver
        );
        previews.push(live.preview().unwrap());
    }
    assert_eq!(live.complex().len(), cells);
    // The preview follows the hand: the handle's end rises pose by pose.
    let tip = points.iter().position(|p| p.x == 10.0).unwrap();
    let rises: Vec<f64> = previews.iter().map(|p| p[tip].z - points[tip].z).collect();
    assert!(rises.windows(2).all(|w| w[1] > w[0]), "{rises:?}");
    assert!(rises[11] > 2.0, "{rises:?}");

    // Idle refinement converges; the release is deform's shape for the last pose.
    let mut idle = 0;
    while live.refine().unwrap().is_some() {
        idle += 1;
        assert!(idle < 50, "the refinement does not converge");
    }
    assert!(live.converged());
    let (moved, _, solution, info) = live.release(&[], &Silent).unwrap();
    assert!(solution.unwrap().info.converged);
    let last = spec(&points, 3.0, -30.0);
    let (expected, _, expected_info) =
        pipeline::deform(&points, &triangles, &last, &params, &Silent).unwrap();
    let off = farthest(&moved, &expected);
    assert!(off < 1e-3, "the release is {off} from deform's shape");
    assert_eq!(info.foldovers.0, expected_info.foldovers.0);
    // Exact where the spec said: fixed samples keep their coordinates, handle samples follow
    // the handle's map.
    for (i, p) in points.iter().enumerate() {
        if p.x < 2.0 {
            assert_eq!(moved[i], *p);
        }
    }
}

#[test]
fn new_regions_solve_from_rest_and_an_empty_spec_rests() {
    let (points, triangles) = bar();
    let mut live = Live::new(points.clone(), &triangles, Vec::new(), params()).unwrap();
    let a = live
        .solve(spec(&points, 1.0, 0.0), 1, &Silent)
        .unwrap()
        .unwrap();
    assert!(a.from_rest);
    // Another fixed region: resolved and solved from rest, to convergence.
    let mut other = spec(&points, 1.0, 0.0);
    other.fixed.truncate(0);
    other.pins.push(rigidcells::internal::spec::Pin {
        point: Vect::<3>::new(0.0, 0.5, 0.5),
        to: Vect::<3>::new(0.0, 0.5, 0.5),
        line: 1,
    });
    let b = live.solve(other, 1, &Silent).unwrap().unwrap();
    assert!(b.from_rest && b.solver.converged, "{b:?}");
    // Nothing constrained: the session ends and the release is the rest.
    assert!(
        live.solve(EditSpec::default(), 1, &Silent)
            .unwrap()
            .is_none()
    );
    let (moved, _, solution, _) = live.release(&[], &Silent).unwrap();
    assert!(solution.is_none());
    assert_eq!(moved, points);
}

#[test]
fn poses_alone_move_the_handles_of_the_last_spec() {
    let (points, triangles) = bar();
    let name = Path::new("poses");
    let mut live = Live::new(points.clone(), &triangles, Vec::new(), params()).unwrap();
    // No spec yet: nothing to pose.
    let lift = parse_poses::<3>("[[handle]]\ntranslate = [0.0, 0.0, 1.0]\n", name).unwrap();
    assert!(live.pose(&lift, &[], &[], 1).is_err());
    live.solve(spec(&points, 0.0, 0.0), 1, &Silent).unwrap();
    // The pose as a matrix: the same step as the whole spec with that translation.
    let matrix = "[[handle]]\nmatrix = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], \
                  [0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 0.0, 1.0]]\n";
    let poses = parse_poses::<3>(matrix, name).unwrap();
    let step = live.pose(&poses, &[], &[], 50).unwrap();
    assert!(!step.from_rest && step.solver.converged, "{step:?}");
    let (moved, _, _, _) = live.release(&[], &Silent).unwrap();
    let tip = points.iter().position(|p| p.x == 10.0).unwrap();
    assert!((moved[tip].z - points[tip].z - 1.0).abs() < 1e-9);
    // One pose a handle, and nothing but a pose.
    assert!(live.pose(&[], &[], &[], 1).is_err());
    let region = "[[handle]]\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n";
    let err = parse_poses::<3>(region, name).unwrap_err().to_string();
    assert!(err.contains("box"), "{err}");
}

/// A point at the bar's middle that a pose moves: a pin, or a soft target (a Blender vertex
/// weight's partial pull follows its Empty).
#[derive(Clone, Copy, PartialEq, Debug)]
enum Moved {
    Pin,
    Target,
}

/// Pins and soft targets go where each pose sends them, warm, and the release is `deform`'s
/// shape with them there; a pose with the wrong count of them is refused.
#[test]
fn pins_and_targets_move_warm_and_release_onto_deforms_shape() {
    let (points, triangles) = bar();
    let params = params();
    for kind in [Moved::Pin, Moved::Target] {
        let with = |to_z: f64| {
            let mut s = spec(&points, 1.0, 0.0);
            let text = match kind {
                Moved::Pin => {
                    format!("[[pin]]\npoint = [5.0, 0.5, 1.0]\nto = [5.0, 0.5, {to_z:?}]\n")
                }
                Moved::Target => format!(
                    "[[target]]\nfrom = [5.0, 0.5, 1.0]\nto = [5.0, 0.5, {to_z:?}]\nweight = 4.0\n"
                ),
            };
            let extra = parse_spec::<3>(&text, Path::new("."), Path::new("m.toml")).unwrap();
            s.pins = extra.pins;
            s.targets = extra.targets;
            s
        };
        let mut live = Live::new(points.clone(), &triangles, Vec::new(), params).unwrap();
        let first = live.solve(with(1.0), 1, &Silent).unwrap().unwrap();
        assert!(first.from_rest, "{kind:?}");
        let lift = parse_poses::<3>(
            "[[handle]]\ntranslate = [0.0, 0.0, 1.0]\npivot = [10.0, 0.5, 0.5]\n",
            Path::new("p"),
        )
        .unwrap();
        let pose = |live: &mut Live, to: &[Vect<3>]| match kind {
            Moved::Pin => live.pose(&lift, to, &[], 1),
            Moved::Target => live.pose(&lift, &[], to, 1),
        };
        for k in 1..=4 {
            let to = Vect::<3>::new(5.0, 0.5, 1.0 + 0.25 * f64::from(k));
            let step = pose(&mut live, &[to]).unwrap();
            assert!(!step.from_rest, "{kind:?} move {k} was solved from rest");
        }
        let e = pose(&mut live, &[Vect::<3>::zeros(); 2]).unwrap_err();
        let said = format!("2 {}s for the spec's 1", format!("{kind:?}").to_lowercase());
        assert!(e.to_string().contains(&said), "{e}");
        let (moved, _, _, _) = live.release(&[], &Silent).unwrap();
        let deformed = |z| {
            pipeline::deform(&points, &triangles, &with(z), &params, &Silent)
                .unwrap()
                .0
        };
        let off = farthest(&moved, &deformed(2.0));
        assert!(
            off < 1e-3,
            "{kind:?}: the release is {off} from deform's shape"
        );
        let unmoved = farthest(&moved, &deformed(1.0));
        assert!(
            unmoved > 0.05,
            "{kind:?}: the move did not pull ({unmoved})"
        );
    }
}

#[test]
fn a_pivot_given_or_left_to_the_centroid_and_tied_handles_are_resolved_again() {
    let (points, triangles) = bar();
    let params = params();
    let mut live = Live::new(points.clone(), &triangles, Vec::new(), params).unwrap();
    live.solve(spec(&points, 1.0, -20.0), 1, &Silent).unwrap();
    // The same handle turned about its centroid (no pivot): resolved from rest, so that the
    // centroid is the pivot, and released onto deform's shape.
    let mut centroid = spec(&points, 1.0, -20.0);
    centroid.handles[0].value.pivot = None;
    let step = live.solve(centroid.clone(), 1, &Silent).unwrap().unwrap();
    assert!(step.from_rest, "{step:?}");
    let (moved, _, _, _) = live.release(&[], &Silent).unwrap();
    let (expected, _, _) =
        pipeline::deform(&points, &triangles, &centroid, &params, &Silent).unwrap();
    assert!(farthest(&moved, &expected) < 1e-3);

    // Two handles over the same end, moving together, then apart: as deform, refused.
    let two = |second: f64| {
        let mut s = spec(&points, 1.0, 0.0);
        let mut other = s.handles[0].clone();
        other.value.translate[2] = second;
        other.line += 1;
        s.handles.push(other);
        s
    };
    let mut live = Live::new(points.clone(), &triangles, Vec::new(), params).unwrap();
    live.solve(two(1.0), 1, &Silent).unwrap();
    let apart = live.solve(two(3.0), 1, &Silent).unwrap_err().to_string();
    let alone = pipeline::deform(&points, &triangles, &two(3.0), &params, &Silent)
        .unwrap_err()
        .to_string();
    assert_eq!(apart, alone);
}

#[test]
fn a_release_without_a_drag_is_deforms_points_bit_for_bit_loose_parts_too() {
    let (mut points, triangles) = bar();
    // A block of points two units beside the bar: a part no constraint reaches.
    let bar_len = points.len();
    for k in 0..125 {
        let (i, j, l) = (k % 5, k / 5 % 5, k / 25);
        points.push(Vect::<3>::new(
            6.0 + 0.25 * f64::from(i),
            3.0 + 0.25 * f64::from(j),
            0.25 * f64::from(l),
        ));
    }
    let spec = spec(&points, 3.0, -30.0);
    for loose in [LooseParts::Carry, LooseParts::Rest] {
        let params = Options {
            cell_size: Some(0.25),
            loose_parts: loose,
            ..Default::default()
        }
        .params()
        .unwrap();
        let (expected, _, expected_info) =
            pipeline::deform(&points, &triangles, &spec, &params, &Silent).unwrap();
        let mut live = Live::new(points.clone(), &triangles, Vec::new(), params).unwrap();
        let most = params.solve().max_iterations;
        let step = live.solve(spec.clone(), most, &Silent).unwrap().unwrap();
        let preview = live.preview().unwrap();
        let (moved, _, _, info) = live.release(&[], &Silent).unwrap();
        let differ = moved.iter().zip(&expected).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "{loose:?}: {differ} points differ from deform's");
        assert_eq!(info.warnings, expected_info.warnings, "{loose:?}");
        // The step and the preview say and show what the release gives.
        assert!(
            expected_info
                .warnings
                .iter()
                .all(|w| step.warnings.contains(w))
        );
        let block = bar_len..points.len();
        assert!(farthest(&preview[block.clone()], &moved[block.clone()]) < 1e-9);
        let travel = farthest(&moved[block.clone()], &points[block]);
        match loose {
            LooseParts::Carry => assert!(travel > 0.5, "the loose block moved {travel}"),
            LooseParts::Rest => assert_eq!(travel, 0.0),
        }
    }
}

#[test]
fn las_classes_select_in_a_live_session_as_in_deform() {
    let (points, triangles) = bar();
    // Class 2 at the right end (the "ground" a surveyor lifts), 1 elsewhere.
    let classes: Vec<u8> = points
        .iter()
        .map(|p| if p.x > 8.0 { 2 } else { 1 })
        .collect();
    let text = "[[fixed]]\nbox = { min = [-1.0, -1.0, -1.0], max = [2.0, 2.0, 2.0] }\n\
                [[handle]]\nclassification = [2]\ntranslate = [0.0, 0.0, 2.0]\n";
    let spec = parse_spec::<3>(text, Path::new("."), Path::new("class.toml")).unwrap();
    let params = params();
    let (expected, _, _, _) =
        pipeline::deform_oriented(&points, &[], &triangles, &classes, &spec, &params, &Silent)
            .unwrap();
    let tip = points.iter().position(|p| p.x == 10.0).unwrap();
    assert_eq!(expected[tip].z, points[tip].z + 2.0);
    let mut live = Live::new(points.clone(), &triangles, classes.clone(), params).unwrap();
    live.solve(spec.clone(), params.solve().max_iterations, &Silent)
        .unwrap();
    let (moved, _, _, _) = live.release(&[], &Silent).unwrap();
    assert!(moved == expected, "the release is not deform's");
    // Without classes, or with a class a sample too few, the spec is refused, never read past.
    for wrong in [Vec::new(), classes[1..].to_vec()] {
        let refused =
            pipeline::deform_oriented(&points, &[], &triangles, &wrong, &spec, &params, &Silent);
        assert!(refused.is_err(), "{} classes", wrong.len());
    }
    let short = Live::new(points.clone(), &triangles, classes[1..].to_vec(), params);
    let message = short.err().unwrap().to_string();
    assert!(message.contains("LAS classes for"), "{message}");
}

/// A pose that turns a handle by more than a load step from the last one is solved from rest in
/// load steps, with its winding: a twist typed at 360° straight from rest turns the bar a whole
/// turn, as `deform` does, where a warm step would have taken the identity the short way.
#[test]
fn a_pose_a_whole_turn_from_the_last_keeps_its_winding() {
    let (points, triangles) = bar();
    let params = params();
    let twist = |degrees: f64| {
        let text = format!(
            "[[fixed]]\nbox = {{ min = [-0.1, -0.1, -0.1], max = [2.0, 1.1, 1.1] }}\n\
             [[handle]]\nbox = {{ min = [8.0, -0.1, -0.1], max = [10.1, 1.1, 1.1] }}\n\
             rotate = {{ axis = [1.0, 0.0, 0.0], degrees = {degrees:?} }}\npivot = [9.0, 0.5, 0.5]\n"
        );
        parse_spec::<3>(&text, Path::new("."), Path::new("live.toml")).unwrap()
    };
    let mut live = Live::new(points.clone(), &triangles, Vec::new(), params).unwrap();
    live.solve(twist(0.0), 1, &Silent).unwrap().unwrap();
    let step = live.solve(twist(360.0), 1, &Silent).unwrap().unwrap();
    assert!(
        step.from_rest,
        "a whole turn from the last pose was stepped warm"
    );
    while live.refine().unwrap().is_some() {}
    let (moved, _, _, _) = live.release(&[], &Silent).unwrap();
    let (expected, _, _) =
        pipeline::deform(&points, &triangles, &twist(360.0), &params, &Silent).unwrap();
    let off = farthest(&moved, &expected);
    assert!(off < 1e-3, "the release is {off} from deform's whole turn");
    // The middle turned half a turn: its corners went to the opposite ones.
    let corner = points
        .iter()
        .position(|p| p.x == 5.0 && p.y == 0.0 && p.z == 0.0)
        .unwrap();
    let q = moved[corner];
    assert!(
        (q.y - 1.0).abs() < 0.15 && (q.z - 1.0).abs() < 0.15,
        "the middle's corner went to {q:?}"
    );
    // Small steps on from there stay warm.
    let on = live.solve(twist(370.0), 1, &Silent).unwrap().unwrap();
    assert!(!on.from_rest);
}

/// The bar's middle nine units twisted by `degrees` about its axis.
fn long_twist(degrees: f64) -> EditSpec<3> {
    let text = format!(
        "[[fixed]]\nbox = {{ min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }}\n\
         [[handle]]\nbox = {{ min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }}\n\
         rotate = {{ axis = [1.0, 0.0, 0.0], degrees = {degrees:?} }}\n\
         pivot = [9.75, 0.5, 0.5]\n"
    );
    parse_spec::<3>(&text, Path::new("."), Path::new("live.toml")).unwrap()
}

/// A drag that outruns its cells keeps the turn: twisted on by 15° a pose with one iteration
/// each (a hand faster than the solver), the cells would fall a half turn behind the handle and
/// converge the short way round; a pose more than a load step from the one the session last
/// converged on converges the last pose first, so the release is `deform`'s 540° twist.
#[test]
fn a_drag_that_outruns_its_cells_keeps_the_turn() {
    let (points, triangles) = bar();
    let params = params();
    let mut live = Live::new(points.clone(), &triangles, Vec::new(), params).unwrap();
    for k in 0..=36 {
        let step = live
            .solve(long_twist(15.0 * k as f64), 1, &Silent)
            .unwrap()
            .unwrap();
        assert!(
            k == 0 || !step.from_rest,
            "the pose at {}° solved from rest",
            15 * k
        );
    }
    while live.refine().unwrap().is_some() {}
    let (moved, _, _, info) = live.release(&[], &Silent).unwrap();
    let taken = info.solver.turns[0].taken_degrees;
    assert!(taken.is_some_and(|t| (t - 540.0).abs() < 1e-6), "{taken:?}");
    let (expected, _, _) =
        pipeline::deform(&points, &triangles, &long_twist(540.0), &params, &Silent).unwrap();
    // Converged from another start, as deform's last load step ends, by Newton's iterations
    // (by Gauss-Newton's the release stopped 0.006 away, its steps lowering the energy by
    // less than a millionth along the twist's soft modes).
    let off = farthest(&moved, &expected);
    assert!(off < 1e-4, "the release is {off} from deform's twist");
}

/// A release converges its pose, and the drag goes on warm from there: a pose a few degrees
/// past the released one is a warm step, however far it is from the last pose converged before.
#[test]
fn a_drag_goes_on_warm_after_a_release() {
    let (points, triangles) = bar();
    let mut live = Live::new(points, &triangles, Vec::new(), params()).unwrap();
    live.solve(long_twist(0.0), 1, &Silent).unwrap().unwrap();
    let step = live.solve(long_twist(25.0), 1, &Silent).unwrap().unwrap();
    assert!(!step.from_rest && !step.solver.converged);
    live.release(&[], &Silent).unwrap();
    let step = live.solve(long_twist(35.0), 1, &Silent).unwrap().unwrap();
    assert!(
        !step.from_rest,
        "the pose after the release solved from rest"
    );
}

/// A drag that twists the bar on past where the default soft inside gives way stiffens the
/// session's inside to a solid's, as `deform` does for the whole turn: dragged in 15° poses to
/// 720° and refined, a converged pose says so and starts again from the last pose whose turn
/// the cells held, and after more poses the release holds the whole 720° as the same drag with
/// a solid inside asked for (`interior_stiffness` 1) does, which says nothing.
#[test]
fn a_drag_past_where_the_soft_inside_gives_way_stiffens_it() {
    let (points, triangles) = bar();
    let twist = long_twist;
    let drag = |params: DeformParams| {
        let mut live = Live::new(points.clone(), &triangles, Vec::new(), params).unwrap();
        let mut said = false;
        for k in 0..=48 {
            let step = live
                .solve(twist(15.0 * k as f64), 1, &Silent)
                .unwrap()
                .unwrap();
            said |= step.solver.inside_stiffened.is_some();
        }
        while let Some(step) = live.refine().unwrap() {
            said |= step.solver.inside_stiffened.is_some();
        }
        // Poses after the stiffening keep the solid inside, stiffened once.
        for degrees in [705.0, 690.0, 720.0] {
            live.solve(twist(degrees), 1, &Silent).unwrap().unwrap();
        }
        while live.refine().unwrap().is_some() {}
        let (moved, _, _, info) = live.release(&[], &Silent).unwrap();
        let taken = info.solver.turns[0].taken_degrees;
        assert!(taken.is_some_and(|t| (t - 720.0).abs() < 1e-6), "{taken:?}");
        (moved, said)
    };
    let (soft, said) = drag(params());
    assert!(said, "no pose stiffened the inside");
    let solid = Options {
        cell_size: Some(0.25),
        interior_stiffness: 1.0,
        ..Default::default()
    };
    let (solid, said) = drag(solid.params().unwrap());
    assert!(!said);
    // Both converged on the solid's 720° twist from other starts, to Newton's minimum.
    let off = farthest(&soft, &solid);
    assert!(off < 1e-4, "the release is {off} from the solid drag's");
}
