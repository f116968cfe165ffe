//! The method's stage sequence, written once: cells → constraints → solve → field → exact
//! transfer, with the checks and warnings every face gets.
//!
//! [`run`] owns the sequence. Its callers differ only in where the cells come from
//! ([`Cells`]: samples in memory, or a streaming first pass that built them and gathered what
//! the spec's regions select) and in what they do with the result: [`super::deform`] warps the
//! samples, [`super::solve_points`] keeps the field, [`super::deform_file`] streams a file
//! through it and [`crate::image::deform_image`] warps a picture's pixel corners. A live
//! deformation ([`super::Live`]: the editor, Python's `Session`, Blender's Live) solves warm,
//! one pose at a time, on cells it built once: it calls the same stages one by one
//! ([`constraints`], then its [`crate::solve::Session`], then [`warnings`], [`field`] and
//! [`control_results`]), so that it refuses and warns as `deform` does.
//!
//! The checks live here: the dense RBF's memory before the solve and again after refinement
//! ([`check_rbf_memory`]), and the warnings of the build, the constraints and the solver, in
//! that order ([`warnings`]).

use std::time::Instant;

use crate::cells::{BuildInfo, CellComplex, Inside, build_checked};
use crate::control::ControlPoint;
use crate::error::Result;
use crate::field::{Field, Outside, Rbf, SavedField, Transfer, Warp, apply, apply_into};
use crate::progress::Observer;
use crate::rigid::{Dim, Rigid, Vect};
use crate::said::{Opt, Said};
use crate::solve::{self, Constraints, Selections, Solution, SolverInfo};
use crate::spec::EditSpec;

use super::{DeformInfo, DeformParams, check_foldovers, check_moved};

/// Where a run's cells come from, and what the spec's regions select on them. (Made once
/// per run and moved straight into [`run`]: its size does not matter.)
#[allow(clippy::large_enum_variant)]
pub(crate) enum Cells<'a, const D: usize> {
    /// Samples in memory: the cells are built from them (and `triangles`), and the regions are
    /// evaluated on them (with their LAS classes, when they have some).
    Samples {
        points: &'a [Vect<D>],
        triangles: &'a [[u32; 3]],
        classes: Option<&'a [u8]>,
    },
    /// Cells built by a streaming first pass, with what the regions selected there.
    Built {
        complex: CellComplex<D>,
        build: BuildInfo,
        selections: Selections<D>,
    },
}

impl<'a, const D: usize> Cells<'a, D> {
    /// Samples in memory, without classes.
    pub(crate) fn samples(points: &'a [Vect<D>], triangles: &'a [[u32; 3]]) -> Self {
        Cells::Samples {
            points,
            triangles,
            classes: None,
        }
    }
}

/// What [`run`] gives: the solution, its field (with the RBF's factorization when that is the
/// transfer; [`SavedField::deformer`] makes the map with its exact constraints), the cells'
/// construction and the warnings so far.
pub(crate) struct Staged<const D: usize> {
    pub(crate) solution: Solution<D>,
    pub(crate) saved: SavedField<D>,
    pub(crate) build: BuildInfo,
    pub(crate) warnings: Vec<Said>,
    /// When the field's construction began (after the solve): the start of the transfer's time.
    pub(crate) transfer_start: Instant,
}

/// The method's stages in order: the cells ([`Cells`]), the spec resolved onto them
/// ([`constraints`]), the solve, the warnings ([`warnings`]) and the field with its transfer
/// ([`field`]).
pub(crate) fn run<const D: usize>(
    cells: Cells<'_, D>,
    spec: &EditSpec<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<Staged<D>>
where
    Dim<D>: Rigid<D>,
{
    // What a `--cells N` search says when the count it found is not N (a streamed file's
    // first pass says it among the file's notes).
    let mut sizing = None;
    let (complex, build, constraints) = match cells {
        Cells::Samples {
            points,
            triangles,
            classes,
        } => {
            // What the spec asks of the samples (their classes, their indices), before the
            // cells are built.
            crate::solve::Selections::new(spec, classes.is_some(), points.len() as u64)?;
            let check = |forecast: &crate::cells::Forecast| params.check_forecast(forecast);
            let (complex, info) =
                build_checked(points, triangles, &params.build, params.memory, &check)?;
            sizing = crate::cells::shortfall(params.build.target_cells, complex.len());
            let selected = Selected::Samples { points, classes };
            let constraints = self::constraints(&complex, spec, selected, params)?;
            (complex, info, constraints)
        }
        Cells::Built {
            complex,
            build,
            selections,
        } => {
            let selected = Selected::Gathered(&selections);
            let constraints = self::constraints(&complex, spec, selected, params)?;
            (complex, build, constraints)
        }
    };
    let solution = solve::solve(complex, constraints, &params.solve, params.memory, observer)?;
    // The solved constraints' warnings: an adaptive solve decides its parts at rest again.
    let mut warnings = warnings(
        &build,
        &solution.complex,
        &solution.constraints,
        &solution.info,
        params,
    );
    warnings.extend(sizing);
    let transfer_start = Instant::now();
    let saved = field(&solution, params, observer)?;
    Ok(Staged {
        solution,
        saved,
        build,
        warnings,
        transfer_start,
    })
}

/// What the spec's regions select: evaluated on samples in memory, or gathered by a pass
/// over a file.
pub(crate) enum Selected<'a, const D: usize> {
    /// Samples in memory, with their LAS classes when they have some.
    Samples {
        points: &'a [Vect<D>],
        classes: Option<&'a [u8]>,
    },
    /// Gathered while the cells were built.
    Gathered(&'a Selections<D>),
}

/// The spec resolved onto `complex`, after checking that the transfer's memory fits the
/// budget for these cells (so that no face solves what it then cannot transfer).
pub(crate) fn constraints<const D: usize>(
    complex: &CellComplex<D>,
    spec: &EditSpec<D>,
    selected: Selected<'_, D>,
    params: &DeformParams,
) -> Result<Constraints<D>>
where
    Dim<D>: Rigid<D>,
{
    let constraints = resolved(complex, spec, selected, params)?;
    check_rbf_memory::<D>(complex.len(), params)?;
    Ok(constraints)
}

/// The spec resolved onto `complex` with the cells' stiffness as `params` set it (the inside's
/// scale on the spec's regions): what a run solves and what the estimate forecasts.
pub(crate) fn resolved<const D: usize>(
    complex: &CellComplex<D>,
    spec: &EditSpec<D>,
    selected: Selected<'_, D>,
    params: &DeformParams,
) -> Result<Constraints<D>>
where
    Dim<D>: Rigid<D>,
{
    let mut constraints = match selected {
        Selected::Samples { points, classes } => solve::resolve(complex, spec, points, classes)?,
        Selected::Gathered(selections) => solve::resolve_selected(complex, spec, selections)?,
    };
    constraints.scale_interior(complex, params.interior_stiffness);
    Ok(constraints)
}

/// The field of `solution` for `params.transfer`, with the RBF factored when that is the
/// transfer (checked against the memory budget again: refinement may have added cells).
pub(crate) fn field<const D: usize>(
    solution: &Solution<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<SavedField<D>>
where
    Dim<D>: Rigid<D>,
{
    check_rbf_memory::<D>(solution.complex.len(), params)?;
    let field = Field::from_solution(solution);
    observer.stage("factoring", 0);
    let rbf = match params.transfer {
        Transfer::Rbf => Some(Rbf::new(&field)?),
        _ => None,
    };
    observer.finish();
    Ok(SavedField::new(field, params.transfer, rbf))
}

/// The dense RBF of `cells` cells, when that is the transfer, checked against the budget:
/// checked before the solve, and again after refinement, so that neither ends in an abort.
pub(crate) fn check_rbf_memory<const D: usize>(cells: usize, params: &DeformParams) -> Result<()> {
    if params.transfer != Transfer::Rbf {
        return Ok(());
    }
    params.memory.check(
        format!("the RBF transfer of {cells} cells"),
        crate::memory::rbf_bytes(cells, D),
        Said::from("use ")
            .set(Opt::Transfer, "pu")
            .text(" (the default) or blend, or a larger ")
            .opt(Opt::CellSize)
            .text(" (or fewer ")
            .opt(Opt::Cells)
            .text(")"),
    )
}

/// The warnings of a solve with `params`, in order: the cell construction's, the constraints',
/// the solver's.
pub(crate) fn warnings<const D: usize>(
    build: &BuildInfo,
    complex: &CellComplex<D>,
    constraints: &Constraints<D>,
    solver: &SolverInfo,
    params: &DeformParams,
) -> Vec<Said> {
    let mut out = build_warnings(build, complex, params);
    out.extend_from_slice(&constraints.warnings);
    out.extend(solver.warnings());
    out
}

/// The warnings of the cell construction with `params`: parts glued by the finest cells (the
/// advice asks for more cells where a count sized them, `--cells`, else a smaller size), and
/// options the cells leave without effect — a winding-number inside asked of points with
/// neither triangles nor normals (the flood fill found it), an inside's stiffness with no
/// cell inside to scale.
pub(crate) fn build_warnings<const D: usize>(
    build: &BuildInfo,
    complex: &CellComplex<D>,
    params: &DeformParams,
) -> Vec<Said> {
    let by_count = params.build.target_cells.is_some();
    let mut out = Vec::new();
    if params.build.inside == Inside::Winding && build.inside != Inside::Winding {
        out.push(
            Said::new()
                .set(Opt::Inside, Inside::Winding)
                .text(" needs a mesh's triangles or the points' normals, and these points have neither: the inside was found by ")
                .set(Opt::Inside, build.inside),
        );
    }
    if params.interior_stiffness != super::options::DEFAULT_INTERIOR_STIFFNESS
        && build.interior_cells == 0
    {
        out.push(
            Said::new()
                .set(Opt::InteriorStiffness, params.interior_stiffness)
                .text(" scales nothing: no cell lies inside the shape (")
                .text(match build.inside {
                    Inside::Winding => {
                        "its winding numbers found none: an open surface, or a shape no \
                         thicker than two cells, whose every cell holds part of its surface"
                    }
                    _ => {
                        "a flood fill from outside found none: an open surface, points \
                         with gaps wider than a cell, or a shape no thicker than two cells"
                    }
                })
                .text(")"),
        );
    }
    if build.glued_cells > 0 {
        let size = complex.grid.finest_size();
        let said = Said::from(format!(
            "{} cells hold parts of the mesh that are not connected but lie closer than the \
             finest cell size ({}): the parts move together there; ",
            build.glued_cells,
            crate::human::length(size, size),
        ));
        out.push(match by_count {
            true => said.text("more ").opt(Opt::Cells).text(" keep them apart"),
            false => said
                .text("a smaller ")
                .opt(Opt::CellSize)
                .text(" keeps them apart"),
        });
    }
    out
}

/// The control points of `spec` in `solution` as `warp` moves them, with the leave-one-out
/// check when `params` asks for it, and the seconds that check took (a stage of its own: one
/// solve per control point).
pub(crate) fn control_results<const D: usize>(
    spec: &EditSpec<D>,
    solution: &Solution<D>,
    warp: &impl Warp<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(Vec<ControlPoint>, f64)>
where
    Dim<D>: Rigid<D>,
{
    let mut got = crate::control::from_points(solution);
    apply(warp, &solution.constraints.origin, &mut got);
    let mut points = crate::control::control_points(spec, solution, &got);
    if !params.check_control_points {
        return Ok((points, 0.0));
    }
    let start = Instant::now();
    crate::control::leave_one_out(
        spec,
        solution,
        &params.solve,
        params.memory,
        &mut points,
        observer,
    )?;
    Ok((points, start.elapsed().as_secs_f64()))
}

/// The end of a deformation of samples in memory, after its stages ([`run`], or a live
/// session's solve): the field's map (the chosen transfer with its exact constraints) applied
/// to `points` and their `normals` (one each, or none), the moved samples checked, the
/// fold-over check and the control points' results. What [`super::deform`] and
/// [`super::Live::release`] return.
#[allow(clippy::type_complexity)]
pub(crate) fn transfer_samples<const D: usize>(
    staged: Staged<D>,
    (points, normals): (&[Vect<D>], &[Vect<D>]),
    spec: &EditSpec<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(Vec<Vect<D>>, Vec<Vect<D>>, Solution<D>, DeformInfo)>
where
    Dim<D>: Rigid<D>,
{
    let Staged {
        solution,
        saved,
        build,
        mut warnings,
        transfer_start,
    } = staged;
    let origin = saved.field.origin;
    let deformer = saved.deformer(None, params.rbf_tolerance, Outside::Extend)?;
    let (mut moved, mut turned) = (Vec::new(), Vec::new());
    apply_into(&deformer, &origin, points, normals, &mut moved, &mut turned);
    check_moved(0, &moved)?;
    let (checked, folded) = check_foldovers(&deformer, &solution, points, &mut warnings);
    let controls = control_results(spec, &solution, &deformer, params, observer)?;
    let mut info = DeformInfo::of(
        params,
        build,
        &solution.info,
        transfer_start,
        (checked, folded.len()),
        controls,
        warnings,
    );
    info.folded = folded;
    Ok((moved, turned, solution, info))
}
