//! One iteration as the solver reports it ([`IterationLog`]): which kind, where it ended, the
//! figures its stopping rule reads, and where its time went.

use rayon::prelude::*;

use crate::cells::CellComplex;
use crate::rigid::{Motion, Vect};

/// The default [`super::SolveParams::move_tolerance`]: a thousandth of the finest cell.
pub const MOVE_TOLERANCE: f64 = 1e-3;

/// Whether a Newton iteration `now` that followed `before` (both in the same load step) leaves
/// the solve converged: both full steps, `now` contracting `before` by at least half, and the
/// tail that rate predicts — the move still to come `m·r/(1 − r)` for the ratio `r` of the last
/// two moves, and the energy still to gain the same way — within `move_tolerance` (finest
/// cells) and `tolerance` (relative). Newton converges at least this fast near a minimum, so
/// the next step, which would move less than the tolerance, need not be taken (at 431k cells a
/// Newton iteration takes 7–8 s).
pub(crate) fn newton_converged(
    before: &IterationLog,
    now: &IterationLog,
    tolerance: f64,
    move_tolerance: f64,
) -> bool {
    let tail = |last: f64, previous: f64| {
        let r = last / previous;
        (r < 0.5).then(|| last * r / (1.0 - r))
    };
    now.method == IterationMethod::Newton
        && before.load_step == now.load_step
        && before.step_length == 1.0
        && now.step_length == 1.0
        && tail(now.largest_move, before.largest_move).is_some_and(|m| m <= move_tolerance)
        && tail(now.decrease, before.decrease).is_some_and(|d| d <= tolerance)
}

/// What the iteration asking for a step knows that the multilevel path can use.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Ask {
    /// The last step lowered the energy by less than half: the coarse levels built for it may
    /// be kept (`multilevel` module, "Kept between steps").
    pub settled: bool,
    /// The loosest relative residual that still solves the step well within the move
    /// tolerance ([`enough_residual`]); 0 where nothing is known.
    pub enough: f64,
}

/// The loosest relative residual at which the linear solve of the step after `now` still
/// places it within a tenth of `move_tolerance` (finest cells): the step expected from the last
/// move `m`, solved to `0.1·move_tolerance / (m·r)` of itself. `r` is the rate of the last two
/// moves where `before` (the iteration before `now`, in the same load step, both full steps)
/// says it and they contract by at least half — a linear rate, which Newton's outruns near a
/// minimum — and 1 (the step no longer than the last) otherwise. The step is still taken and
/// its move measured: the stopping rule reads the move as solved, within a tenth of the
/// tolerance of the exact step's.
pub(crate) fn enough_residual(
    before: Option<&IterationLog>,
    now: &IterationLog,
    move_tolerance: f64,
) -> f64 {
    let rate = before.map_or(1.0, |before| {
        let r = now.largest_move / before.largest_move;
        let contracting = before.load_step == now.load_step
            && before.step_length == 1.0
            && now.step_length == 1.0
            && r < 0.5;
        if contracting { r } else { 1.0 }
    });
    match now.step_length == 1.0 && now.largest_move > 0.0 {
        true => 0.1 * move_tolerance / (now.largest_move * rate),
        false => 0.0,
    }
}

/// Which kind of iteration an [`IterationLog`] records.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum IterationMethod {
    /// A Gauss-Newton step (the normal equations without the rotations' curvature).
    #[default]
    GaussNewton,
    /// A Newton step: the rotations' second-order term added (or its positive part).
    Newton,
    /// A local-global iteration: Procrustes fits, then one back substitution.
    LocalGlobal,
    /// A local-global iteration whose Anderson-accelerated rotations were kept.
    Anderson,
}

impl IterationMethod {
    /// As the report writes it.
    pub fn name(self) -> &'static str {
        match self {
            IterationMethod::GaussNewton => "gauss-newton",
            IterationMethod::Newton => "newton",
            IterationMethod::LocalGlobal => "local-global",
            IterationMethod::Anderson => "anderson",
        }
    }
}

/// One accepted iteration: which kind, where it ended, why the solver went on or stopped, and
/// where its time went. A local-global iteration's `seconds_assembly` is its local step (the
/// Procrustes fits and Anderson's), `seconds_linear` its global steps (back substitutions),
/// `seconds_line_search` the energy's evaluations; its `step_length` is 1.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct IterationLog {
    /// The kind of iteration.
    pub method: IterationMethod,
    /// The load step (0 first; the stages of a solve coarse to fine, and refinement rounds,
    /// count on after the last load step): the index into
    /// [`super::SolverInfo::step_starts`].
    pub load_step: usize,
    /// The cells of the complex solved (fewer than the cells in a coarse stage).
    pub cells: usize,
    /// The energy after the iteration.
    pub energy: f64,
    /// What the iteration lowered the energy by, as a fraction of the energy before it (the
    /// energy test: [`super::SolveParams::tolerance`]).
    pub decrease: f64,
    /// The largest distance any corner of any cell moved in the iteration, in finest cell
    /// sizes (the move test: [`super::SolveParams::move_tolerance`]).
    pub largest_move: f64,
    /// The multiple of the Gauss-Newton step the line search took.
    pub step_length: f64,
    /// Conjugate-gradient iterations of the step (multilevel; 0 when factored).
    pub linear_iterations: usize,
    /// Seconds assembling the normal equations (pairs, targets, curvature, the matrix).
    pub seconds_assembly: f64,
    /// Seconds factoring them numerically, or building or refreshing the multilevel hierarchy.
    pub seconds_setup: f64,
    /// Seconds in the linear solve (triangular solves, or conjugate gradients).
    pub seconds_linear: f64,
    /// Seconds in the line search: trial motions, their positions' projection and energy.
    pub seconds_line_search: f64,
}

/// `iterations` solver iterations in words, by the kinds `log` holds: `34 local-global
/// iterations`, `32 local-global and 6 Gauss-Newton iterations`, `6 Gauss-Newton iterations`.
pub fn iterations_in_words(iterations: usize, log: &[IterationLog]) -> String {
    let local_global = log
        .iter()
        .filter(|l| {
            matches!(
                l.method,
                IterationMethod::LocalGlobal | IterationMethod::Anderson
            )
        })
        .count();
    match (local_global, log.len() - local_global) {
        (0, _) => format!("{iterations} Gauss-Newton iterations"),
        (n, 0) => format!("{n} local-global iterations"),
        (n, m) => format!("{n} local-global and {m} Gauss-Newton iterations"),
    }
}

/// The largest distance a corner of a cell moves from `from` to `to`.
pub(super) fn largest_corner_move<const D: usize>(
    complex: &CellComplex<D>,
    from: &[Motion<D>],
    to: &[Motion<D>],
) -> f64 {
    complex
        .cells
        .par_iter()
        .zip(from.par_iter().zip(to))
        .map(|(cell, (a, b))| {
            let h = cell.half;
            (0..1usize << D)
                .map(|bits| {
                    let corner = Vect::<D>::from_fn(|k, _| if bits >> k & 1 == 1 { h } else { -h });
                    let at = cell.center + corner;
                    (a.apply(&cell.center, &at) - b.apply(&cell.center, &at)).norm()
                })
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max)
}

impl std::fmt::Display for IterationLog {
    /// One line for the progress bar: the energy, both stopping figures and the time's parts.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: energy {:.4e} (-{:.1e}), largest move {:.1e} cells, step {}; assembly {:.0} ms, \
             setup {:.0} ms, solve {:.0} ms",
            self.method.name(),
            self.energy,
            self.decrease,
            self.largest_move,
            self.step_length,
            1e3 * self.seconds_assembly,
            1e3 * self.seconds_setup,
            1e3 * self.seconds_linear,
        )?;
        if self.linear_iterations > 0 {
            write!(f, " ({} CG)", self.linear_iterations)?;
        }
        write!(f, ", line search {:.0} ms", 1e3 * self.seconds_line_search)
    }
}

#[cfg(test)]
mod newton_tests {
    use super::*;

    fn log(method: IterationMethod, decrease: f64, largest_move: f64) -> IterationLog {
        IterationLog {
            method,
            decrease,
            largest_move,
            step_length: 1.0,
            ..Default::default()
        }
    }

    #[test]
    fn newton_stops_where_its_contraction_leaves_a_tail_within_the_tolerances() {
        let gn = log(IterationMethod::GaussNewton, 0.34, 0.12);
        let newton = log(IterationMethod::Newton, 6.7e-6, 3.4e-3);
        assert!(newton_converged(&gn, &newton, 1e-6, 1e-3));
        // A Gauss-Newton iteration, a slow contraction, a shortened step or another load step
        // goes on.
        let gauss = IterationLog {
            method: IterationMethod::GaussNewton,
            ..newton
        };
        assert!(!newton_converged(&gn, &gauss, 1e-6, 1e-3));
        let slow = log(IterationMethod::Newton, 0.2, 0.07);
        assert!(!newton_converged(&gn, &slow, 1e-6, 1e-3));
        let short = IterationLog {
            step_length: 0.5,
            ..newton
        };
        assert!(!newton_converged(&gn, &short, 1e-6, 1e-3));
        let other = IterationLog {
            load_step: 1,
            ..newton
        };
        assert!(!newton_converged(&gn, &other, 1e-6, 1e-3));
        // A tail over the move tolerance goes on.
        assert!(!newton_converged(&gn, &newton, 1e-6, 1e-5));
    }

    /// The plate's finest stage (BENCHMARKS.md §3): moves of 0.876 and 0.103 cells, so the next
    /// step is expected at 0.103 · 0.118 and needs solving only to 1e-4 / 0.0121 of itself.
    #[test]
    fn a_step_expected_small_is_solved_as_far_as_the_move_tolerance_needs() {
        let before = log(IterationMethod::Newton, 5e-3, 0.876);
        let now = log(IterationMethod::Newton, 2e-5, 0.103);
        let enough = enough_residual(Some(&before), &now, 1e-3);
        let expected = 0.103 * (0.103 / 0.876);
        assert!((enough - 1e-4 / expected).abs() < 1e-12, "{enough}");
        // Without the rate (a stage's first step, moves that do not contract by half, or
        // another load step before), the step is expected no longer than the last.
        assert!((enough_residual(None, &now, 1e-3) - 1e-4 / 0.103).abs() < 1e-15);
        let slow = log(IterationMethod::Newton, 0.2, 0.15);
        assert!((enough_residual(Some(&slow), &now, 1e-3) - 1e-4 / 0.103).abs() < 1e-15);
        let other = IterationLog {
            load_step: 1,
            ..before
        };
        assert!((enough_residual(Some(&other), &now, 1e-3) - 1e-4 / 0.103).abs() < 1e-15);
        // A step the line search shortened says nothing of the next one's length.
        let short = IterationLog {
            step_length: 0.5,
            ..now
        };
        assert_eq!(enough_residual(Some(&before), &short, 1e-3), 0.0);
        assert_eq!(
            enough_residual(None, &log(IterationMethod::Newton, 0.0, 0.0), 1e-3),
            0.0
        );
    }
}
