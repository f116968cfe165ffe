//! Parts of a shape that no constraint reaches (a leaf, a fitting, a loose piece of a soup):
//! their cells have [`Role::Rest`] while the solve runs (`constraints::anchor` finds them among
//! the cells' connected parts), then are carried rigidly by the nearest constrained cell
//! ([`carry_loose`], `--loose-parts carry`) or left at rest, with a warning either way.

use super::constraints::{Constraints, LOOSE_WARNING, Role};
use crate::cells::CellComplex;
use crate::said::{Opt, Said};

/// What becomes of the parts of a shape that no constraint reaches (`--loose-parts`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LooseParts {
    /// Each rides along rigidly with the nearest cell of a constrained part ([`carry_loose`]).
    #[default]
    Carry,
    /// Each keeps its rest pose.
    Rest,
}

/// The end of the warning once [`carry_loose`] moved them.
fn carried_warning() -> Said {
    Said::from(
        "have no constraint and ride along rigidly with the nearest cell of a constrained part",
    )
    .aside(
        Said::from(" (")
            .set(Opt::LooseParts, "rest")
            .text(" keeps them at rest)"),
    )
}

/// Moves every cell at rest (in a part without constraints) rigidly with the nearest cell of a
/// constrained part — as a leaf follows its twig, a fitting its wall — and marks it
/// [`Role::Carried`]: each loose part takes, whole, the motion of the constrained cell nearest
/// to any of its cells, so it keeps its shape and its place beside that cell. `motions` are
/// the solved motions of `complex`; the warning about the parts at rest says what happened.
pub fn carry_loose<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &mut Constraints<D>,
    motions: &mut [crate::rigid::Motion<D>],
) {
    let anchors = loose_anchors(complex, &constraints.roles);
    carry_with(complex, constraints, motions, &anchors);
}

/// The cells [`carry_loose`] moves, each with the constrained cell whose motion it takes: a
/// function of the cells and their roles alone, which a session keeps while they stay.
pub(crate) fn loose_anchors<const D: usize>(
    complex: &CellComplex<D>,
    roles: &[Role],
) -> Vec<[u32; 2]> {
    if !roles.contains(&Role::Rest) {
        return Vec::new();
    }
    let anchored: Vec<u32> = (0..roles.len() as u32)
        .filter(|&c| !matches!(roles[c as usize], Role::Rest | Role::Carried(_)))
        .collect();
    if anchored.is_empty() {
        return Vec::new();
    }
    let centers: Vec<[f64; D]> = anchored
        .iter()
        .map(|&c| complex.cells[c as usize].center.into())
        .collect();
    // Cell centers are distinct, so the tree builds; should it not, the parts stay at rest
    // and the warning still says so.
    let Ok(tree) = kiddo::ImmutableKdTree::<f64, D>::new_from_slice(&centers) else {
        return Vec::new();
    };
    // Per loose part: its nearest constrained cell and the distance to it.
    let (component, count) = complex.components();
    let mut nearest: Vec<Option<(f64, u32)>> = vec![None; count];
    for (c, r) in roles.iter().enumerate() {
        if *r != Role::Rest {
            continue;
        }
        let q: [f64; D] = complex.cells[c].center.into();
        let one = std::num::NonZero::new(1).expect("1 is not 0");
        let Some(hit) = tree
            .query(&q)
            .nearest_n::<kiddo::SquaredEuclidean<f64>>(one)
            .execute()
            .first()
            .map(|r| (r.distance, r.item))
        else {
            continue;
        };
        let slot = &mut nearest[component[c] as usize];
        if slot.is_none_or(|(d, _)| hit.0 < d) {
            *slot = Some((hit.0, anchored[hit.1 as usize]));
        }
    }
    (0..roles.len())
        .filter(|&c| roles[c] == Role::Rest)
        .filter_map(|c| nearest[component[c] as usize].map(|(_, a)| [c as u32, a]))
        .collect()
}

/// [`carry_loose`] with its [`loose_anchors`] known.
pub(crate) fn carry_with<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &mut Constraints<D>,
    motions: &mut [crate::rigid::Motion<D>],
    anchors: &[[u32; 2]],
) {
    for &[c, a] in anchors {
        let (c, a) = (c as usize, a as usize);
        let (anchor, m) = (&complex.cells[a], motions[a]);
        motions[c] = crate::rigid::Motion {
            rot: m.rot,
            pos: m.apply(&anchor.center, &complex.cells[c].center),
        };
        constraints.roles[c] = Role::Carried(a as u32);
    }
    if anchors.is_empty() {
        return;
    }
    for w in &mut constraints.warnings {
        if let Some(head) = w.strip_suffix(LOOSE_WARNING) {
            *w = head.then(carried_warning());
        }
    }
}
