//! The whole method on samples in memory: cells → constraints → solve → transfer.
//!
//! [`deform`] is what the CLI's `deform` and `demo` run; file handling stays with the caller.

use std::time::Instant;

use crate::cells::{BuildInfo, BuildParams, build};
use crate::error::Result;
use crate::field::{Deformer, Field, Transfer, apply};
use crate::progress::Observer;
use crate::rigid::{Dim, Rigid, Vect};
use crate::solve::{self, Solution, SolveParams, SolverInfo};
use crate::spec::EditSpec;

/// Parameters of [`deform`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DeformParams {
    /// The cell complex.
    pub build: BuildParams,
    /// The solver.
    pub solve: SolveParams,
    /// The transfer to the samples.
    pub transfer: Transfer,
}

/// What [`deform`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DeformInfo {
    /// The cell complex's construction.
    pub build: BuildInfo,
    /// The solver.
    pub solver: SolverInfo,
    /// Seconds spent in the transfer (building it and applying it).
    pub seconds_transfer: f64,
    /// Messages for the user.
    pub warnings: Vec<String>,
}

/// Deforms `points` (with `triangles` over them, or none) under `spec`; returns the moved
/// points, the solution, and what was done.
pub fn deform<const D: usize>(
    points: &[Vect<D>],
    triangles: &[[u32; 3]],
    spec: &EditSpec<D>,
    params: &DeformParams,
    observer: &dyn Observer,
) -> Result<(Vec<Vect<D>>, Solution<D>, DeformInfo)>
where
    Dim<D>: Rigid<D>,
{
    let (complex, build_info) = build(points, triangles, &params.build)?;
    let constraints = solve::resolve(&complex, spec, points, None)?;
    let warnings = constraints.warnings.clone();
    let solution = solve::solve(complex, constraints, &params.solve, observer)?;
    let t = Instant::now();
    let field = Field::from_solution(&solution);
    let deformer = Deformer::new(&field, params.transfer)?;
    let mut moved = points.to_vec();
    apply(&deformer, &field.origin, &mut moved);
    let info = DeformInfo {
        build: build_info,
        solver: solution.info.clone(),
        seconds_transfer: t.elapsed().as_secs_f64(),
        warnings,
    };
    Ok((moved, solution, info))
}
