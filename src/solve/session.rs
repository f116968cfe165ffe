//! Warm solves on fixed cells: the session of a live deformation (the editor, Python's
//! `Session`, Blender's Live).
//!
//! A session's motions end as [`super::solve`]'s end: the parts no constraint reaches ride
//! along with the nearest constrained cell ([`carry_loose`]) where the parameters carry them,
//! so that its [`Session::motions`] and [`Session::solution`] are what `solve` gives for the
//! same constraints. The solver itself works on the motions before that step (the loose parts at
//! rest), as `solve`'s iterations do.

use std::time::Instant;

use super::coarse::{holders, prolong_held};
use super::loose::{carry_with, loose_anchors};
use super::system::System;
use super::turns::TurnGauge;
use super::{
    Constraints, Role, Solution, SolveParams, SolverInfo, cells_advice, coarsen_stage,
    from_rest_either_way, minimize_with, prescribe, targets_at, timed,
};
use crate::cells::{CellComplex, CellKind};
use crate::error::{Error, Result};
use crate::memory::Budget;
use crate::progress::Observer;
use crate::rigid::{Dim, Motion, Rigid};

/// An editing session on fixed cells: the paper's interactive case. The first solve runs from
/// rest with load steps, as [`super::solve`] does (without refinement); each
/// [`Session::update`] then starts from the current motions, without load steps, and reuses
/// the system (the local-global iterations' factored Laplacian, the Gauss-Newton system's
/// symbolic factorization) when only the handles, pins and targets moved. A handle dragged a little converges in a few iterations instead of a solve
/// from rest. Each solve ends as `solve` ends, its loose parts carried.
pub struct Session<const D: usize> {
    complex: CellComplex<D>,
    constraints: Constraints<D>,
    system: System<D>,
    motions: Vec<Motion<D>>,
    params: SolveParams,
    budget: Budget,
    /// The ancestors' stage that drags move on large complexes ([`Session::drag`]).
    drag: Option<DragStage<D>>,
    /// Whether `motions` are a drag stage's carried down (the next update on the cells starts
    /// from their free positions' optimum), and whether `system` was made for constraints of
    /// another structure than `constraints` (a drag changed them; the stage follows the
    /// constraints, the cells' system waits for the next update on the cells).
    dragged: bool,
    stale_system: bool,
    /// The constraints and motions as a solution holds them, where they differ from
    /// `constraints` and `motions`: the loose parts carried ([`carry_loose`]).
    carried: Option<(Constraints<D>, Vec<Motion<D>>)>,
    /// The roles the loose parts were last found for, and their anchors
    /// ([`super::constraints::loose_anchors`]): the same while the roles stay.
    anchors: Option<(Vec<Role>, Vec<[u32; 2]>)>,
    /// The inside's default soft scale the first solve gave up for a solid inside
    /// ([`SolverInfo::inside_stiffened`]): the constraints of every later pose are stiffened
    /// the same way, so that a pose solves as a whole run of it does.
    stiffened: Option<(super::TurnRefusal, f64)>,
    /// While the inside is the default soft one: the motions of the last converged pose whose
    /// turns the cells held (under constraints of the present structure), where a pose that
    /// loses its turn starts again with the inside stiffened (the steps between may have begun
    /// to give way before one converged).
    held: Option<Vec<Motion<D>>>,
}

/// Local-global iterations a drag's step takes for each Gauss-Newton iteration it is given
/// (`pipeline::live::DRAG_ITERATIONS`, one): on 5k cells 2–5 ms each, against 30–90 ms for the
/// factorization of one Gauss-Newton step. Their matrix is factored once per session (per
/// structure of the constraints); a pose changes only the right-hand sides. Two a pose keep
/// Blender's Live at its timer's rate on 5k cells; four halved the editor's updates a second,
/// with a release sooner (BENCHMARKS.md).
pub const DRAG_LOCAL_GLOBAL: usize = 2;

/// Local-global iterations of an idle refinement's step ([`Session::refine`]). A face refines
/// once its handle rests, and a pose that comes meanwhile waits for the step; each step's
/// Anderson history restarts (at two a step the bar of the tests needed more than 50 steps to
/// converge; the release after a drag in Live took about 1 s at four, 0.8 s at eight, 3 s at
/// two).
pub const IDLE_LOCAL_GLOBAL: usize = 4;

/// From this many cells on, a drag moves the cells' ancestors (at most 6,000 where three levels
/// of coarsening reach that) and the cells follow them rigidly; the cells themselves are solved
/// when the drag pauses or ends. A drag's two local-global iterations cost about 2.5 ms per
/// thousand cells on two cores: on the 15k cells of a bust 34–41 ms, 15.6 shapes a second in
/// Blender's Live, against 37–38 on their ancestors, with the same release (BENCHMARKS.md §11).
pub const DRAG_COARSE_FROM: usize = 10_000;

/// A drag also moves the cells' ancestors when the cells' Cholesky factor has more nonzeros
/// than this, whatever their count: a numeric factorization costs about what its factor
/// holds. On two cores, a step on 5k cells of a terrain (autzen_trim, 2.5M nonzeros) takes
/// 95–180 ms; on 5k cells of a solid (the Stanford bunny and dragons, 5.3–5.5M) 160–350 ms,
/// and on their parents a few tens of milliseconds.
pub const DRAG_FACTOR_MOST: usize = 3_000_000;

/// A drag's stage has at most this many cells where coarsening gets there in
/// [`DRAG_MOST_LEVELS`] levels. On autzen_trim at 50k cells the parents are 17.4k (an update
/// 260–300 ms) and the grandparents 5.4k (55–110 ms after the first, most of it the
/// factorization).
const DRAG_STAGE_CELLS: usize = 6_000;
const DRAG_MOST_LEVELS: u8 = 3;

/// The ancestors a drag moves: the parents, or older ones while the stage has more than
/// [`DRAG_STAGE_CELLS`] and a level still merges cells.
fn drag_parents<const D: usize>(
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
) -> (CellComplex<D>, Constraints<D>)
where
    Dim<D>: Rigid<D>,
{
    let mut stage = coarsen_stage(complex, constraints, 1);
    for k in 2..=DRAG_MOST_LEVELS {
        if stage.0.len() <= DRAG_STAGE_CELLS {
            break;
        }
        let older = coarsen_stage(complex, constraints, k);
        if 4 * older.0.len() > 3 * stage.0.len() {
            break;
        }
        stage = older;
    }
    stage
}

/// The coarse complex a drag solves, with its constraints, system and motions.
struct DragStage<const D: usize> {
    complex: CellComplex<D>,
    constraints: Constraints<D>,
    system: System<D>,
    motions: Vec<Motion<D>>,
    /// For each of the session's cells, the stage's cell that holds it.
    holders: Vec<Option<u32>>,
}

impl<const D: usize> DragStage<D> {
    /// Moves the stage's handles, pins and targets to those of `constraints`, the session's
    /// cells' constraints of the same structure.
    fn follow(&mut self, constraints: &Constraints<D>) {
        let on_parents = &mut self.constraints;
        on_parents.handles = constraints.handles.clone();
        for (p, q) in on_parents.pins.iter_mut().zip(&constraints.pins) {
            p.to = q.to;
        }
        for (t, u) in on_parents.targets.iter_mut().zip(&constraints.targets) {
            t.to = u.to;
        }
    }
}

impl<const D: usize> Session<D>
where
    Dim<D>: Rigid<D>,
{
    /// Solves `constraints` on `complex` from rest (`params.refine_strain` is not used: a
    /// session's cells stay those of `complex`).
    pub fn new(
        complex: CellComplex<D>,
        mut constraints: Constraints<D>,
        params: &SolveParams,
        budget: Budget,
        observer: &dyn Observer,
    ) -> Result<(Self, SolverInfo)> {
        let start = Instant::now();
        let (system, motions, mut info) =
            from_rest_either_way(&complex, &mut constraints, params, budget, observer, &[])?;
        observer.finish();
        info.turns = TurnGauge::new(&complex).turns(&complex, &constraints, &motions);
        let soft = info.inside_stiffened.is_none()
            && complex.cells.iter().any(|c| c.kind == CellKind::Interior);
        let mut session = Self {
            complex,
            constraints,
            system,
            motions,
            params: SolveParams {
                // No inside to stiffen, or stiffened already: no pose looks for a lost turn.
                soft_inside: params.soft_inside.filter(|_| soft),
                ..*params
            },
            budget,
            drag: None,
            dragged: false,
            stale_system: false,
            carried: None,
            anchors: None,
            stiffened: info.inside_stiffened,
            held: None,
        };
        if session.params.soft_inside.is_some() && session.stiffened.is_none() {
            session.held = Some(session.motions.clone());
        }
        let info = session.finished(info, start);
        Ok((session, info))
    }

    /// Moves to `constraints` — the same edit with its handles, pins or targets moved, resolved
    /// on the cells the session holds — starting from the current motions. The symbolic
    /// factorization is kept unless the cells' roles, stiffness or targets' cells and weights
    /// changed.
    pub fn update(&mut self, constraints: Constraints<D>) -> Result<SolverInfo> {
        self.update_with(constraints, self.params.max_iterations)
    }

    /// [`Session::update`] with at most `max_iterations` Gauss-Newton iterations (or
    /// [`DRAG_LOCAL_GLOBAL`] local-global ones for each): a drag takes one per pose and goes on
    /// from there with the next (the info says whether it converged).
    pub fn update_with(
        &mut self,
        constraints: Constraints<D>,
        max_iterations: usize,
    ) -> Result<SolverInfo> {
        let constraints = self.as_first_solved(constraints);
        self.update_steps(constraints, (max_iterations, DRAG_LOCAL_GLOBAL), false)
    }

    /// One step more on the current constraints while nothing moves (an idle face's
    /// refinement): one Newton iteration (its curvature from the first, as in
    /// [`Session::converge`]), or [`IDLE_LOCAL_GLOBAL`] local-global ones.
    pub fn refine(&mut self) -> Result<SolverInfo> {
        let constraints = self.constraints.clone();
        self.update_steps(constraints, (1, IDLE_LOCAL_GLOBAL), true)
    }

    /// The current constraints solved to convergence from the current motions (a release, or
    /// a pose converged before a drag goes on): as [`Session::update`] with the same
    /// constraints, its Gauss-Newton iterations Newton's from the first, as the motions are
    /// near the minimum already (the last load step of [`super::solve`] ends on Newton's).
    pub fn converge(&mut self) -> Result<SolverInfo> {
        let constraints = self.constraints.clone();
        let steps = (self.params.max_iterations, DRAG_LOCAL_GLOBAL);
        self.update_steps(constraints, steps, true)
    }

    /// [`Session::update_with`], a step short of the solver's limit taking `per_step`
    /// local-global iterations for each of `max_iterations`, on `constraints` as the session
    /// solves them ([`Session::as_first_solved`]); `in_place` where they are the session's
    /// own, the motions near their minimum (Newton's iterations from the first).
    fn update_steps(
        &mut self,
        constraints: Constraints<D>,
        (max_iterations, per_step): (usize, usize),
        in_place: bool,
    ) -> Result<SolverInfo> {
        if constraints.roles.len() != self.complex.len() {
            return Err(Error::solver(format!(
                "the constraints are for {} cells, the session has {}",
                constraints.roles.len(),
                self.complex.len()
            )));
        }
        let (start, mut info) = (Instant::now(), self.warm_info());
        let same_structure = !self.stale_system && same_structure(&constraints, &self.constraints);
        if !same_structure {
            self.drag = None;
            self.stale_system = false;
            self.system = self.system_for(&self.complex, &constraints, &mut info)?;
            // Motions held under other roles, stiffness or targets are no start for these.
            self.held = None;
        }
        self.constraints = constraints;
        // A whole solve after a drag on the ancestors starts coarse to fine: the ancestors
        // converged first (a few thousand cells), their motions carried down, so that the
        // cells' own iterations start where only their finer detail is left.
        let whole = max_iterations >= self.params.max_iterations;
        if let Some(stage) = self.drag.as_mut().filter(|_| self.dragged && whole) {
            stage.follow(&self.constraints);
            let cells = (
                &mut stage.system,
                &stage.complex,
                &stage.constraints,
                &mut stage.motions[..],
            );
            warm_steps(cells, &self.params, (max_iterations, per_step), &mut info)?;
            self.motions = prolong_held(
                &stage.complex,
                &stage.motions,
                &self.complex,
                &stage.holders,
            );
        }
        // Motions carried down from a drag's ancestors are not near the cells' minimum.
        let in_place = in_place && !self.dragged;
        if self.dragged {
            prescribe(&self.complex, &self.constraints, &mut self.motions, 1.0);
            let targets = targets_at(&self.constraints, 1.0);
            let (complex, constraints) = (&self.complex, &self.constraints);
            self.system
                .project_positions(complex, constraints, &mut self.motions, &targets)?;
            self.dragged = false;
        }
        let soft = self.params.soft_inside.is_some() && self.stiffened.is_none();
        let before = (soft && self.held.is_none()).then(|| self.motions.clone());
        self.warm((max_iterations, per_step), in_place, &mut info)?;
        if soft {
            if self.stiffen_where_given_way(&mut info)? {
                // The pose again from the last one the cells held (or, held none under these
                // constraints, from where it started), with the solid inside.
                if let Some(start) = self.held.take().or(before) {
                    self.motions = start;
                }
                self.warm((max_iterations, per_step), false, &mut info)?;
            } else if info.converged {
                self.held = Some(self.motions.clone());
            }
        }
        Ok(self.finished(info, start))
    }

    /// [`warm_steps`] on the session's cells from its motions (`in_place`: near their
    /// minimum, [`SolveParams::newton_at_start`]).
    fn warm(&mut self, steps: (usize, usize), in_place: bool, info: &mut SolverInfo) -> Result<()> {
        let cells = (
            &mut self.system,
            &self.complex,
            &self.constraints,
            &mut self.motions[..],
        );
        let params = SolveParams {
            newton_at_start: in_place,
            ..self.params
        };
        warm_steps(cells, &params, steps, info)
    }

    /// Where the session's inside is still the default soft one and a converged pose has lost a
    /// handle's turn (the cells carry it more than a quarter turn off, as a load step that left
    /// its branch does), stiffens the inside to a solid's as a whole run does
    /// ([`super::SolveParams::soft_inside`]), for this pose and every later one: whether it
    /// did.
    fn stiffen_where_given_way(&mut self, info: &mut SolverInfo) -> Result<bool> {
        // A pose not yet converged may only lag the handle (a drag takes one iteration a pose).
        let (Some(scale), None, true) = (self.params.soft_inside, self.stiffened, info.converged)
        else {
            return Ok(false);
        };
        let gauge = TurnGauge::new(&self.complex);
        let lost = super::turns::lost_turn(&gauge, &self.constraints, &self.motions, 1.0);
        let Some(k) = lost else {
            return Ok(false);
        };
        let refusal = super::TurnRefusal::new(&self.complex, &self.constraints, k, 1.0);
        self.stiffened = Some((refusal, scale));
        self.constraints.scale_interior(&self.complex, 1.0 / scale);
        self.drag = None;
        self.system = self.system_for(&self.complex, &self.constraints, info)?;
        info.inside_stiffened = self.stiffened;
        Ok(true)
    }

    /// `constraints` with the inside as stiff as the first solve left it.
    fn as_first_solved(&self, mut constraints: Constraints<D>) -> Constraints<D> {
        // The session's own constraints, given back (as the live faces do), are stiffened.
        if let Some((_, scale)) = self.stiffened
            && constraints.roles.len() == self.complex.len()
            && constraints.stiffness != self.constraints.stiffness
        {
            constraints.scale_interior(&self.complex, 1.0 / scale);
        }
        constraints
    }

    /// One step of a drag toward `constraints` (at most `max_iterations` Gauss-Newton
    /// iterations, or [`DRAG_LOCAL_GLOBAL`] local-global ones for each). From
    /// [`DRAG_COARSE_FROM`] cells on, or with a Gauss-Newton factor of more than
    /// [`DRAG_FACTOR_MOST`] nonzeros (a session taking local-global iterations has none), the
    /// step is taken on the cells' ancestors (`coarsen` by
    /// as many levels as bring them to a few thousand, made once for the drag's constraints
    /// and kept while only their handles, pins and targets move), and
    /// each cell then takes its ancestor's rigid motion, as a solve coarse to fine starts its
    /// cells: the step costs what those few thousand cells cost
    /// ([`Session::drag_on_parents`]). Smaller complexes take [`Session::update_with`] itself.
    pub fn drag(
        &mut self,
        constraints: Constraints<D>,
        max_iterations: usize,
    ) -> Result<SolverInfo> {
        let dense = self
            .system
            .factor_len()
            .is_some_and(|n| n > DRAG_FACTOR_MOST);
        if self.complex.len() < DRAG_COARSE_FROM && !dense {
            return self.update_with(constraints, max_iterations);
        }
        self.drag_on_parents(constraints, max_iterations)
    }

    /// [`Session::drag`]'s step on the cells' ancestors, whatever the count of cells: the info
    /// says it has not converged, and the next [`Session::update_with`] solves the cells
    /// themselves from there. Constraints for other cells, and complexes that coarsening
    /// hardly merges, take [`Session::update_with`].
    pub fn drag_on_parents(
        &mut self,
        constraints: Constraints<D>,
        max_iterations: usize,
    ) -> Result<SolverInfo> {
        if constraints.roles.len() != self.complex.len() {
            return self.update_with(constraints, max_iterations);
        }
        let constraints = self.as_first_solved(constraints);
        let (start, mut info) = (Instant::now(), self.warm_info());
        // The stage was made for the last constraints' structure (an update that changed it
        // dropped the stage).
        let same = same_structure(&constraints, &self.constraints);
        let mut stage = match self.drag.take() {
            Some(mut stage) if same => {
                stage.follow(&constraints);
                stage
            }
            _ => {
                let (complex, on_parents) = drag_parents(&self.complex, &constraints);
                if 3 * complex.len() > 2 * self.complex.len() {
                    let steps = (max_iterations, DRAG_LOCAL_GLOBAL);
                    return self.update_steps(constraints, steps, false);
                }
                let system = self.system_for(&complex, &on_parents, &mut info)?;
                let holders = holders(&complex, &self.complex);
                let motions = restrict(&self.complex, &self.motions, &complex, &holders);
                DragStage {
                    complex,
                    constraints: on_parents,
                    system,
                    motions,
                    holders,
                }
            }
        };
        let cells = (
            &mut stage.system,
            &stage.complex,
            &stage.constraints,
            &mut stage.motions[..],
        );
        let steps = (max_iterations, DRAG_LOCAL_GLOBAL);
        warm_steps(cells, &self.params, steps, &mut info)?;
        info.converged = false;
        self.motions = prolong_held(
            &stage.complex,
            &stage.motions,
            &self.complex,
            &stage.holders,
        );
        prescribe(&self.complex, &constraints, &mut self.motions, 1.0);
        self.stale_system |= !same;
        self.constraints = constraints;
        self.dragged = true;
        self.drag = Some(stage);
        Ok(self.finished(info, start))
    }

    /// The info a warm solve starts with: one load step on the session's cells.
    fn warm_info(&self) -> SolverInfo {
        SolverInfo {
            cells_initial: self.complex.len(),
            load_steps: 1,
            inside_stiffened: self.stiffened,
            ..Default::default()
        }
    }

    /// The system of `constraints` on `complex` under the session's method and budget, its
    /// time counted as the info's symbolic analysis.
    fn system_for(
        &self,
        complex: &CellComplex<D>,
        constraints: &Constraints<D>,
        info: &mut SolverInfo,
    ) -> Result<System<D>> {
        timed(&mut info.seconds_symbolic, || {
            System::new(
                complex,
                constraints,
                &self.params,
                self.budget,
                &cells_advice(),
            )
        })
    }

    /// The end of a solve: the loose parts carried as [`super::solve`] carries them, and the
    /// info's counts and seconds.
    fn finished(&mut self, mut info: SolverInfo, start: Instant) -> SolverInfo {
        let roles = &self.constraints.roles;
        self.carried = None;
        if self.params.carry_loose && roles.contains(&Role::Rest) {
            if self.anchors.as_ref().is_none_or(|(r, _)| r != roles) {
                let anchors = loose_anchors(&self.complex, roles);
                self.anchors = Some((roles.clone(), anchors));
            }
            let (mut constraints, mut motions) = (self.constraints.clone(), self.motions.clone());
            let anchors = self.anchors.as_ref().map_or(&[][..], |(_, a)| a);
            carry_with(&self.complex, &mut constraints, &mut motions, anchors);
            self.carried = Some((constraints, motions));
        }
        info.cells_final = self.complex.len();
        info.unknowns = self.system.unknowns();
        info.seconds = start.elapsed().as_secs_f64();
        info
    }

    /// The cells.
    pub fn complex(&self) -> &CellComplex<D> {
        &self.complex
    }

    /// The constraints of the last solve, as the solver takes them (loose parts at rest): what
    /// the next [`Session::update`] starts from.
    pub fn constraints(&self) -> &Constraints<D> {
        &self.constraints
    }

    /// The constraints as [`Session::solution`] holds them: the last solve's, with the cells
    /// of loose parts [`Role::Carried`] and the warning saying so where the parameters carry
    /// them.
    pub fn solution_constraints(&self) -> &Constraints<D> {
        self.carried.as_ref().map_or(&self.constraints, |(c, _)| c)
    }

    /// The current motions, one per cell (local frame), the loose parts carried as
    /// [`Session::solution`] carries them.
    pub fn motions(&self) -> &[Motion<D>] {
        self.carried.as_ref().map_or(&self.motions, |(_, m)| m)
    }

    /// The turn the cells carry from the fixed cells to each turning handle, as they are now
    /// (what a solve from rest reports in its info).
    pub fn turns(&self) -> Vec<super::HandleTurn> {
        TurnGauge::new(&self.complex).turns(&self.complex, &self.constraints, &self.motions)
    }

    /// The session's state as a [`Solution`] with `info`: what [`super::solve`] gives for these
    /// motions, the loose parts carried where the parameters carry them.
    pub fn solution(&self, info: SolverInfo) -> Solution<D> {
        Solution {
            complex: self.complex.clone(),
            motions: self.motions().to_vec(),
            constraints: self.solution_constraints().clone(),
            info,
        }
    }
}

/// At most `max_iterations` Gauss-Newton iterations of `params` at full load, from the motions
/// as they are, into `info`. A step short of the solver's limit (a drag's, or an idle
/// refinement's) takes `per_step` local-global iterations for each where the system takes
/// those.
#[allow(clippy::type_complexity)]
fn warm_steps<const D: usize>(
    (system, complex, constraints, motions): (
        &mut System<D>,
        &CellComplex<D>,
        &Constraints<D>,
        &mut [Motion<D>],
    ),
    params: &SolveParams,
    (max_iterations, per_step): (usize, usize),
    info: &mut SolverInfo,
) -> Result<()>
where
    Dim<D>: Rigid<D>,
{
    let short = max_iterations < params.max_iterations;
    let params = SolveParams {
        max_iterations,
        local_global_per_iteration: match short {
            true => per_step,
            false => params.local_global_per_iteration,
        },
        ..*params
    };
    let silent = &crate::progress::Silent;
    let it = minimize_with(
        system,
        complex,
        constraints,
        motions,
        1.0,
        &params,
        info,
        silent,
    )?;
    info.iterations_per_step.push(it);
    Ok(())
}

/// Whether `a` and `b` give systems of one structure: the same roles, stiffness, and targets'
/// cells, weights and masks (handles, pins and targets may have moved).
fn same_structure<const D: usize>(a: &Constraints<D>, b: &Constraints<D>) -> bool {
    a.roles == b.roles
        && a.stiffness == b.stiffness
        && a.targets.len() == b.targets.len()
        && a.targets
            .iter()
            .zip(&b.targets)
            .all(|(s, t)| s.cell == t.cell && s.weight == t.weight && s.mask == t.mask)
}

/// The motions of `coarse`'s cells, a coarsening of `fine`, from those of `fine`'s: each coarse
/// cell takes the rigid motion of the first fine cell it holds (`holders`, by fine cell).
fn restrict<const D: usize>(
    fine: &CellComplex<D>,
    motions: &[Motion<D>],
    coarse: &CellComplex<D>,
    holders: &[Option<u32>],
) -> Vec<Motion<D>>
where
    Dim<D>: Rigid<D>,
{
    let mut out: Vec<Option<Motion<D>>> = vec![None; coarse.len()];
    for ((cell, m), held) in fine.cells.iter().zip(motions).zip(holders) {
        if let Some(c) = held.map(|c| c as usize)
            && out[c].is_none()
        {
            out[c] = Some(Motion {
                rot: m.rot,
                pos: m.apply(&cell.center, &coarse.cells[c].center),
            });
        }
    }
    out.into_iter()
        .zip(&coarse.cells)
        .map(|(m, cell)| m.unwrap_or_else(|| Motion::rest(&cell.center)))
        .collect()
}
