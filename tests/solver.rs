//! The solver's invariants: paper Fig. 4 (collapse and recover), rigid edits give rigid
//! motions, energy never increases, no NaN.

use rand::{Rng, SeedableRng, rngs::StdRng};
use rigidcells::Budget;
use rigidcells::Silent;
use rigidcells::internal::cells::{BuildParams, CellComplex, build};
use rigidcells::internal::rigid::{Dim, Motion, Rigid, Vect};
use rigidcells::internal::solve::{self, Role, SolveParams, SolverInfo, schwarz};
use rigidcells::parse_spec;

/// Dense samples on the surface of an ellipsoid-like blob with semi-axes `radii`.
fn blob<const D: usize>(radii: [f64; D], n: usize) -> Vec<Vect<D>> {
    let mut rng = StdRng::seed_from_u64(3);
    (0..n)
        .map(|_| {
            let mut v = Vect::<D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            while v.norm() < 1e-3 {
                v = Vect::<D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            }
            let u = v.normalize();
            Vect::<D>::from_fn(|a, _| u[a] * radii[a] * (1.0 + 0.15 * (3.0 * u[0]).sin()))
        })
        .collect()
}

fn complex<const D: usize>(radii: [f64; D], cell: f64) -> CellComplex<D> {
    cells(&blob(radii, 40_000), &[], cell)
}

/// The cells of `pts` (and `triangles`) at finest size `cell`.
fn cells<const D: usize>(pts: &[Vect<D>], triangles: &[[u32; 3]], cell: f64) -> CellComplex<D> {
    let params = BuildParams {
        cell_size: Some(cell),
        ..Default::default()
    };
    build(pts, triangles, &params, Budget::default()).unwrap().0
}

/// The vertices and triangles of `data_gen::bar(size, density)`.
fn bar(size: [f64; 3], density: f64) -> (Vec<Vect<3>>, Vec<[u32; 3]>) {
    let mesh = data_gen::bar(size, density);
    let pts = mesh.vertices.iter().map(|v| Vect::<3>::from(*v)).collect();
    (pts, mesh.triangles)
}

/// The 8-long bar's edit of the Newton and adaptive tests: the first 1.0 fixed, the last 1.0 a
/// handle moved by `motion` (spec lines).
fn bar_ends(motion: &str) -> String {
    format!(
        "[[fixed]]\nbox = {{ min = [-0.1, -0.1, -0.1], max = [1.0, 1.1, 1.1] }}\n\
         [[handle]]\nbox = {{ min = [7.0, -0.1, -0.1], max = [8.1, 1.1, 1.1] }}\n{motion}\n"
    )
}

/// The edit spec `text` resolved on `complex` with the samples `pts`.
fn resolved<const D: usize>(
    complex: &CellComplex<D>,
    pts: &[Vect<D>],
    text: &str,
) -> solve::Constraints<D>
where
    Dim<D>: Rigid<D>,
{
    let spec = parse_spec::<D>(
        text,
        std::path::Path::new("."),
        std::path::Path::new("t.toml"),
    )
    .unwrap();
    solve::resolve(complex, &spec, pts, None).unwrap()
}

/// Paper Fig. 4: every cell collapsed to one point with a random rotation, one cell fixed.
fn collapse_and_recover<const D: usize>(
    radii: [f64; D],
    cell: f64,
    min_cells: usize,
    max_iterations: usize,
) where
    Dim<D>: Rigid<D>,
{
    let complex = complex(radii, cell);
    assert!(complex.len() >= min_cells, "only {} cells", complex.len());
    assert_eq!(complex.components().1, 1);
    let mut roles = vec![Role::Free; complex.len()];
    roles[complex.len() / 2] = Role::Fixed;
    let constraints = solve::Constraints {
        roles,
        handles: vec![],
        pins: vec![],
        targets: vec![],
        stiffness: vec![1.0; complex.len()],
        inside: 1.0,
        origin: complex.grid.origin,
        warnings: vec![],
        trend: Default::default(),
        trend_kind: Default::default(),
        shapes: Default::default(),
    };
    let mut rng = StdRng::seed_from_u64(11);
    let point = Vect::<D>::from_fn(|_, _| rng.random_range(-0.1..0.1));
    let mut motions: Vec<Motion<D>> = complex
        .cells
        .iter()
        .map(|_| {
            let axis = Vect::<D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            Motion {
                rot: <Dim<D> as Rigid<D>>::axis_angle(&axis, rng.random_range(-3.1..3.1)),
                pos: point,
            }
        })
        .collect();
    let mut info = SolverInfo::default();
    let params = SolveParams {
        max_iterations,
        tolerance: 0.0,
        ..Default::default()
    };
    let iterations = solve::minimize(
        &complex,
        &constraints,
        &mut motions,
        1.0,
        &params,
        &mut info,
    )
    .unwrap();
    let e0 = info.energies[0];
    let e = *info.energies.last().unwrap();
    eprintln!(
        "D={D}: {} cells, {iterations} iterations, energy {e0:.3e} -> {e:.3e}",
        complex.len()
    );
    assert!(iterations <= max_iterations);
    assert!(
        e <= 1e-8 * e0,
        "energy {e} from {e0} after {iterations} iterations"
    );
    monotone(&info);
    // The fixed cell is at rest, so the rest shape is recovered exactly.
    let size = complex.grid.finest_size();
    for (c, m) in complex.cells.iter().zip(&motions) {
        assert!(
            (m.pos - c.center).norm() < 1e-4 * size,
            "cell at {:?} off",
            c.center
        );
        assert!((m.rot - nalgebra::SMatrix::<f64, D, D>::identity()).norm() < 1e-4);
    }
}

fn monotone(info: &SolverInfo) {
    assert!(info.energies.iter().all(|e| e.is_finite()));
    let mut bounds = info.step_starts.clone();
    bounds.push(info.energies.len());
    for step in bounds.windows(2) {
        for w in info.energies[step[0]..step[1]].windows(2) {
            assert!(w[1] <= w[0], "energy rose from {} to {}", w[0], w[1]);
        }
    }
}

#[test]
fn fig4_collapsed_cells_recover_3d() {
    collapse_and_recover::<3>([2.0, 1.2, 1.0], 0.25, 500, 30);
}

#[test]
fn fig4_collapsed_cells_recover_2d() {
    // Measured: 14–20 iterations over six seeds (3D: 10–13).
    collapse_and_recover::<2>([2.0, 1.0], 0.04, 500, 30);
}

/// If every constraint is the same rigid motion, every cell ends in that motion.
fn rigid_edit<const D: usize>(
    radii: [f64; D],
    spec: &str,
    rot: nalgebra::SMatrix<f64, D, D>,
    shift: Vect<D>,
) where
    Dim<D>: Rigid<D>,
{
    let pts = blob(radii, 20_000);
    let complex = cells(&pts, &[], 0.2);
    let constraints = resolved(&complex, &pts, spec);
    let sol = solve::solve(
        complex,
        constraints,
        &SolveParams::default(),
        Budget::default(),
        &Silent,
    )
    .unwrap();
    monotone(&sol.info);
    let origin = sol.complex.grid.origin;
    let extent = 2.0 * radii.iter().cloned().fold(0.0, f64::max);
    for (c, m) in sol.complex.cells.iter().zip(&sol.motions) {
        // The world map: x ↦ R (x − pivot) + pivot + shift with pivot at the origin of the spec.
        let world = c.center + origin;
        let want = rot * world + shift - origin;
        assert!(
            (m.pos - want).norm() < 1e-6 * extent,
            "cell at {world:?}: {:?} vs {want:?}",
            m.pos
        );
        assert!((m.rot - rot).norm() < 1e-6);
    }
}

#[test]
fn same_rigid_motion_everywhere_3d() {
    let r = <Dim<3> as Rigid<3>>::axis_angle(&Vect::<3>::new(0.0, 0.0, 1.0), 50f64.to_radians());
    let spec = r#"
[[handle]]
box = { min = [-3.0, -3.0, -3.0], max = [-1.5, 3.0, 3.0] }
rotate = { axis = [0.0, 0.0, 1.0], degrees = 50.0 }
pivot = [0.0, 0.0, 0.0]
translate = [1.0, 2.0, 3.0]
[[handle]]
sphere = { center = [2.0, 0.0, 0.0], radius = 0.5 }
rotate = { axis = [0.0, 0.0, 1.0], degrees = 50.0 }
pivot = [0.0, 0.0, 0.0]
translate = [1.0, 2.0, 3.0]
"#;
    rigid_edit::<3>([2.0, 1.0, 1.0], spec, r, Vect::<3>::new(1.0, 2.0, 3.0));
}

#[test]
fn same_rigid_motion_everywhere_2d() {
    let r = <Dim<2> as Rigid<2>>::axis_angle(&Vect::<2>::zeros(), 120f64.to_radians());
    let spec = r#"
[[handle]]
box = { min = [-3.0, -3.0], max = [-1.5, 3.0] }
rotate = { degrees = 120.0 }
pivot = [0.0, 0.0]
translate = [-1.0, 0.5]
[[handle]]
box = { min = [1.5, -3.0], max = [3.0, 3.0] }
rotate = { degrees = 120.0 }
pivot = [0.0, 0.0]
translate = [-1.0, 0.5]
"#;
    rigid_edit::<2>([2.0, 1.0], spec, r, Vect::<2>::new(-1.0, 0.5));
}

/// `--refine-strain`: strained cells split, children inherit motion and constraint, the solve
/// continues, and the refined complex is valid and lower in energy.
#[test]
fn refinement_splits_strained_cells_and_continues() {
    let (pts, triangles) = bar([6.0, 1.0, 1.0], 8.0);
    let complex = cells(&pts, &triangles, 0.5);
    let constraints = resolved(
        &complex,
        &pts,
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[handle]]\nbox = { min = [5.5, -0.1, -0.1], max = [6.1, 1.1, 1.1] }\n\
         rotate = { axis = [0.0, 1.0, 0.0], degrees = -60.0 }\ntranslate = [-1.0, 0.0, 2.5]\n",
    );
    let plain = solve::solve(
        complex.clone(),
        constraints.clone(),
        &SolveParams::default(),
        Budget::default(),
        &Silent,
    )
    .unwrap();
    let strain = solve::cell_strain(&plain.complex, &plain.motions);
    let tau = strain.iter().cloned().fold(0.0, f64::max) * 0.5;
    let params = SolveParams {
        refine_strain: Some(tau),
        ..Default::default()
    };
    let refined = solve::solve(complex, constraints, &params, Budget::default(), &Silent).unwrap();
    let info = &refined.info;
    assert!(!info.refinements.is_empty());
    assert!(info.cells_final > info.cells_initial);
    refined.complex.validate().unwrap();
    monotone(info);
    // Fixed cells stayed fixed through the split, handle cells follow the handle.
    for (c, role) in refined.complex.cells.iter().zip(&refined.constraints.roles) {
        if *role == Role::Fixed {
            assert!(
                (refined.motions[refined.complex.find(&c.key).unwrap()].pos - c.center).norm()
                    < 1e-12
            );
        }
    }
    // More freedom: the energy at the end is below the unrefined optimum.
    let e_plain = *plain.info.energies.last().unwrap();
    let e_refined = *info.energies.last().unwrap();
    assert!(e_refined < e_plain, "{e_refined} vs {e_plain}");
}

/// The blob's west end fixed and its east end turned by 20° about y and lifted by `lift`.
fn lifted_end(lift: f64) -> String {
    format!(
        r#"
[[fixed]]
box = {{ min = [-3.0, -3.0, -3.0], max = [-1.5, 3.0, 3.0] }}
[[handle]]
box = {{ min = [1.5, -3.0, -3.0], max = [3.0, 3.0, 3.0] }}
rotate = {{ axis = [0.0, 1.0, 0.0], degrees = -20.0 }}
pivot = [1.5, 0.0, 0.0]
translate = [0.0, 0.0, {lift}]
"#
    )
}

/// The interactive case: after a bend is solved, dragging the handle a little further and
/// updating the session from the solved motions reaches the same minimum as a solve from rest
/// of the new edit, in fewer iterations, with the symbolic factorization kept.
#[test]
fn a_session_follows_a_dragged_handle_from_its_last_solution() {
    let pts = blob([2.0, 1.0, 1.0], 20_000);
    let complex = cells(&pts, &[], 0.2);
    let spec = |lift: f64| resolved(&complex, &pts, &lifted_end(lift));
    let solve_params = SolveParams::default();
    let (mut session, first) = solve::Session::new(
        complex.clone(),
        spec(0.8),
        &solve_params,
        Budget::default(),
        &Silent,
    )
    .unwrap();
    assert!(first.iterations > 0);
    let warm = session.update(spec(0.9)).unwrap();
    assert_eq!(
        warm.seconds_symbolic, 0.0,
        "the symbolic factorization is kept"
    );
    let cold = solve::solve(
        complex.clone(),
        spec(0.9),
        &solve_params,
        Budget::default(),
        &Silent,
    )
    .unwrap();
    monotone(&warm);
    assert!(
        warm.iterations < cold.info.iterations,
        "warm {} iterations, cold {}",
        warm.iterations,
        cold.info.iterations
    );
    let (e_warm, e_cold) = (
        *warm.energies.last().unwrap(),
        *cold.info.energies.last().unwrap(),
    );
    assert!(
        (e_warm - e_cold).abs() <= 1e-3 * e_cold,
        "{e_warm} vs {e_cold}"
    );
    let worst = session
        .motions()
        .iter()
        .zip(&cold.motions)
        .map(|(a, b)| (a.pos - b.pos).norm())
        .fold(0.0, f64::max);
    assert!(worst < 0.01, "cells differ by {worst}");
}

/// A drag on the cells' parents: each step moves the parents and the cells follow them (the
/// info says the cells are not converged; the fixed cells stay at rest, the handle's cells
/// are where the pose puts them), and the update after the drag solves the cells to the
/// minimum an update without the drag reaches.
#[test]
fn a_drag_on_the_parents_ends_where_the_cells_solve() {
    let pts = blob([2.0, 1.0, 1.0], 20_000);
    let complex = cells(&pts, &[], 0.2);
    let spec = |lift: f64| resolved(&complex, &pts, &lifted_end(lift));
    let session = || {
        let params = SolveParams::default();
        solve::Session::new(
            complex.clone(),
            spec(0.8),
            &params,
            Budget::default(),
            &Silent,
        )
        .unwrap()
        .0
    };
    let (mut dragged, mut plain) = (session(), session());
    for lift in [0.85, 0.9] {
        let info = dragged.drag_on_parents(spec(lift), 1).unwrap();
        let most = solve::DRAG_LOCAL_GLOBAL;
        assert!(
            !info.converged && (1..=most).contains(&info.iterations),
            "{info:?}"
        );
    }
    // The cells of a parent share its rotation.
    let rotations: std::collections::BTreeSet<Vec<u64>> = dragged
        .motions()
        .iter()
        .map(|m| m.rot.iter().map(|v| v.to_bits()).collect())
        .collect();
    assert!(
        3 * rotations.len() < 2 * complex.len(),
        "{} rotations",
        rotations.len()
    );
    let roles = &dragged.constraints().roles;
    let handle = dragged.constraints().handle_map(0, 1.0);
    for ((m, role), cell) in dragged.motions().iter().zip(roles).zip(&complex.cells) {
        let at = match role {
            solve::Role::Fixed => cell.center,
            solve::Role::Handle(_) => handle.cell_motion(&cell.center).pos,
            _ => continue,
        };
        assert!((m.pos - at).norm() < 1e-12, "{role:?} cell at {:?}", m.pos);
    }
    let (ends, direct) = (
        dragged.update(spec(0.9)).unwrap(),
        plain.update(spec(0.9)).unwrap(),
    );
    assert!(ends.converged && direct.converged);
    let (a, b) = (
        *ends.energies.last().unwrap(),
        *direct.energies.last().unwrap(),
    );
    assert!((a - b).abs() <= 1e-6 * b, "{a} after the drag, {b} without");
}

/// A session of the lifted end on `complex` after one drag step: the session, and how many
/// distinct rotations the cells took (cells that follow one ancestor share its rotation).
fn dragged(complex: &CellComplex<3>, pts: &[Vect<3>]) -> (solve::Session<3>, usize) {
    let spec = |lift: f64| resolved(complex, pts, &lifted_end(lift));
    let params = SolveParams::default();
    let (mut session, _) = solve::Session::new(
        complex.clone(),
        spec(0.0),
        &params,
        Budget::default(),
        &Silent,
    )
    .unwrap();
    let info = session.drag(spec(0.05), 1).unwrap();
    assert!(!info.converged, "{info:?}");
    let rotations: std::collections::BTreeSet<Vec<u64>> = session
        .motions()
        .iter()
        .map(|m| m.rot.iter().map(|v| v.to_bits()).collect())
        .collect();
    (session, rotations.len())
}

/// On a large complex a drag moves ancestors of a few thousand cells, older than the parents
/// where the parents are still many (a shell, whose parents merge about four cells each).
#[test]
fn a_drag_on_many_cells_moves_a_few_thousand_ancestors() {
    let pts = blob([2.0, 1.0, 1.0], 80_000);
    let complex = cells(&pts, &[], 0.03);
    // 25.7k cells, 6.3k parents, 1.9k grandparents.
    assert!(complex.len() > 4 * 6_000, "{} cells", complex.len());
    let (_, rotations) = dragged(&complex, &pts);
    assert!(rotations <= 6_000, "{rotations} rotations");
}

/// A drag on a few thousand cells of a solid moves their ancestors: a step on the cells
/// themselves would factor more than `DRAG_FACTOR_MOST` nonzeros. The release (an update on
/// the cells) then converges on the cells.
#[test]
fn a_drag_on_a_dense_solid_moves_its_ancestors() {
    let pts = blob([2.0, 1.0, 1.0], 60_000);
    let complex = cells(&pts, &[], 0.06);
    let n = complex.len();
    assert!(n < solve::DRAG_COARSE_FROM, "{n} cells");
    let (mut session, rotations) = dragged(&complex, &pts);
    assert!(2 * rotations < n, "{rotations} rotations for {n} cells");
    let info = session
        .update(resolved(&complex, &pts, &lifted_end(0.05)))
        .unwrap();
    assert!(info.converged, "{info:?}");
}

/// The multilevel path (conjugate gradients with the rigid-motion multigrid) reaches
/// the direct factorization's minimum, on a bent bar with a pin (3D) and on a 2D disk with a
/// turned handle, both large enough for a coarse level.
#[test]
fn multilevel_solve_reaches_the_direct_minimum() {
    let (pts, triangles) = bar([8.0, 1.0, 1.0], 12.0);
    same_minimum(
        &pts,
        &triangles,
        0.125,
        "[[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\
         [[handle]]\nbox = { min = [7.5, -0.1, -0.1], max = [8.1, 1.1, 1.1] }\n\
         rotate = { axis = [0.0, 1.0, 0.0], degrees = -70.0 }\ntranslate = [-1.5, 0.0, 3.0]\n\
         [[pin]]\npoint = [4.0, 0.5, 1.0]\nto = [4.0, 0.5, 2.2]\n",
    );
    same_minimum(
        &blob([4.0, 2.0], 20_000),
        &[],
        0.012,
        "[[fixed]]\nbox = { min = [-5, -3], max = [-3.0, 3] }\n\
         [[handle]]\nbox = { min = [3.0, -3], max = [5, 3] }\n\
         rotate = { degrees = 90.0 }\ntranslate = [0.0, 2.0]\n",
    );
}

/// Solves `spec` on the cells of `pts` directly and by the multilevel path, and checks that the
/// multilevel path reaches the direct minimum or one lower, within a thousandth of it, and
/// really ran on two levels. Lower: their load steps take different paths, and on the 2D blob
/// turned 90° the multilevel path ends at 5.4791 where the direct one stops at 5.4815, its last
/// step lowering the energy by less than the tolerance while moving cells by 0.12.
fn same_minimum<const D: usize>(pts: &[Vect<D>], triangles: &[[u32; 3]], cell: f64, spec: &str)
where
    Dim<D>: Rigid<D>,
{
    let complex = cells(pts, triangles, cell);
    assert!(complex.len() > 2000, "{D}D: {} cells", complex.len());
    let constraints = resolved(&complex, pts, spec);
    let solved = |method| {
        let params = SolveParams {
            method,
            ..Default::default()
        };
        let s = solve::solve(
            complex.clone(),
            constraints.clone(),
            &params,
            Budget::default(),
            &Silent,
        )
        .unwrap();
        monotone(&s.info);
        (*s.info.energies.last().unwrap(), s.info)
    };
    let (direct, _) = solved(solve::Method::Direct);
    let (multi, info) = solved(solve::Method::Multilevel);
    assert!(
        info.levels >= 2 && info.linear_iterations > 0,
        "{D}D: {info:?}"
    );
    assert!(
        multi <= (1.0 + 1e-4) * direct && multi >= (1.0 - 1e-3) * direct,
        "{D}D: multilevel {multi} vs direct {direct}"
    );
}

/// The end of the bar of [`bent_bar`] bent by −90° about y and moved by (−2.5, 0, 4).
const BEND: &str = "rotate = { axis = [0.0, 1.0, 0.0], degrees = -90.0 }
translate = [-2.5, 0.0, 4.0]";

/// The 8-long bar in cells of `cell`, its first 1.0 fixed and its last 1.0 moved by `motion`.
fn bent_bar(motion: &str, cell: f64) -> (CellComplex<3>, solve::Constraints<3>) {
    let (pts, triangles) = bar([8.0, 1.0, 1.0], 12.0);
    let complex = cells(&pts, &triangles, cell);
    let constraints = resolved(&complex, &pts, &bar_ends(motion));
    (complex, constraints)
}

/// [`solve::solve`] of copies of `complex` and `constraints`.
fn solve_bar(
    complex: &CellComplex<3>,
    constraints: &solve::Constraints<3>,
    params: &SolveParams,
) -> rigidcells::Result<solve::Solution<3>> {
    solve::solve(
        complex.clone(),
        constraints.clone(),
        params,
        Budget::default(),
        &Silent,
    )
}

/// Newton's curvature term (the default) reaches Gauss-Newton's minimum, or a lower
/// one, in fewer iterations on a bar bent by 90°, where the residuals at the minimum are large
/// and Gauss-Newton converges only linearly.
#[test]
fn newton_reaches_the_gauss_newton_minimum_in_fewer_iterations() {
    let (complex, constraints) = bent_bar(BEND, 0.25);
    let solved = |newton| {
        let params = SolveParams {
            newton,
            method: solve::Method::Direct,
            ..Default::default()
        };
        let s = solve_bar(&complex, &constraints, &params).unwrap();
        monotone(&s.info);
        assert!(s.info.converged, "newton {newton}: {:?}", s.info);
        s.info
    };
    let (newton, gauss) = (solved(true), solved(false));
    let (en, eg) = (
        *newton.energies.last().unwrap(),
        *gauss.energies.last().unwrap(),
    );
    assert!(en <= eg * (1.0 + 1e-6), "Newton {en} vs Gauss-Newton {eg}");
    assert!(
        (en - eg).abs() <= 1e-4 * eg,
        "Newton {en} vs Gauss-Newton {eg}"
    );
    let last = |i: &SolverInfo| *i.iterations_per_step.last().unwrap();
    // 4 against 6 iterations in the last load step here (4 against 7 at cells of 0.125).
    assert!(
        last(&newton) < last(&gauss) && newton.iterations < gauss.iterations,
        "Newton {newton:?} vs Gauss-Newton {gauss:?}"
    );
}

/// Workers that factor and solve the blocks sent to them in this process, counting the
/// blocks: the seam a process pool plugs into.
struct Counting(std::sync::atomic::AtomicUsize);

struct Factors(Vec<schwarz::BlockFactor>);

impl schwarz::Workers for Counting {
    fn factor(
        &self,
        blocks: Vec<schwarz::Block>,
    ) -> rigidcells::Result<Box<dyn schwarz::BlockSolves>> {
        self.0
            .fetch_add(blocks.len(), std::sync::atomic::Ordering::Relaxed);
        Ok(Box::new(Factors(
            blocks.iter().map(|b| b.factor().unwrap()).collect(),
        )))
    }
}

impl schwarz::BlockSolves for Factors {
    fn solve(&self, rhs: Vec<Vec<f64>>) -> rigidcells::Result<Vec<Vec<f64>>> {
        Ok(self
            .0
            .iter()
            .zip(&rhs)
            .map(|(f, r)| f.solve(r).unwrap())
            .collect())
    }
}

/// Local-global iterations with the global step by subdomains reach the default solve's
/// minimum, with the same motions whether the blocks are solved here or by workers; the
/// subdomains with a Gauss-Newton solver are refused.
#[test]
fn subdomains_reach_the_minimum_here_and_on_workers() {
    let (complex, constraints) = bent_bar(BEND, 0.25);
    let default = solve_bar(&complex, &constraints, &SolveParams::default()).unwrap();
    let split = SolveParams {
        subdomains: 4,
        ..Default::default()
    };
    let here = solve_bar(&complex, &constraints, &split).unwrap();
    monotone(&here.info);
    assert_eq!(here.info.linear_solver(), "local-global");
    let (e, e0) = (
        *here.info.energies.last().unwrap(),
        *default.info.energies.last().unwrap(),
    );
    assert!(
        (e - e0).abs() <= 1e-6 * e0,
        "by subdomains {e}, default {e0}"
    );
    let workers = std::sync::Arc::new(Counting(Default::default()));
    let registration = schwarz::register(workers.clone());
    let there = solve_bar(
        &complex,
        &constraints,
        &SolveParams {
            workers: Some(registration.id()),
            ..split
        },
    )
    .unwrap();
    assert_eq!(there.motions, here.motions);
    assert_eq!(there.info.linear_solver(), "local-global");
    assert!(workers.0.load(std::sync::atomic::Ordering::Relaxed) >= 4);
    // More subdomains than cells: one a cell (thousands of blocks factored and solved in
    // parallel, which once overflowed a thread's stack), the same minimum.
    let each = solve_bar(
        &complex,
        &constraints,
        &SolveParams {
            subdomains: 100_000,
            ..split
        },
    )
    .unwrap();
    let e1 = *each.info.energies.last().unwrap();
    assert!(
        (e1 - e0).abs() <= 1e-6 * e0,
        "a cell each {e1}, default {e0}"
    );
    let refused = solve_bar(
        &complex,
        &constraints,
        &SolveParams {
            method: solve::Method::Direct,
            ..split
        },
    )
    .unwrap_err();
    assert_eq!(refused.exit_code(), 4);
    assert!(
        refused.to_string().contains("--subdomains 4")
            && refused.to_string().contains("--solver direct"),
        "{refused}"
    );
}

/// Every iteration is logged with both stopping figures and its time's parts. With the move
/// test off the solve runs to the energy test; with the default tolerance it stops no later and
/// at the same minimum (1e-6); with a tolerance of many cells each load step stops after its
/// first full step; a tolerance that is not a number of cells is refused.
#[test]
fn the_iteration_log_says_why_each_load_step_stopped() {
    let (complex, constraints) = bent_bar(
        "rotate = { axis = [0.0, 1.0, 0.0], degrees = -60.0 }\ntranslate = [-1.0, 0.0, 2.0]",
        0.25,
    );
    // Gauss-Newton's: local-global iterations stop by the distance left to move, not by the
    // last one.
    let run = |move_tolerance| {
        let params = SolveParams {
            move_tolerance,
            method: solve::Method::Direct,
            ..Default::default()
        };
        solve_bar(&complex, &constraints, &params)
    };
    let energy_only = run(0.0).unwrap().info;
    let info = run(solve::MOVE_TOLERANCE).unwrap().info;
    for i in [&energy_only, &info] {
        assert_eq!(i.log.len(), i.iterations, "no load step taken again here");
        let mut after = i.energies.clone();
        for &s in i.step_starts.iter().rev() {
            after.remove(s);
        }
        let logged: Vec<f64> = i.log.iter().map(|l| l.energy).collect();
        assert_eq!(logged, after);
        for l in &i.log {
            assert!(l.load_step < i.step_starts.len(), "{l:?}");
            assert!(
                (0.0..=1.0).contains(&l.decrease) && l.largest_move >= 0.0,
                "{l:?}"
            );
            let seconds = [l.seconds_assembly, l.seconds_setup, l.seconds_linear];
            assert!(l.step_length > 0.0 && seconds.iter().all(|s| s.is_finite() && *s >= 0.0));
        }
    }
    let last = energy_only.log.last().unwrap();
    assert!(last.decrease <= 1e-6, "{last:?}");
    let last = info.log.last().unwrap();
    assert!(
        last.decrease <= 1e-6 || (last.step_length >= 1.0 && last.largest_move <= 1e-3),
        "{last:?}"
    );
    // (Not a law: an earlier load step stopped sooner starts the next elsewhere; on this bar it
    // holds, and the same every run.)
    assert!(info.iterations <= energy_only.iterations);
    let (a, b) = (
        *info.energies.last().unwrap(),
        *energy_only.energies.last().unwrap(),
    );
    assert!((a - b).abs() <= 1e-6 * b, "{a} against {b}");
    let loose = run(1e3).unwrap().info;
    assert!(
        loose.iterations_per_step.iter().all(|&n| n == 1),
        "{:?}",
        loose.iterations_per_step
    );
    assert!(matches!(run(f64::NAN), Err(rigidcells::Error::Param(_))));
}

/// Solved coarse to fine (two coarse stages, each starting the next finer one at its
/// solution), the bent bar reaches the minimum it reaches from rest (1e-6), with its fixed and
/// handle cells where they are prescribed, and its own cells need fewer iterations than from
/// rest; the automatic choice takes one stage for a complex of this size (4k cells).
#[test]
fn coarse_to_fine_reaches_the_minimum_from_rest_in_fewer_fine_iterations() {
    let (complex, constraints) = bent_bar(BEND, 0.125);
    let run = |coarse_levels| {
        let params = SolveParams {
            coarse_levels,
            ..Default::default()
        };
        let s = solve_bar(&complex, &constraints, &params).unwrap();
        assert!(s.info.converged, "{coarse_levels:?}: {:?}", s.info);
        s
    };
    let (rest, staged, auto) = (run(Some(0)), run(Some(2)), run(None));
    assert!((solve::COARSE_FROM..4 * solve::COARSE_STAGE).contains(&complex.len()));
    assert_eq!(auto.info.energies, run(Some(1)).info.energies);
    let energy = |s: &solve::Solution<3>| *s.info.energies.last().unwrap();
    let (a, b) = (energy(&staged), energy(&rest));
    assert!(
        (a - b).abs() <= 1e-6 * b,
        "coarse to fine {a} against {b} from rest"
    );
    // The load steps on the coarsest cells, then one stage for each finer complex.
    let stages = staged.info.iterations_per_step.len();
    assert_eq!(stages, staged.info.load_steps + 2, "{:?}", staged.info);
    assert_eq!(staged.info.cells_initial, complex.len());
    let fine = staged.info.iterations_per_step[stages - 1];
    assert!(
        fine < rest.info.iterations,
        "{fine} against {:?}",
        rest.info
    );
    let last = staged.info.log.last().unwrap();
    assert_eq!(last.load_step, stages - 1);
    for (c, role) in constraints.roles.iter().enumerate() {
        let (m, r) = (&staged.motions[c], &rest.motions[c]);
        if matches!(role, solve::Role::Fixed | solve::Role::Handle(_)) {
            assert!(m.rot == r.rot && m.pos == r.pos, "cell {c} ({role:?})");
        }
    }
}

/// A finer stage starts at its parents' minimum carried down, at full load: every one of its
/// iterations, the first too, takes Newton's curvature (by the factor and by the multilevel
/// path alike), and it reaches the minimum from rest.
#[test]
fn a_finer_stage_takes_newtons_curvature_from_its_first_iteration() {
    let (complex, constraints) = bent_bar(BEND, 0.125);
    let energy = |s: &solve::Solution<3>| *s.info.energies.last().unwrap();
    for method in [solve::Method::Direct, solve::Method::Multilevel] {
        let run = |coarse_levels| {
            let params = SolveParams {
                coarse_levels,
                method,
                ..Default::default()
            };
            solve_bar(&complex, &constraints, &params).unwrap()
        };
        let (rest, staged) = (run(Some(0)), run(Some(1)));
        let fine: Vec<_> = staged
            .info
            .log
            .iter()
            .filter(|l| l.cells == complex.len())
            .collect();
        assert!(!fine.is_empty(), "{method:?}: {:?}", staged.info.log);
        assert!(
            fine.iter()
                .all(|l| l.method == solve::IterationMethod::Newton),
            "{method:?}: {fine:?}"
        );
        // From rest each load step starts by Gauss-Newton, where the handles jumped.
        assert_eq!(
            rest.info.log[0].method,
            solve::IterationMethod::GaussNewton,
            "{method:?}"
        );
        let (a, b) = (energy(&staged), energy(&rest));
        assert!((a - b).abs() <= 1e-6 * b, "{method:?}: {a} against {b}");
    }
}

/// Merging sibling cells of one role keeps every fine cell's role (a region
/// ends where it ended), and the adaptive solve splits the strained cells again, meeting the
/// handle exactly with fewer cells than the uniform complex.
#[test]
fn coarsened_cells_keep_their_roles_and_adaptive_refines_where_it_bends() {
    let (pts, triangles) = bar([8.0, 1.0, 1.0], 12.0);
    let fine = cells(&pts, &triangles, 0.125);
    let spec = bar_ends("rotate = { axis = [0.0, 1.0, 0.0], degrees = -45.0 }");
    let constraints = resolved(&fine, &pts, &spec);
    let (coarse, merged) = solve::coarsen(&fine, &constraints, 2);
    coarse.validate().unwrap();
    assert!(
        3 * coarse.len() < fine.len(),
        "{} of {}",
        coarse.len(),
        fine.len()
    );
    for (c, cell) in fine.cells.iter().enumerate() {
        let k = coarse
            .locate(&cell.center)
            .expect("a fine cell lies in a coarse one");
        assert_eq!(merged.roles[k], constraints.roles[c], "fine cell {c}");
    }
    let (_, params) = solve::adaptive(
        0.125,
        &rigidcells::internal::cells::BuildParams::default(),
        &SolveParams::default(),
    )
    .unwrap();
    let s = solve::solve(
        fine.clone(),
        constraints.clone(),
        &params,
        Budget::default(),
        &Silent,
    )
    .unwrap();
    let (start, _) = solve::coarsen(&fine, &constraints, solve::ADAPTIVE_LEVELS);
    assert_eq!(s.info.cells_initial, start.len());
    assert!(
        s.info.cells_final > s.info.cells_initial && s.info.cells_final < fine.len(),
        "{:?} of {}",
        s.info.refinements,
        fine.len()
    );
    // Handle cells follow the handle exactly, fixed cells stay.
    for (c, cell) in s.complex.cells.iter().enumerate() {
        let m = &s.motions[c];
        match s.constraints.roles[c] {
            Role::Fixed => assert!((m.pos - cell.center).norm() < 1e-12),
            Role::Handle(k) => {
                let want = s
                    .constraints
                    .handle_map(k as usize, 1.0)
                    .apply(&cell.center);
                assert!((m.pos - want).norm() < 1e-9, "cell {c}");
            }
            _ => {}
        }
    }
}

/// A soft inside (the default) merges with the surface for a coarse stage: a parent of
/// surface and inside cells takes their mean stiffness, so the stage is as coarse as a uniform
/// solid's. The cells an adaptive solve starts from keep the two apart, each cell with the
/// stiffness of the cells it stands for.
#[test]
fn a_soft_inside_merges_with_the_surface_for_a_coarse_stage() {
    use rigidcells::internal::cells::CellKind;
    let (pts, triangles) = bar([8.0, 1.0, 1.0], 12.0);
    let fine = cells(&pts, &triangles, 0.125);
    assert!(fine.cells.iter().any(|c| c.kind == CellKind::Interior));
    let spec = bar_ends("rotate = { axis = [1.0, 0.0, 0.0], degrees = 90.0 }");
    let solid = resolved(&fine, &pts, &spec);
    let mut soft = solid.clone();
    soft.scale_interior(&fine, 0.05);
    let (solid_stage, _) = solve::coarsen_stage(&fine, &solid, 1);
    let (stage, merged) = solve::coarsen_stage(&fine, &soft, 1);
    assert_eq!(stage.len(), solid_stage.len());
    let (apart, kept) = solve::coarsen(&fine, &soft, 1);
    assert!(
        apart.len() > stage.len() + stage.len() / 2,
        "{} against {}",
        apart.len(),
        stage.len()
    );
    let mut sums = vec![(0.0, 0.0); stage.len()];
    for (c, cell) in fine.cells.iter().enumerate() {
        let k = stage.locate(&cell.center).unwrap();
        sums[k].0 += soft.stiffness[c];
        sums[k].1 += 1.0;
        let j = apart.locate(&cell.center).unwrap();
        assert_eq!(kept.stiffness[j], soft.stiffness[c], "fine cell {c}");
    }
    let mixed = sums
        .iter()
        .zip(&merged.stiffness)
        .inspect(|((sum, n), s)| assert!((*s - sum / n).abs() < 1e-12, "{s} against {}", sum / n))
        .filter(|(_, s)| **s > 0.05 && **s < 1.0)
        .count();
    assert!(mixed > 0);
}

/// A part kept at rest on the fine cells only for want of a constraint (a speck above the
/// bar) merges into the bar's cells when coarsened, and is then free: a cell at rest inside a
/// constrained part would pin it down (it sagged the corridor's middle from 13 m to 2 m).
#[test]
fn coarsening_frees_rest_parts_that_join_a_constrained_one() {
    let (mut pts, triangles) = bar([8.0, 1.0, 1.0], 12.0);
    let speck: Vec<Vect<3>> = (0..20)
        .map(|i| Vect::<3>::new(4.0 + 0.01 * i as f64, 0.5, 1.45))
        .collect();
    pts.extend(&speck);
    let fine = cells(&pts, &triangles, 0.125);
    let constraints = resolved(&fine, &pts, &bar_ends("translate = [0.0, 0.0, 1.0]"));
    assert!(
        constraints.roles.contains(&Role::Rest),
        "the speck is its own part"
    );
    let (coarse, merged) = solve::coarsen(&fine, &constraints, 3);
    let (component, count) = coarse.components();
    let mut anchored = vec![false; count];
    for (c, r) in merged.roles.iter().enumerate() {
        anchored[component[c] as usize] |= matches!(r, Role::Fixed | Role::Handle(_));
    }
    for (c, r) in merged.roles.iter().enumerate() {
        if *r == Role::Rest {
            assert!(
                !anchored[component[c] as usize],
                "cell {c} at rest in a moving part"
            );
        }
    }
    let speck_cell = coarse.locate(&(speck[0] - coarse.grid.origin)).unwrap();
    assert_eq!(merged.roles[speck_cell], Role::Free);
}

/// The glue energy, which the line search compares, is summed in a fixed order: the same bits
/// on one thread and on three.
#[test]
fn glue_energy_is_the_same_on_any_number_of_threads() {
    let (pts, triangles) = bar([8.0, 1.0, 1.0], 12.0);
    let complex = cells(&pts, &triangles, 0.1);
    let motions: Vec<Motion<3>> = complex
        .cells
        .iter()
        .map(|c| {
            let mut m = Motion::rest(&c.center);
            m.pos.z += 0.01 * c.center.x * c.center.x;
            m
        })
        .collect();
    let stiffness = vec![1.0; complex.len()];
    let energy = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| solve::glue_energy(&complex, &motions, &stiffness))
    };
    assert!(
        complex.pairs.len() > 1 << 13,
        "{} pairs",
        complex.pairs.len()
    );
    assert_eq!(energy(1).to_bits(), energy(3).to_bits());
}
