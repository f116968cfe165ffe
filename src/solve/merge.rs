//! The cells merged into their parents and split into their children, with their
//! constraints: the coarse stages and the adaptive solve's cells ([`coarsen`],
//! [`coarsen_stage`]), and the children a refinement makes ([`inherit`]).

use crate::cells::{CellComplex, CellKey};
use crate::rigid::Vect;

use super::constraints::{Constraints, LOOSE_WARNING, Role, TargetLocal, anchor};

/// The constraints of a complex made by [`CellComplex::split`]: children inherit their parent's
/// role and stiffness, except that a pin stays with the child holding the pinned point; targets
/// move to the child holding their point.
pub fn inherit<const D: usize>(
    old: &Constraints<D>,
    complex: &CellComplex<D>,
    parent: &[u32],
) -> Constraints<D> {
    let mut roles: Vec<Role> = parent.iter().map(|&p| old.roles[p as usize]).collect();
    let stiffness = parent.iter().map(|&p| old.stiffness[p as usize]).collect();
    // A region with a border holds the children whose centers it holds, as it held the parents
    // whose centers it held (a parent's center: the mean of its children's).
    let mut sums = vec![(Vect::<D>::zeros(), 0.0); old.roles.len()];
    for (c, &p) in parent.iter().enumerate() {
        sums[p as usize].0 += complex.cells[c].center;
        sums[p as usize].1 += 1.0;
    }
    let bordered: Vec<Role> = old
        .region_roles()
        .filter(|&r| old.shape_of(r).is_some())
        .collect();
    for (c, role) in roles.iter_mut().enumerate() {
        let center = complex.cells[c].center + old.origin;
        let (sum, count) = sums[parent[c] as usize];
        let was = sum / count + old.origin;
        match old.shape_of(*role) {
            Some(shape) if shape.contains(&was) && !shape.contains(&center) => *role = Role::Free,
            None if *role == Role::Free => {
                if let Some(&r) = bordered
                    .iter()
                    .find(|&&r| old.shape_of(r).is_some_and(|s| s.contains(&center)))
                {
                    *role = r;
                }
            }
            _ => {}
        }
    }
    let mut pins = old.pins.clone();
    for (k, pin) in pins.iter_mut().enumerate() {
        let cell = complex
            .locate(&pin.point)
            .filter(|&c| parent[c] == pin.cell)
            .or_else(|| parent.iter().position(|&p| p == pin.cell))
            .unwrap_or(0);
        for (c, r) in roles.iter_mut().enumerate() {
            if *r == Role::Pin(k as u32) && c != cell {
                *r = Role::Free;
            }
        }
        pin.cell = cell as u32;
    }
    let targets = old
        .targets
        .iter()
        .map(|t| TargetLocal {
            cell: complex
                .locate(&t.from)
                .filter(|&c| parent[c] == t.cell)
                .or_else(|| parent.iter().position(|&p| p == t.cell))
                .unwrap_or(0) as u32,
            ..*t
        })
        .collect();
    Constraints {
        roles,
        handles: old.handles.clone(),
        pins,
        targets,
        stiffness,
        inside: old.inside,
        origin: old.origin,
        warnings: old.warnings.clone(),
        trend: old.trend.clone(),
        trend_kind: old.trend_kind,
        shapes: old.shapes.clone(),
    }
}

/// The complex with sibling leaves merged into their parent, up to `levels` times, wherever
/// all the leaves inside the parent are its children and share one role and one stiffness,
/// and none holds a pin or a soft target; with its constraints. The cells along a
/// constraint's border (where roles differ) keep the size they were resolved at, so a region
/// ends where it ends on the fine cells; elsewhere the cells are as coarse as `levels`
/// allows, and [`super::adaptive`] splits them again where the solved strain is high: the
/// cells an adaptive solve starts from (`--min-cell-size`), each with the stiffness of the
/// cells it stands for.
pub fn coarsen<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    levels: u8,
) -> (CellComplex<D>, Constraints<D>) {
    merged(complex, constraints, levels, false)
}

/// [`coarsen`] for a stage that only starts the cells' own solve (a coarse-to-fine stage, a
/// drag's ancestors): the inside's scale ([`Constraints::inside`]) does not keep siblings
/// apart, a parent of surface and inside cells taking their mean stiffness. Kept apart, a
/// soft inside leaves the cells along the surface at their size: the bust's 14,962 cells
/// merge to 11,618 a level up instead of 3,912, and neither its coarse stage nor a drag's
/// ancestors are coarse (a drag at 15,000 cells takes 63 ms instead of 15).
pub fn coarsen_stage<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    levels: u8,
) -> (CellComplex<D>, Constraints<D>) {
    merged(complex, constraints, levels, true)
}

fn merged<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    levels: u8,
    across_inside: bool,
) -> (CellComplex<D>, Constraints<D>) {
    use crate::cells::CellKind;
    use rustc_hash::FxHashMap;
    let mut keep = vec![false; complex.len()];
    for p in &constraints.pins {
        keep[p.cell as usize] = true;
    }
    for t in &constraints.targets {
        keep[t.cell as usize] = true;
    }
    // (key, kind, role, stiffness, keep, the spec's stiffness)
    let mut leaves: Vec<(CellKey<D>, CellKind, Role, f64, bool, f64)> = complex
        .cells
        .iter()
        .enumerate()
        .map(|(c, cell)| {
            let keep = keep[c] || matches!(constraints.roles[c], Role::Pin(_));
            // A part kept at rest only for want of a constraint may merge into a neighbor and
            // so join a constrained part: its role is decided again below.
            let role = match constraints.roles[c] {
                Role::Rest => Role::Free,
                r => r,
            };
            let s = constraints.stiffness[c];
            let spec = match cell.kind {
                CellKind::Interior if across_inside => s / constraints.inside,
                _ => s,
            };
            (cell.key, cell.kind, role, s, keep, spec)
        })
        .collect();
    let deepest = leaves.iter().map(|l| l.0.level).max().unwrap_or(0);
    for level in (1..=deepest).rev().take(levels as usize) {
        // Parents whose inside holds a leaf other than their mergeable children.
        let mut blocked: rustc_hash::FxHashSet<CellKey<D>> = Default::default();
        let mut groups: FxHashMap<CellKey<D>, Vec<usize>> = FxHashMap::default();
        for (i, l) in leaves.iter().enumerate() {
            if l.0.level > level {
                let mut k = l.0;
                while k.level >= level {
                    k = k.parent().expect("level > 0");
                }
                blocked.insert(k);
            } else if l.0.level == level {
                let parent = l.0.parent().expect("level > 0");
                if l.4 {
                    blocked.insert(parent);
                }
                groups.entry(parent).or_default().push(i);
            }
        }
        let mut merged = vec![false; leaves.len()];
        let mut parents = Vec::new();
        for (parent, members) in &groups {
            let first = &leaves[members[0]];
            let same = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs());
            if blocked.contains(parent)
                || members
                    .iter()
                    .any(|&i| leaves[i].2 != first.2 || !same(leaves[i].5, first.5))
            {
                continue;
            }
            let stiffness =
                members.iter().map(|&i| leaves[i].3).sum::<f64>() / members.len() as f64;
            let kind = if members.iter().any(|&i| leaves[i].1 == CellKind::Boundary) {
                CellKind::Boundary
            } else {
                CellKind::Interior
            };
            for &i in members {
                merged[i] = true;
            }
            parents.push((*parent, kind, first.2, stiffness, false, first.5));
        }
        let mut next: Vec<_> = leaves
            .iter()
            .zip(&merged)
            .filter(|(_, m)| !**m)
            .map(|(l, _)| *l)
            .collect();
        next.extend(parents);
        leaves = next;
    }
    leaves.sort_unstable_by_key(|l| l.0);
    let coarse = CellComplex::from_keys(complex.grid, leaves.iter().map(|l| (l.0, l.1)).collect());
    let mut out = Constraints {
        roles: leaves.iter().map(|l| l.2).collect(),
        stiffness: leaves.iter().map(|l| l.3).collect(),
        ..constraints.clone()
    };
    // The cells of pins and targets were kept as they were (`keep`): found again by key.
    let index_of = |c: u32| {
        let key = complex.cells[c as usize].key;
        leaves
            .binary_search_by_key(&key, |l| l.0)
            .expect("a kept cell is a leaf of the coarse complex") as u32
    };
    for p in &mut out.pins {
        p.cell = index_of(p.cell);
    }
    for t in &mut out.targets {
        t.cell = index_of(t.cell);
    }
    let (_, _, loose) = anchor(&coarse, &mut out.roles, &out.targets);
    out.warnings
        .retain(|w| w.strip_suffix(LOOSE_WARNING).is_none());
    out.warnings.extend(loose);
    (coarse, out)
}
