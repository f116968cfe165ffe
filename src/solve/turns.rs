//! How far each handle's turn reached through the cells: the solver's check that a load path
//! stayed on its branch, the report's `turn_asked_degrees` / `turn_taken_degrees`, and how a
//! turn is said to people (a bend or a twist, in degrees as typed).
//!
//! A rotation matrix cannot say how many whole turns it makes: a cell turned by 270° and one
//! turned by −90° have the same motion. What tells a twisted part from an untwisted one is the
//! chain of cells between the fixed cells and the handle, along which neighbors turn by little
//! relative to each other. `TurnGauge::taken` follows it over a breadth-first tree from the
//! fixed cells and gives the median over the handle's cells of two things carried along it:
//!
//! - each cell's rotation *lifted* along the chain: its unit quaternion, of the sign nearest
//!   its parent's. Rotations form a space with two kinds of paths between two poses, told apart
//!   by the lifted quaternion's sign at the end, whatever the path (a half turn bent forwards
//!   ends at `q`, bent backwards at `−q`; a whole turn twisted in ends at `−1`, untwisted at
//!   `1`). Its turn about the handle's axis, `2 atan2(q⃗ · n, q_w)`, is therefore exact up to
//!   whole double turns (720°): on the asked branch it is the handle's turn itself, after the
//!   part gave way it is a whole turn off;
//! - the twists about the handle's axis summed pair by pair (each the twist of `R_j R_iᵀ`, in
//!   (−180°, 180°]), which only picks the number of double turns. A sum alone drifts where
//!   neighbors turn about other axes too — the relative rotations of a bend that is not planar
//!   do not commute: the dragon's head bent 180° about its neck summed to 165°, and a chain
//!   that reaches a half turn about z by turning about x and y sums to 0°.
//!
//! A turn is a bend or a twist ([`TurnKind`]) by the angle between its axis and the direction
//! from the fixed cells to the handle; its messages ([`TurnRefusal::said`],
//! [`HandleTurn::said`]) print angles with [`crate::human::degrees`] and name the handle as
//! the command line does, or leave the name to the face (Python names `spec["handle"][0]`,
//! Blender "the handle Empty").

use nalgebra::UnitQuaternion;

use crate::cells::CellComplex;
use crate::human::degrees;
use crate::rigid::{Dim, Motion, Rigid};

use super::constraints::{Constraints, Role, in_3d};
pub use crate::error::{TurnKind, TurnRefusal, handle_named};

/// A turn is a twist where its axis lies within this angle (45°) of the direction from the fixed
/// cells to the handle's cells, else a bend.
pub(crate) const TWIST_WITHIN_DEGREES: f64 = 45.0;

impl TurnKind {
    /// The kind of handle `k`'s turn: by the angle between its axis and the direction from the
    /// fixed cells to its cells ([`Constraints::arm`]; a bend without fixed cells, and in 2D,
    /// where every turn is about the plane's normal).
    pub fn of<const D: usize>(
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        k: usize,
    ) -> Self
    where
        Dim<D>: Rigid<D>,
    {
        let axis = <Dim<D> as Rigid<D>>::axis_3d(&constraints.handles[k].motion.turn.0);
        let arm = constraints.arm(complex, k).map(|a| in_3d(&a).normalize());
        match arm {
            Some(arm) if axis.dot(&arm).abs() >= TWIST_WITHIN_DEGREES.to_radians().cos() => {
                TurnKind::Twist
            }
            _ => TurnKind::Bend,
        }
    }
}

/// A handle's turn: as asked by the spec and as carried by the cells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandleTurn {
    /// The handle's index among the spec's handles (0 for the first).
    pub handle: usize,
    /// The handle's line in the edit spec.
    pub line: usize,
    /// A bend or a twist.
    pub kind: TurnKind,
    /// The turn asked, in degrees, as the user would write it
    /// ([`crate::spec::HandleMotion::asked_degrees`]): signed, of any size (720 is two whole
    /// turns). A matrix's half turn, which the solver may take either way round, is said
    /// about the axis that makes it positive.
    pub asked_degrees: f64,
    /// The turn the cells carry from the fixed cells to the handle, in degrees (about the
    /// axis of `asked_degrees`); `None` when no chain of cells joins the handle to a fixed
    /// cell (nothing to turn against).
    pub taken_degrees: Option<f64>,
}

impl HandleTurn {
    /// Whether the turn taken differs from the one asked by more than a tenth of it, and by
    /// a degree at least (a turn asked of nothing — a quaternion typed at 720°, the identity —
    /// is not missed by the cells' fraction of a degree).
    pub fn differs(&self) -> bool {
        self.taken_degrees.is_some_and(|t| {
            (t - self.asked_degrees).abs() > (0.1 * self.asked_degrees.abs()).max(1.0)
        })
    }

    /// The warning for a turn that [`HandleTurn::differs`], the handle named as each face
    /// names its spec's entries ([`crate::said::Part::Entry`]: `handle #1 (line 3)` on the
    /// command line, `spec["handle"][0]` in Python, the handle group in Blender).
    pub fn warning(&self) -> Option<crate::said::Said> {
        self.said().map(|said| {
            crate::said::Said::new()
                .entry("handle", self.handle, self.line)
                .text(format!(" {said}"))
        })
    }

    /// The warning for a turn that [`HandleTurn::differs`] after the handle's name (a face
    /// names the handle its own way): `bends by 180°, but the cells …`.
    pub fn said(&self) -> Option<String> {
        let taken = self.taken_degrees?;
        let word = self.kind.name();
        self.differs().then(|| {
            format!(
                "{word}s by {}, but the cells between it and the fixed cells carry {}: the \
                 shape did not {word} as asked",
                degrees(self.asked_degrees),
                degrees(taken.round()),
            )
        })
    }
}

impl TurnRefusal {
    /// The refusal of handle `k`'s turn, held to the load fraction `held`.
    pub(crate) fn new<const D: usize>(
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        k: usize,
        held: f64,
    ) -> Self
    where
        Dim<D>: Rigid<D>,
    {
        let h = &constraints.handles[k];
        let (sign, asked) = asked(constraints, k);
        let other_way_degrees = (!h.motion.from_matrix && (asked.abs() - 180.0).abs() <= 1.0)
            .then(|| asked - 360f64.copysign(asked));
        Self {
            handle: k,
            line: h.line,
            kind: TurnKind::of(complex, constraints, k),
            asked_degrees: asked,
            held_degrees: (sign * held * h.motion.turn.1.to_degrees()).round(),
            other_way_degrees,
        }
    }
}

/// Handle `k`'s turn as asked, in degrees, with the sign that makes a matrix's turn positive
/// (the sign, and the turn).
fn asked<const D: usize>(constraints: &Constraints<D>, k: usize) -> (f64, f64) {
    let motion = &constraints.handles[k].motion;
    let sign = match motion.from_matrix && motion.turn.1 < 0.0 {
        true => -1.0,
        false => 1.0,
    };
    (sign, sign * motion.asked_degrees())
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
        let unit = <Dim<D> as Rigid<D>>::axis_3d(&axis);
        let handle = Role::Handle(k as u32);
        // Per cell: the twists summed along the chain, and its rotation lifted along the chain
        // (a quaternion of the sign nearest its parent's).
        let mut phi = vec![f64::NAN; motions.len()];
        let mut lift = vec![UnitQuaternion::identity(); motions.len()];
        let mut queue = std::collections::VecDeque::new();
        for (c, role) in constraints.roles.iter().enumerate() {
            if *role == Role::Fixed {
                phi[c] = 0.0;
                lift[c] = <Dim<D> as Rigid<D>>::quaternion(&motions[c].rot);
                if lift[c].w < 0.0 {
                    lift[c] = UnitQuaternion::new_unchecked(-lift[c].into_inner());
                }
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
                let q = <Dim<D> as Rigid<D>>::quaternion(&motions[n].rot).into_inner();
                lift[n] = match q.coords.dot(&lift[c].coords) < 0.0 {
                    true => UnitQuaternion::new_unchecked(-q),
                    false => UnitQuaternion::new_unchecked(q),
                };
                if constraints.roles[n] == handle {
                    // The lifted rotation's turn about the axis, in (−2π, 2π], with as many
                    // double turns as bring it nearest the summed twists.
                    let q = &lift[n];
                    let turn = 2.0 * q.imag().dot(&unit).atan2(q.w);
                    let tau = 2.0 * std::f64::consts::TAU;
                    reached.push(turn + tau * ((phi[n] - turn) / tau).round());
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
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        motions: &[Motion<D>],
    ) -> Vec<HandleTurn>
    where
        Dim<D>: Rigid<D>,
    {
        turning(constraints)
            .map(|k| {
                let (sign, asked) = asked(constraints, k);
                let taken = self.taken(constraints, motions, k);
                HandleTurn {
                    handle: k,
                    line: constraints.handles[k].line,
                    kind: TurnKind::of(complex, constraints, k),
                    asked_degrees: asked,
                    taken_degrees: taken.map(|t| sign * t.to_degrees()),
                }
            })
            .collect()
    }
}

/// The first turning handle whose turn the cells carry at load fraction `to` more than a
/// quarter turn off (`super::BRANCH_JUMP`), if any: the part has left the branch the load path
/// was on.
pub(crate) fn lost_turn<const D: usize>(
    gauge: &TurnGauge,
    constraints: &Constraints<D>,
    motions: &[Motion<D>],
    to: f64,
) -> Option<usize>
where
    Dim<D>: Rigid<D>,
{
    turning(constraints).find(|&k| {
        gauge.taken(constraints, motions, k).is_some_and(|taken| {
            (taken - to * constraints.handles[k].motion.turn.1).abs() > super::BRANCH_JUMP
        })
    })
}

/// The handles that turn.
pub(crate) fn turning<const D: usize>(
    constraints: &Constraints<D>,
) -> impl Iterator<Item = usize> + '_ {
    (0..constraints.handles.len()).filter(|&k| constraints.handles[k].motion.turn.1 != 0.0)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::cells::{BuildParams, build};
    use crate::memory::Budget;
    use crate::rigid::{Mat, Vect};
    use crate::solve::resolve;
    use crate::spec::parse_spec;

    /// A row of cells along x from 0 to 12, the first fixed, the last a handle turned by
    /// `motion`: the complex and its constraints.
    fn row(motion: &str) -> (CellComplex<3>, Constraints<3>) {
        let pts: Vec<Vect<3>> = (0..=240)
            .map(|i| Vect::<3>::new(0.05 * i as f64, 0.1, 0.1))
            .collect();
        let text = format!(
            "[[fixed]]\nbox = {{ min = [-1, -1, -1], max = [1, 1, 1] }}\n\
             [[handle]]\nbox = {{ min = [11, -1, -1], max = [13, 1, 1] }}\n{motion}\n"
        );
        edited(&pts, 0.25, &text)
    }

    /// The cells of size `cell` holding `pts`, and the constraints of the edit spec `text`.
    pub(in crate::internal::solve) fn edited(
        pts: &[Vect<3>],
        cell: f64,
        text: &str,
    ) -> (CellComplex<3>, Constraints<3>) {
        let params = BuildParams {
            cell_size: Some(cell),
            ..Default::default()
        };
        let complex = build(pts, &[], &params, Budget::default()).unwrap().0;
        let spec = parse_spec::<3>(text, ".".as_ref(), "t.toml".as_ref()).unwrap();
        let constraints = resolve(&complex, &spec, pts, None).unwrap();
        (complex, constraints)
    }

    fn turn(axis: Vect<3>, degrees: f64) -> Mat<3> {
        <Dim<3> as Rigid<3>>::axis_angle(&axis, degrees.to_radians())
    }

    /// A chain that reaches a half turn about z by turning about x, then about y, then about
    /// its own x the other way: it carries +180° about z, though no pair of neighbors twists
    /// about z at all (the summed twists say 0°). The turn taken is the chain's lifted
    /// rotation, not the sum.
    #[test]
    fn a_chain_turning_about_other_axes_carries_its_half_turn() {
        let (x, y, z) = (Vect::<3>::x(), Vect::<3>::y(), Vect::<3>::z());
        let (complex, constraints) = row("rotate = { axis = [0, 0, 1], degrees = 180 }");
        let motions: Vec<Motion<3>> = complex
            .cells
            .iter()
            .zip(&constraints.roles)
            .map(|(c, role)| {
                let along = c.center.x + constraints.origin.x;
                let s = ((along - 1.0) / 10.0).clamp(0.0, 1.0);
                let rot = match role {
                    Role::Fixed => Mat::<3>::identity(),
                    Role::Handle(_) => turn(z, 180.0),
                    _ if s < 1.0 / 3.0 => turn(x, 270.0 * s),
                    _ if s < 2.0 / 3.0 => turn(y, 540.0 * (s - 1.0 / 3.0)) * turn(x, 90.0),
                    _ => turn(y, 180.0) * turn(x, 90.0) * turn(x, -810.0 * (s - 2.0 / 3.0)),
                };
                Motion { rot, pos: c.center }
            })
            .collect();
        assert!((motions.last().unwrap().rot - turn(z, 180.0)).norm() < 1e-9);
        let taken = TurnGauge::new(&complex)
            .taken(&constraints, &motions, 0)
            .unwrap();
        assert!(
            (taken.to_degrees() - 180.0).abs() < 1e-6,
            "{}",
            taken.to_degrees()
        );
    }

    /// The messages say a bend or a twist, the angles as typed (a matrix's to a tenth of a
    /// degree), and the handle's line.
    #[test]
    fn messages_say_a_bend_or_a_twist_in_rounded_degrees() {
        let (complex, constraints) =
            row("rotate = { axis = [0, 0, 1], degrees = 180 }\npivot = [6, 2, 0]");
        assert_eq!(TurnKind::of(&complex, &constraints, 0), TurnKind::Bend);
        let refusal = TurnRefusal::new(&complex, &constraints, 0, 0.9);
        let text = refusal.to_string();
        assert!(
            text.starts_with("handle #1 (line 3) bends by 180°")
                && text.contains("gives way past 162°")
                && text.contains("by -180°, to the same pose")
                && !text.contains("twist"),
            "{text}"
        );
        let (complex, constraints) = row("rotate = { axis = [1, 0.2, 0], degrees = 33.25 }");
        assert_eq!(TurnKind::of(&complex, &constraints, 0), TurnKind::Twist);
        let turn = HandleTurn {
            handle: 0,
            line: 3,
            kind: TurnKind::Twist,
            asked_degrees: 33.25,
            taken_degrees: Some(-326.7499),
        };
        assert_eq!(
            turn.warning().unwrap().to_string(),
            "handle #1 (line 3) twists by 33.25°, but the cells between it and the fixed \
             cells carry -327°: the shape did not twist as asked"
        );
        // Each face names the handle its own way, as it names its spec's entries.
        struct Panel;
        impl crate::said::Terms for Panel {
            fn option(&self, o: crate::said::Opt) -> String {
                o.keyword().into()
            }
            fn entry(&self, kind: &str, _: usize, _: usize) -> String {
                format!("the {kind} group")
            }
        }
        let said = crate::said::Terms::render(&Panel, &turn.warning().unwrap());
        assert!(
            said.starts_with("the handle group twists by 33.25°"),
            "{said}"
        );
        // No turn asked (a quaternion typed at 720°) is not missed by a fraction of a degree;
        // a small turn missed by more than a degree is.
        let nothing = HandleTurn {
            asked_degrees: 1e-14,
            taken_degrees: Some(0.4),
            ..turn
        };
        assert_eq!(nothing.warning(), None);
        let missed = HandleTurn {
            asked_degrees: 5.0,
            taken_degrees: Some(3.5),
            ..turn
        };
        assert!(missed.warning().is_some());
        let matrix = "matrix = [[-1, 1e-7, 0, 12], [-1e-7, -1, 0, 4], [0, 0, 1, 0], [0, 0, 0, 1]]";
        let (complex, constraints) = row(matrix);
        let refusal = TurnRefusal::new(&complex, &constraints, 0, 0.5);
        let text = refusal.to_string();
        assert!(
            text.contains("bends by 180°, but") && text.contains("past 90°"),
            "{text}"
        );
        assert_eq!(refusal.other_way_degrees, None);
    }
}
