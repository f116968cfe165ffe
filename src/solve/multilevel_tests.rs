//! Tests of the multilevel hierarchy: its levels, their shape counted on the graph, the
//! solve and the refresh, the reused coarse analysis, threads, and the forcing term.

use super::*;

/// Small limits, so that a lattice of a few thousand cells has several levels; no level
/// past `factored` nodes is factored for being cheap.
const TEST_LIMITS: Limits = Limits {
    coarsest: 100,
    factored: 60,
    work: 0.0,
};

/// The Gauss-Newton matrix of a `w × h` lattice of 2D cells glued to their right and upper
/// neighbors at two points of each shared face, the left column glued to the ground;
/// `stiff` scales the horizontal glue.
fn lattice(w: usize, h: usize, stiff: f64) -> (BlockMatrix, Nodes<2>) {
    let at = |i: usize, j: usize| Vect::<2>::new(i as f64, j as f64);
    // Velocity at `q` of a cell centered at `y`: rows of `v + ω perp(q − y)`.
    let jac = |q: Vect<2>, y: Vect<2>| [[1.0, 0.0, -(q - y)[1]], [0.0, 1.0, (q - y)[0]]];
    let prod = |a: [[f64; 3]; 2], b: [[f64; 3]; 2], w: f64| {
        let mut m = [0.0; 9];
        for r in 0..3 {
            for c in 0..3 {
                m[r * 3 + c] = w * (a[0][r] * b[0][c] + a[1][r] * b[1][c]);
            }
        }
        m
    };
    let n = w * h;
    let mut diag = vec![0.0; n * 9];
    let (mut edges, mut blocks) = (Vec::new(), Vec::new());
    for j in 0..h {
        for i in 0..w {
            let a = j * w + i;
            let mut faces = vec![];
            if i + 1 < w {
                faces.push((a + 1, Vect::<2>::new(0.5, 0.0), stiff));
            }
            if j + 1 < h {
                faces.push((a + w, Vect::<2>::new(0.0, 0.5), 1.0));
            }
            for (b, half, k) in faces {
                let (ya, yb) = (at(i, j), at(b % w, b / w));
                let mid = ya + half;
                let along = Vect::<2>::new(-half[1], half[0]);
                let mut hab = [0.0; 9];
                for q in [mid + along, mid - along] {
                    let (ja, jb) = (jac(q, ya), jac(q, yb));
                    add(&mut diag[a * 9..a * 9 + 9], &prod(ja, ja, k));
                    add(&mut diag[b * 9..b * 9 + 9], &prod(jb, jb, k));
                    add(&mut hab, &prod(ja, jb, -k));
                }
                edges.push([a as u32, b as u32]);
                blocks.extend_from_slice(&hab);
            }
            if i == 0 {
                let y = at(i, j);
                for q in [
                    y + Vect::<2>::new(-0.5, 0.5),
                    y + Vect::<2>::new(-0.5, -0.5),
                ] {
                    add(
                        &mut diag[a * 9..a * 9 + 9],
                        &prod(jac(q, y), jac(q, y), 1.0),
                    );
                }
            }
        }
    }
    let rest: Vec<Vect<2>> = (0..n).map(|a| at(a % w, a / w)).collect();
    let nodes = Nodes {
        deformed: rest.clone(),
        rest,
        pinned: vec![false; n],
    };
    (BlockMatrix::new(3, n, diag, edges, blocks), nodes)
}

fn residual(a: &BlockMatrix, x: &[f64], b: &[f64]) -> f64 {
    let mut ax = vec![0.0; b.len()];
    a.mul(x, &mut ax);
    ax.iter()
        .zip(b)
        .map(|(p, q)| (p - q).powi(2))
        .sum::<f64>()
        .sqrt()
        / norm(b)
}

/// The hierarchy's shape counted on the graph alone is the hierarchy's: the same nodes
/// and edges on every level, the same smoothed prolongation.
#[test]
fn the_shape_counted_on_the_graph_is_the_hierarchys() {
    let (matrix, nodes) = lattice(192, 48, 1.0);
    let (rest, edges) = (nodes.rest.clone(), matrix.edges.clone());
    let h = Hierarchy::new(matrix, nodes, 1.0, TEST_LIMITS, None);
    let mut levels: Vec<(usize, usize)> = h
        .levels
        .iter()
        .map(|l| (l.smoother.n, l.smoother.edges.len()))
        .collect();
    let coarsest = h.coarsest.as_ref().unwrap();
    let nodes = h.levels.last().unwrap().prolongation.coarse;
    levels.push((nodes, coarsest.edges.len()));
    let shape = shape(rest, &edges, 1.0, TEST_LIMITS);
    assert!(levels.len() >= 4, "{levels:?}");
    assert_eq!(shape.levels, levels);
    assert_eq!(shape.prolongation, h.levels[0].prolongation.to.len());
    let mut edges = coarsest.edges.clone();
    edges.sort_unstable();
    assert_eq!(shape.coarsest_edges, edges);
}

/// The first level's groups hold eight cells on average (a grid of twice the cell size holds
/// four on a plate one cell thick), and more where that many groups are too many to factor,
/// up to twenty-four.
#[test]
fn the_first_groups_hold_eight_cells_or_more() {
    let first_groups = |factored: usize| {
        let (matrix, nodes) = lattice(96, 24, 1.0);
        let limits = Limits {
            factored,
            ..TEST_LIMITS
        };
        Hierarchy::new(matrix, nodes, 1.0, limits, None).levels[0]
            .prolongation
            .coarse
    };
    let n = 96 * 24;
    let roomy = first_groups(1000);
    assert!(
        roomy * 8 <= n && roomy * 16 > n,
        "{roomy} groups of {n} cells"
    );
    let tight = first_groups(60);
    assert!(
        tight < roomy,
        "{tight} groups, {roomy} where more may be factored"
    );
    assert!(tight * 24 <= n, "{tight} groups of {n} cells");
}

/// A coarse level past `factored` nodes (at most four times as many) is factored where its
/// factor is cheap enough, in the hierarchy and in its shape alike; and solves in fewer
/// iterations than with the unsmoothed level below it.
#[test]
fn a_cheap_coarse_level_is_factored_rather_than_coarsened() {
    let (matrix, nodes) = lattice(96, 24, 1.0);
    let (rest, edges) = (nodes.rest.clone(), matrix.edges.clone());
    let b: Vec<f64> = (0..matrix.len())
        .map(|i| ((i * 7919) % 13) as f64 - 6.0)
        .collect();
    let (check, _) = lattice(96, 24, 1.0);
    let deep = {
        let (matrix, nodes) = lattice(96, 24, 1.0);
        Hierarchy::new(matrix, nodes, 1.0, TEST_LIMITS, None)
    };
    let cheap = Limits {
        work: f64::INFINITY,
        ..TEST_LIMITS
    };
    let h = Hierarchy::new(matrix, nodes, 1.0, cheap, None);
    let coarse = h.levels.last().unwrap().prolongation.coarse;
    assert!(h.depth() < deep.depth(), "{} levels", h.depth());
    assert!(coarse > 60 && coarse <= 240, "{coarse} nodes factored");
    let shape = shape(rest, &edges, 1.0, cheap);
    assert_eq!(shape.levels.len(), h.depth());
    assert_eq!(shape.levels.last().unwrap().0, coarse);
    let (x, iterations) = h.solve(&b).unwrap();
    let (_, deeper) = deep.solve(&b).unwrap();
    assert!(residual(&check, &x, &b) <= TOLERANCE);
    assert!(
        iterations <= deeper,
        "{iterations} iterations against {deeper}"
    );
}

/// Four levels (a smoothed one, unsmoothed ones, a factored one) solve a thin lattice
/// plate to the tolerance in a bounded number of iterations; kept coarse levels with a
/// renewed finest one still solve a changed matrix.
#[test]
fn deep_hierarchy_solves_and_survives_a_refresh() {
    let (matrix, nodes) = lattice(192, 48, 1.0);
    let b: Vec<f64> = (0..matrix.len())
        .map(|i| ((i * 7919) % 13) as f64 - 6.0)
        .collect();
    let (check, _) = lattice(192, 48, 1.0);
    let mut h = Hierarchy::new(matrix, nodes, 1.0, TEST_LIMITS, None);
    assert!(h.depth() >= 4, "{} levels", h.depth());
    let (x, iterations) = h.solve(&b).unwrap();
    assert!(iterations <= 20, "{iterations} iterations");
    assert!(
        residual(&check, &x, &b) <= TOLERANCE,
        "{}",
        residual(&check, &x, &b)
    );

    let (changed, _) = lattice(192, 48, 3.0);
    let (check, _) = lattice(192, 48, 3.0);
    h.shed_finest();
    h.refresh(changed);
    let (x, again) = h.solve(&b).unwrap();
    assert!(again <= 30, "{again} iterations after the refresh");
    assert!(residual(&check, &x, &b) <= TOLERANCE);
}

/// The matrix a waiting hierarchy hands back ([`Hierarchy::shed_finest`]), its blocks written
/// over with the next system's, solves with the same bits as that system assembled anew: what
/// the Gauss-Newton steps of one minimization assemble into.
#[test]
fn a_matrix_assembled_into_the_shed_one_gives_the_same_bits() {
    let b: Vec<f64> = (0..96 * 24 * 3)
        .map(|i| ((i * 13) % 11) as f64 - 5.0)
        .collect();
    let build = || {
        let (matrix, nodes) = lattice(96, 24, 1.0);
        Hierarchy::new(matrix, nodes, 1.0, TEST_LIMITS, None)
    };
    let (mut reused, mut fresh) = (build(), build());
    let (next, _) = lattice(96, 24, 3.0);
    let mut spare = reused.shed_finest().expect("a level below the coarsest");
    spare.diag.copy_from_slice(&next.diag);
    spare.blocks.copy_from_slice(&next.blocks);
    reused.refresh(spare);
    fresh.shed_finest();
    fresh.refresh(next);
    assert_eq!(reused.solve(&b).unwrap(), fresh.solve(&b).unwrap());
}

/// A hierarchy built on an earlier one's coarsest analysis (the same groups, other values)
/// solves with the same bits as one built from nothing; a coarsest level of other edges
/// is analysed anew.
#[test]
fn a_reused_coarse_analysis_gives_the_same_bits() {
    let b: Vec<f64> = (0..96 * 24 * 3)
        .map(|i| ((i * 31) % 17) as f64 - 8.0)
        .collect();
    let build = |stiff: f64, reuse| {
        let (matrix, nodes) = lattice(96, 24, stiff);
        Hierarchy::new(matrix, nodes, 1.0, TEST_LIMITS, reuse)
    };
    let earlier = build(1.0, None).into_coarsest();
    assert!(earlier.as_ref().is_some_and(|f| f.values.is_none()));
    let fresh = build(3.0, None);
    // The same coarsest edges: the analysis is taken over, not made again.
    let edges = |h: &Hierarchy| h.coarsest.as_ref().map(|f| f.edges.clone());
    assert_eq!(edges(&fresh), earlier.as_ref().map(|f| f.edges.clone()));
    let reused = build(3.0, earlier);
    assert_eq!(fresh.solve(&b).unwrap(), reused.solve(&b).unwrap());
    let (small, nodes) = lattice(48, 24, 3.0);
    let other = Hierarchy::new(
        small,
        nodes,
        1.0,
        TEST_LIMITS,
        build(1.0, None).into_coarsest(),
    );
    let (check, _) = lattice(48, 24, 3.0);
    let b = &b[..check.len()];
    let (x, _) = other.solve(b).unwrap();
    assert!(residual(&check, &x, b) <= TOLERANCE);
}

/// The solve gives the same bits on one thread and on three (fixed summation orders).
#[test]
fn solves_the_same_on_any_number_of_threads() {
    let b: Vec<f64> = (0..96 * 24 * 3)
        .map(|i| ((i * 31) % 17) as f64 - 8.0)
        .collect();
    let solve = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (matrix, nodes) = lattice(96, 24, 1.0);
            Hierarchy::new(matrix, nodes, 1.0, TEST_LIMITS, None)
                .solve(&b)
                .unwrap()
        })
    };
    let (one, three) = (solve(1), solve(3));
    assert_eq!(one.1, three.1);
    assert!(
        one.0
            .iter()
            .zip(&three.0)
            .all(|(x, y)| x.to_bits() == y.to_bits())
    );
}

/// The first system of a solve is solved loosely, later ones as far as the gradient's fall
/// says (0.9 times its square), never looser than the first nor tighter than the floor; a step
/// the caller expects to be small is solved only as far as it asks, up to the loosest.
#[test]
fn the_forcing_term_follows_the_gradients_fall() {
    assert_eq!(forcing(3.0, None, 0.0), LOOSEST);
    assert_eq!(forcing(3.0, Some(2.0), 0.0), LOOSEST);
    let tenth = forcing(0.1, Some(1.0), 0.0);
    assert!((tenth - 0.009).abs() < 1e-15, "{tenth}");
    assert_eq!(forcing(1e-3, Some(1.0), 0.0), TOLERANCE);
    assert_eq!(forcing(1.0, Some(0.0), 0.0), LOOSEST);
    assert_eq!(forcing(1e-3, Some(1.0), 2e-3), 2e-3);
    assert_eq!(forcing(1e-3, Some(1.0), 0.5), LOOSEST);
    assert!((forcing(0.1, Some(1.0), 1e-3) - 0.009).abs() < 1e-15);
}
