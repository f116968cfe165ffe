//! Live deformation of samples in memory: the paper's interactive setting, for every face that
//! drags a handle (the browser editor, the Python package's `Session`, Blender's Live).
//!
//! [`Live`] builds the cells once. Each [`Live::solve`] takes the whole edit spec: when only
//! the handles' poses and the pins' destinations changed since the last one, the session goes
//! on warm from its current motions for a few iterations ([`Session::drag`], a short step per
//! pose while dragging); otherwise the spec is resolved again and solved from rest. Like a
//! solve's load steps, a warm pose goes at most a load step past the pose the session last
//! converged on (the last pose is converged first): a hand faster than the solver would
//! otherwise leave the cells half a turn behind a twist, and they would untwist.
//! [`Live::preview`] blends the cells' current motions at the samples (cheap, for every pose);
//! [`Live::release`] converges and runs the chosen transfer with its exact constraints, as
//! [`super::deform`] does.
//!
//! A spec solved from rest and released without a drag gives `deform`'s points bit for bit:
//! the cells are built, the spec resolved (with the samples' LAS classes), solved from rest
//! and its loose parts carried as `deform` does each, and the release runs `deform`'s transfer.

use std::time::Instant;

use rayon::prelude::*;

use super::DeformParams;
use super::stages::{self, Selected};
use crate::cells::{BuildInfo, CellComplex};
use crate::error::Error;
use crate::error::Result;
use crate::field::{Blend, Field, Prescribed, Weights};
use crate::progress::{Observer, Silent};
use crate::rigid::{Dim, Motion, Rigid, Vect};
use crate::said::{Opt, Said};
use crate::solve::{Session, Solution, SolverInfo};
use crate::spec::HandleMotion;
use crate::spec::{EditSpec, Target, Trend};

use super::DeformInfo;

/// Gauss-Newton iterations per pose while dragging: one (or, where the session's system takes
/// local-global iterations, [`crate::solve::DRAG_LOCAL_GLOBAL`] of those), so that the shape
/// follows the hand; the next pose goes on from there, the idle solver converges the last one
/// ([`Live::refine`]), and a release converges before the final transfer. (One Gauss-Newton
/// iteration is about 40 ms for 5,000 cells on two cores; three an update, to convergence,
/// gave 7 updates a second.)
pub const DRAG_ITERATIONS: usize = 1;

/// Per sample, its four nearest cells and their blend weights ([`Live::blend_weights`]).
pub type BlendWeights = (Vec<[u32; 4]>, Vec<[f32; 4]>);

/// A live deformation: the samples, their cells, and the warm session of the last spec.
pub struct Live {
    points: Vec<Vect<3>>,
    classes: Vec<u8>,
    complex: CellComplex<3>,
    /// How the cells were built (for the build's warnings).
    build: BuildInfo,
    params: DeformParams,
    /// The last spec solved, and its session.
    spec: Option<EditSpec<3>>,
    session: Option<Session<3>>,
    /// The last solve's report, and the warnings of the session's solve from rest.
    info: SolverInfo,
    warnings: Vec<Said>,
    /// Whether the motions moved warm (a drag's step, a refinement) since the solve from rest.
    warm: bool,
    /// Pairs of handles whose motions were equal when the spec was resolved.
    tied: Vec<(usize, usize)>,
    /// Each handle's selection centroid where the spec it was resolved from gave no pivot.
    centroids: Vec<Option<Vect<3>>>,
    /// The handles' poses the session last converged on (see [`Live::solve`]).
    settled: Vec<HandleMotion<3>>,
    /// Each sample's four nearest cells and blend weights, made at the first preview.
    blend: Option<BlendWeights>,
}

/// What one [`Live::solve`] or [`Live::refine`] did.
#[derive(Debug, Clone, Default)]
pub struct Step {
    /// The solver: its iterations, and whether it converged.
    pub solver: SolverInfo,
    /// Whether the spec was solved from rest (its regions changed, or it was the first).
    pub from_rest: bool,
    /// The warnings of a solve from rest: the build's, the constraints', the solver's.
    pub warnings: Vec<Said>,
    /// Seconds of the step.
    pub seconds: f64,
}

impl Live {
    /// Builds the cells of `points` (with `triangles` over them, and their LAS `classes` or
    /// none) as [`super::deform`] builds them. Parameters that refine the cells are refused:
    /// a session's cells stay those it built.
    pub fn new(
        points: Vec<Vect<3>>,
        triangles: &[[u32; 3]],
        classes: Vec<u8>,
        params: DeformParams,
    ) -> Result<Self> {
        let refining = [
            (params.solve.refine_strain.is_some(), Opt::RefineStrain),
            (params.solve.refine_fraction.is_some(), Opt::MinCellSize),
        ];
        if let Some((_, option)) = refining.iter().find(|(given, _)| *given) {
            return Err(Error::param(
                Said::new()
                    .opt(*option)
                    .text(
                        " refines the cells where they strain; a live deformation keeps the \
                         cells it built: give ",
                    )
                    .opt(Opt::CellSize)
                    .text(" or ")
                    .opt(Opt::Cells)
                    .text(" (deform refines)"),
            ));
        }
        super::classes_of(points.len(), &classes)?;
        let check = |forecast: &crate::cells::Forecast| params.check_forecast(forecast);
        let (complex, build) =
            crate::cells::build_checked(&points, triangles, &params.build, params.memory, &check)?;
        Ok(Self {
            points,
            classes,
            complex,
            build,
            params,
            spec: None,
            session: None,
            info: SolverInfo::default(),
            warnings: Vec::new(),
            warm: false,
            tied: Vec::new(),
            centroids: Vec::new(),
            settled: Vec::new(),
            blend: None,
        })
    }

    /// The samples at rest.
    pub fn points(&self) -> &[Vect<3>] {
        &self.points
    }

    /// The cells.
    pub fn complex(&self) -> &CellComplex<3> {
        &self.complex
    }

    /// The parameters.
    pub fn params(&self) -> &DeformParams {
        &self.params
    }

    /// The last spec solved.
    pub fn spec(&self) -> Option<&EditSpec<3>> {
        self.spec.as_ref()
    }

    /// The warnings of the last solve from rest: the build's, the constraints', the
    /// solver's (a [`Live::release`]'s info holds them, then its fold-overs).
    pub fn warnings(&self) -> &[Said] {
        &self.warnings
    }

    /// The cells' current motions (`None` before a spec constrains anything).
    pub fn motions(&self) -> Option<&[Motion<3>]> {
        self.session.as_ref().map(|s| s.motions())
    }

    /// Moves to `spec` with at most `max_iterations` Gauss-Newton iterations: warm from the
    /// current motions when only its handles' poses and pins' destinations differ from the
    /// last spec's (a drag's step below the solver's iteration limit, else the whole solve),
    /// else resolved and solved from rest (to convergence, with load steps). A failed warm
    /// step ends the session: the next spec is solved from rest. `None` when the spec constrains
    /// nothing (the samples stay at rest). `observer` hears a solve from rest.
    pub fn solve(
        &mut self,
        spec: EditSpec<3>,
        max_iterations: usize,
        observer: &dyn Observer,
    ) -> Result<Option<Step>> {
        if !spec.has_constraints() {
            self.spec = None;
            self.session = None;
            return Ok(None);
        }
        let start = Instant::now();
        // Handles that shared a motion when the last spec was resolved may share cells, which
        // they may only while their motions stay equal: once they differ, it is resolved again.
        // The pairs index the last spec's handles: asked only of a spec with the same handles.
        let tied = &self.tied;
        let still_tied = |spec: &EditSpec<3>| {
            tied.iter()
                .all(|&(i, j)| spec.handles[i].value == spec.handles[j].value)
        };
        // A pose without a pivot turns about its selection's centroid, known where the spec
        // it was resolved from gave none (a matrix needs no pivot at full load).
        let pivots: Option<Vec<Option<Vect<3>>>> = spec
            .handles
            .iter()
            .zip(self.centroids.iter().chain(std::iter::repeat(&None)))
            .map(
                |(entry, centroid)| match (entry.value.pivot, entry.value.from_matrix) {
                    (Some(p), _) => Some(Some(p)),
                    (None, true) => Some(None),
                    (None, false) => centroid.map(Some),
                },
            )
            .collect();
        let step = self.params.solve.max_step_degrees;
        let poses: Vec<HandleMotion<3>> = spec.handles.iter().map(|h| h.value).collect();
        let warm = match (&mut self.session, &self.spec, pivots) {
            (Some(session), Some(last), Some(pivots))
                if same_but_poses(last, &spec) && still_tied(&spec) =>
            {
                // A warm step goes at most a load step from the poses the session last
                // converged on, as a solve's load steps go from the last step's: a drag that
                // outruns its cells (a handle turned on a step a pose while the cells take two
                // iterations of it) would otherwise leave them behind by a half turn and more,
                // and converge the short way round. Past a step, the last pose (within a step)
                // is converged first; a pose past a step even from there is solved from rest.
                let last_poses: Vec<HandleMotion<3>> =
                    last.handles.iter().map(|h| h.value).collect();
                let mut converged_first = None;
                if turns_past_a_step(&self.settled, &poses, step)
                    && !self.info.converged
                    && !turns_past_a_step(&last_poses, &poses, step)
                {
                    let solver = match session.converge() {
                        Ok(solver) => solver,
                        Err(e) => {
                            self.session = None;
                            self.spec = None;
                            return Err(e);
                        }
                    };
                    if solver.converged {
                        self.settled = last_poses;
                    }
                    converged_first = Some(solver);
                }
                if turns_past_a_step(&self.settled, &poses, step) {
                    None
                } else {
                    let mut constraints = session.constraints().clone();
                    for ((handle, entry), pivot) in constraints
                        .handles
                        .iter_mut()
                        .zip(&spec.handles)
                        .zip(pivots)
                    {
                        handle.motion = entry.value;
                        if let Some(p) = pivot {
                            handle.pivot = p;
                        }
                    }
                    let origin = self.complex.grid.origin;
                    for (pin, entry) in constraints.pins.iter_mut().zip(&spec.pins) {
                        pin.wanted = entry.to - origin;
                        pin.to = constraints.trend.back(&pin.wanted).unwrap_or(pin.wanted);
                    }
                    for (target, entry) in constraints.targets.iter_mut().zip(&spec.targets) {
                        let mut to = entry.to - origin;
                        if entry.horizontal {
                            // Its height is the snapped sample's, as it was resolved.
                            to[2] = target.wanted[2];
                        }
                        target.wanted = to;
                        target.to = constraints.trend.back(&to).unwrap_or(to);
                    }
                    // A drag's step (which may move the cells' ancestors), or the whole solve.
                    let stepped = if max_iterations < self.params.solve.max_iterations {
                        session.drag(constraints, max_iterations)
                    } else {
                        session.update(constraints)
                    };
                    match stepped {
                        Ok(mut solver) => {
                            // The step's report counts the converge before it too.
                            if let Some(first) = converged_first {
                                solver.iterations += first.iterations;
                            }
                            Some(solver)
                        }
                        Err(e) => {
                            // The session may hold constraints it did not solve: the next spec
                            // starts from rest.
                            self.session = None;
                            self.spec = None;
                            return Err(e);
                        }
                    }
                }
            }
            _ => None,
        };
        let step = match warm {
            Some(solver) => Step {
                solver,
                ..Default::default()
            },
            None => {
                let classes = (!self.classes.is_empty()).then_some(&self.classes[..]);
                let selected = Selected::Samples {
                    points: &self.points,
                    classes,
                };
                let constraints =
                    stages::constraints(&self.complex, &spec, selected, &self.params)?;
                let (session, solver) = Session::new(
                    self.complex.clone(),
                    constraints,
                    &self.params.solve,
                    self.params.memory,
                    observer,
                )?;
                let mut warnings = stages::warnings(
                    &self.build,
                    &self.complex,
                    session.solution_constraints(),
                    &solver,
                    &self.params,
                );
                warnings.extend(crate::cells::shortfall(
                    self.params.build.target_cells,
                    self.complex.len(),
                ));
                self.warnings = warnings.clone();
                self.session = Some(session);
                self.centroids = spec
                    .handles
                    .iter()
                    .zip(&self.session.as_ref().expect("set").constraints().handles)
                    .map(|(entry, handle)| entry.value.pivot.is_none().then_some(handle.pivot))
                    .collect();
                let n = spec.handles.len();
                self.tied = (0..n)
                    .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
                    .filter(|&(i, j)| spec.handles[i].value == spec.handles[j].value)
                    .collect();
                Step {
                    solver,
                    from_rest: true,
                    warnings,
                    ..Default::default()
                }
            }
        };
        if step.from_rest || step.solver.converged {
            self.settled = poses;
        }
        self.spec = Some(spec);
        self.info = step.solver.clone();
        self.warm = !step.from_rest;
        Ok(Some(Step {
            seconds: start.elapsed().as_secs_f64(),
            ..step
        }))
    }

    /// [`Live::solve`] of the last spec with its handles in `poses` (one per handle, in the
    /// spec's order), its pins going to `pins` (one per pin, or none to leave them) and its
    /// soft targets pulling towards `targets` (one per target, or none): the warm step of a
    /// drag, without writing or reading the regions again.
    pub fn pose(
        &mut self,
        poses: &[HandleMotion<3>],
        pins: &[Vect<3>],
        targets: &[Vect<3>],
        max_iterations: usize,
    ) -> Result<Step> {
        let Some(last) = &self.spec else {
            return Err(Error::param(
                "no spec to pose: give the spec with its regions first",
            ));
        };
        if poses.len() != last.handles.len() {
            return Err(Error::param(format!(
                "{} poses for the spec's {} handles: give one a handle",
                poses.len(),
                last.handles.len()
            )));
        }
        for (given, wanted, what) in [
            (pins.len(), last.pins.len(), "pin"),
            (targets.len(), last.targets.len(), "target"),
        ] {
            if given != 0 && given != wanted {
                return Err(Error::param(format!(
                    "{given} {what}s for the spec's {wanted}: give one a {what}, or none"
                )));
            }
        }
        let mut spec = last.clone();
        for (entry, pose) in spec.handles.iter_mut().zip(poses) {
            entry.value = *pose;
        }
        for (pin, to) in spec.pins.iter_mut().zip(pins) {
            pin.to = *to;
        }
        for (target, to) in spec.targets.iter_mut().zip(targets) {
            target.to = *to;
        }
        Ok(self
            .solve(spec, max_iterations, &Silent)?
            .expect("a spec with handles constrains"))
    }

    /// Whether the last solve converged (a drag's step may stop short); true with nothing to
    /// solve.
    pub fn converged(&self) -> bool {
        self.session.is_none() || self.info.converged
    }

    /// One more iteration on the last spec when its solve stopped short of converging (a face
    /// runs it while no new pose waits); `None` when there is nothing to do.
    pub fn refine(&mut self) -> Result<Option<Step>> {
        if self.converged() {
            return Ok(None);
        }
        let start = Instant::now();
        let Some(session) = self.session.as_mut() else {
            return Ok(None);
        };
        let solver = session.refine()?;
        if let (true, Some(spec)) = (solver.converged, &self.spec) {
            self.settled = spec.handles.iter().map(|h| h.value).collect();
        }
        self.info = solver.clone();
        self.warm = true;
        Ok(Some(Step {
            solver,
            seconds: start.elapsed().as_secs_f64(),
            ..Default::default()
        }))
    }

    /// Each sample's four nearest cells and their continuous blend weights (summing to one;
    /// unused slots weigh zero), four of each per sample: what [`Live::preview`] blends, and
    /// what the editor's page blends on the GPU.
    pub fn blend_weights(&self) -> Result<BlendWeights> {
        let field = Field {
            origin: self.complex.grid.origin,
            centers: self.complex.cells.iter().map(|c| c.center).collect(),
            halves: self.complex.cells.iter().map(|c| c.half).collect(),
            motions: self
                .complex
                .cells
                .iter()
                .map(|c| Motion::rest(&c.center))
                .collect(),
            prescribed: Prescribed::default(),
            heights_kept: false,
            trend: Default::default(),
        };
        let blend = Blend::new(&field, Weights::Continuous)?;
        let origin = self.complex.grid.origin;
        Ok(self
            .points
            .par_iter()
            .map(|p| {
                let (found, k) = blend.weights(&(p - origin));
                let (mut c, mut w) = ([0u32; 4], [0f32; 4]);
                for (slot, &(cell, weight)) in found[..k].iter().enumerate().take(4) {
                    c[slot] = cell as u32;
                    w[slot] = weight as f32;
                }
                (c, w)
            })
            .unzip())
    }

    /// The samples moved by the cells' current motions, blended ([`Live::blend_weights`]):
    /// the preview of a pose, a few milliseconds for a million samples, without the exact
    /// constraints of [`Live::release`]. The samples at rest before anything is constrained.
    pub fn preview(&mut self) -> Result<Vec<Vect<3>>> {
        let Some(session) = &self.session else {
            return Ok(self.points.clone());
        };
        if self.blend.is_none() {
            self.blend = Some(self.blend_weights()?);
        }
        let (cells, weights) = self.blend.as_ref().expect("made");
        let motions = session.motions();
        let origin = self.complex.grid.origin;
        let centers = &self.complex.cells;
        Ok(self
            .points
            .par_iter()
            .zip(cells)
            .zip(weights)
            .map(|((p, c), w)| {
                let x = p - origin;
                let (mut moved, mut total) = (Vect::<3>::zeros(), 0.0);
                for (&cell, &weight) in c.iter().zip(w) {
                    if weight > 0.0 {
                        let (cell, weight) = (cell as usize, f64::from(weight));
                        moved += motions[cell].apply(&centers[cell].center, &x) * weight;
                        total += weight;
                    }
                }
                // Divided by the weights' sum as rounded to f32, so that cells at rest
                // leave the sample where it was.
                if total > 0.0 {
                    moved / total + origin
                } else {
                    *p
                }
            })
            .collect())
    }

    /// The last spec's deformation of the samples: the solve converged (a drag's step may stop
    /// short), then the chosen transfer with its exact constraints and the fold-over check, as
    /// [`super::deform`] gives them (released without a drag, the same bits), with `normals`
    /// (one a sample, or none) turned as [`super::deform_oriented`] turns them. The samples at
    /// rest (and no solution) before anything is constrained.
    #[allow(clippy::type_complexity)]
    pub fn release(
        &mut self,
        normals: &[Vect<3>],
        observer: &dyn Observer,
    ) -> Result<(Vec<Vect<3>>, Vec<Vect<3>>, Option<Solution<3>>, DeformInfo)> {
        super::check_normals(self.points.len(), normals)?;
        let Some(session) = self.session.as_mut() else {
            let info = DeformInfo {
                build: self.build.clone(),
                options: self.params.options,
                ..Default::default()
            };
            return Ok((self.points.clone(), normals.to_vec(), None, info));
        };
        // A warm step that stopped short is converged; a solve from rest is taken as it ended,
        // as `deform` takes it.
        if self.warm && !self.info.converged {
            self.info = session.converge()?;
            if let (true, Some(spec)) = (self.info.converged, &self.spec) {
                self.settled = spec.handles.iter().map(|h| h.value).collect();
            }
        }
        // The turns the cells carry now, and the warnings of this pose (a drag may have
        // turned a handle further than the solve from rest did).
        self.info.turns = session.turns();
        let solution = session.solution(self.info.clone());
        let transfer_start = Instant::now();
        let saved = stages::field(&solution, &self.params, observer)?;
        let mut warnings = stages::warnings(
            &self.build,
            &solution.complex,
            &solution.constraints,
            &solution.info,
            &self.params,
        );
        warnings.extend(crate::cells::shortfall(
            self.params.build.target_cells,
            self.complex.len(),
        ));
        let staged = stages::Staged {
            solution,
            saved,
            build: self.build.clone(),
            warnings,
            transfer_start,
        };
        let spec = self.spec.as_ref().expect("a session has its spec");
        let points = (&self.points[..], normals);
        let (moved, turned, solution, info) =
            stages::transfer_samples(staged, points, spec, &self.params, observer)?;
        Ok((moved, turned, Some(solution), info))
    }
}

/// Whether a handle posed `b` turns from its pose `a` by more than `step` degrees (or the
/// handles differ in number): a warm step from there could take the short way round (a pose
/// typed at 360° from rest is the identity to a rotation matrix).
fn turns_past_a_step(a: &[HandleMotion<3>], b: &[HandleMotion<3>], step: f64) -> bool {
    a.len() != b.len()
        || a.iter().zip(b).any(|(h, k)| {
            let ((axis_a, angle_a), (axis_b, angle_b)) = (h.turn, k.turn);
            let apart = if axis_a.dot(&axis_b) >= 1.0 - 1e-9 {
                (angle_b - angle_a).abs()
            } else {
                <Dim<3> as Rigid<3>>::angle(&(k.rotation * h.rotation.transpose()))
                    .max((angle_b.abs() - angle_a.abs()).abs())
            };
            apart.to_degrees() > step
        })
}

/// Whether `b` is `a` with only its handles' poses and its pins' destinations changed: the
/// same regions, pinned points, targets and stiffness, so that the resolved constraints hold
/// with new handle maps and pin destinations.
fn same_but_poses(a: &EditSpec<3>, b: &EditSpec<3>) -> bool {
    a.fixed == b.fixed
        && a.pins.len() == b.pins.len()
        && a.pins
            .iter()
            .zip(&b.pins)
            .all(|(p, q)| p.point == q.point && p.line == q.line)
        && a.targets.len() == b.targets.len()
        && a.targets.iter().zip(&b.targets).all(|(t, u)| {
            // A target's pull moves warm while no trend is fitted to where the targets go.
            let moved = Target {
                to: u.to,
                ..t.clone()
            };
            moved == *u && (t.to == u.to || a.trend == Trend::None)
        })
        && a.trend == b.trend
        && a.stiffness == b.stiffness
        && a.handles.len() == b.handles.len()
        && a.handles
            .iter()
            .zip(&b.handles)
            .all(|(h, k)| h.region == k.region && h.line == k.line)
}
