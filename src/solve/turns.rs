//! How far each handle's turn reached through the cells: the solver's check that a load path
//! stayed on its branch, and the report's `turn_asked_degrees` / `turn_taken_degrees`.
//!
//! A rotation matrix cannot say how many whole turns it makes: a cell turned by 270° and one
//! turned by −90° have the same motion. What tells a twisted part from an untwisted one is the
//! chain of cells between the fixed cells and the handle: neighbors turn by little relative to
//! each other, so the turn about the handle's axis can be summed pair by pair without
//! ambiguity, and the sum is the turn the shape carries from its fixed cells to its handle.
//! `TurnGauge::taken` sums it over a breadth-first tree from the fixed cells (each pair adds
//! the twist about the axis of `R_j R_iᵀ`, which lies in (−180°, 180°]) and gives the median
//! over the handle's cells. On the asked branch it equals the handle's turn (up to the
//! difference between summed twists and a composed rotation, a fraction of a degree on a
//! twisted or bent bar); after the part untwisted the short way round it is a whole turn off.

use crate::cells::CellComplex;
use crate::rigid::{Dim, Motion, Rigid};

use super::constraints::{Constraints, Role};

/// A handle's turn: as asked by the spec and as carried by the cells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandleTurn {
    /// The handle's line in the edit spec.
    pub line: usize,
    /// The turn asked, in degrees: signed, of any size (720 is two whole turns).
    pub asked_degrees: f64,
    /// The turn the cells carry from the fixed cells to the handle, in degrees; `None` when no
    /// chain of cells joins the handle to a fixed cell (nothing to turn against).
    pub taken_degrees: Option<f64>,
}

impl HandleTurn {
    /// Whether the turn taken differs from the one asked by more than a tenth of it.
    pub fn differs(&self) -> bool {
        self.taken_degrees
            .is_some_and(|t| (t - self.asked_degrees).abs() > 0.1 * self.asked_degrees.abs())
    }

    /// The warning for a turn that [`HandleTurn::differs`].
    pub fn warning(&self) -> Option<String> {
        let taken = self.taken_degrees?;
        self.differs().then(|| {
            format!(
                "the handle on line {} of the edit spec asked for a turn of {}°, but the cells \
                 between it and the fixed cells carry {taken:.0}°: the shape did not turn as \
                 asked",
                self.line, self.asked_degrees
            )
        })
    }
}

/// The face adjacency of a complex, for summing turns along chains of cells.
pub(crate) struct TurnGauge {
    offsets: Vec<u32>,
    neighbors: Vec<u32>,
}

impl TurnGauge {
    /// The adjacency of `complex`.
    pub fn new<const D: usize>(complex: &CellComplex<D>) -> Self {
        let n = complex.len();
        let mut offsets = vec![0u32; n + 1];
        for p in &complex.pairs {
            offsets[p.i as usize + 1] += 1;
            offsets[p.j as usize + 1] += 1;
        }
        for k in 0..n {
            offsets[k + 1] += offsets[k];
        }
        let mut fill = offsets.clone();
        let mut neighbors = vec![0u32; offsets[n] as usize];
        for p in &complex.pairs {
            for (a, b) in [(p.i, p.j), (p.j, p.i)] {
                neighbors[fill[a as usize] as usize] = b;
                fill[a as usize] += 1;
            }
        }
        Self { offsets, neighbors }
    }

    /// The turn in radians about handle `k`'s axis that the cells carry from the fixed cells
    /// to the handle's cells (see the module docs); `None` when the handle has no turn or no
    /// chain of cells joins it to a fixed cell.
    pub fn taken<const D: usize>(
        &self,
        constraints: &Constraints<D>,
        motions: &[Motion<D>],
        k: usize,
    ) -> Option<f64>
    where
        Dim<D>: Rigid<D>,
    {
        let axis = constraints.handles.get(k)?.motion.turn.0;
        let handle = Role::Handle(k as u32);
        let mut phi = vec![f64::NAN; motions.len()];
        let mut queue = std::collections::VecDeque::new();
        for (c, role) in constraints.roles.iter().enumerate() {
            if *role == Role::Fixed {
                phi[c] = 0.0;
                queue.push_back(c);
            }
        }
        let mut reached = Vec::new();
        while let Some(c) = queue.pop_front() {
            let (lo, hi) = (self.offsets[c] as usize, self.offsets[c + 1] as usize);
            for &n in &self.neighbors[lo..hi] {
                let n = n as usize;
                if !phi[n].is_nan() || matches!(constraints.roles[n], Role::Rest | Role::Carried(_))
                {
                    continue;
                }
                let relative = motions[n].rot * motions[c].rot.transpose();
                phi[n] = phi[c] + <Dim<D> as Rigid<D>>::twist(&relative, &axis);
                if constraints.roles[n] == handle {
                    reached.push(phi[n]);
                } else {
                    queue.push_back(n);
                }
            }
        }
        if reached.is_empty() {
            return None;
        }
        reached.sort_by(f64::total_cmp);
        Some(reached[reached.len() / 2])
    }

    /// Every turning handle's turn, asked and taken, at full load.
    pub fn turns<const D: usize>(
        &self,
        constraints: &Constraints<D>,
        motions: &[Motion<D>],
    ) -> Vec<HandleTurn>
    where
        Dim<D>: Rigid<D>,
    {
        turning(constraints)
            .map(|k| {
                let h = &constraints.handles[k];
                HandleTurn {
                    line: h.line,
                    asked_degrees: h.motion.turn.1.to_degrees(),
                    taken_degrees: self.taken(constraints, motions, k).map(f64::to_degrees),
                }
            })
            .collect()
    }
}

/// The handles that turn.
pub(crate) fn turning<const D: usize>(
    constraints: &Constraints<D>,
) -> impl Iterator<Item = usize> + '_ {
    (0..constraints.handles.len()).filter(|&k| constraints.handles[k].motion.turn.1 != 0.0)
}
