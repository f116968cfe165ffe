//! # rigidcells
//!
//! Deforms point clouds, triangle soups and meshes by the method of *Adaptive Space
//! Deformations Based on Rigid Cells* (M. Botsch, M. Pauly, M. Wicke, M. Gross, Computer
//! Graphics Forum 26(3), Eurographics 2007).
//!
//! The shape is embedded in an adaptive octree (quadtree in 2D) of rigid cells; the cells are
//! coupled by an elastic glue energy and solved for under the user's constraints by
//! Gauss-Newton on rigid motions; the resulting space warp moves every sample of the input. One
//! code path serves 2D and 3D: everything is generic over `const D: usize`, and [`Rigid`] holds
//! the few operations that differ.
//!
//! ```text
//! samples ─► cells::build ─► solve::resolve (edit spec) ─► solve::solve ─► field::{Blend,Rbf} ─► samples'
//! ```
//!
//! ## Where to start
//!
//! Everything a caller needs is at the crate root, and is what the library promises: its
//! functions, their parameters, specs, reports and errors, and the choices they take
//! ([`Inside`], [`Method`], [`LooseParts`], [`Transfer`], [`Outside`], [`Budget`], a preview's
//! [`View`]). Messages for people are [`said`]'s. The modules that build it (the cells, the
//! solver, the field, the file formats) live in `internal`, hidden from these pages: the
//! command line, the Python extension, the tools and the tests use their parts, and they change
//! with the library. A type that a root item shows but that the root does not name (the cell
//! complex in a [`Solution`], a solver's iteration log) is read through its fields and methods.
//!
//! - **What to do:** an [`EditSpec`] — read from TOML ([`read_spec`], [`parse_spec`]) or made in
//!   code (its [`Entry`]s of [`Region`]s and [`HandleMotion`]s, [`Pin`]s and [`Target`]s,
//!   checked by [`EditSpec::validate`] where a run starts).
//! - **How:** [`Options`], the user's options with their defaults, checked into
//!   [`DeformParams`] by [`Options::params`].
//! - **Points in memory:** [`deform`] (the moved points, the solution, a [`DeformInfo`]), or
//!   [`solve_points`] for the field alone, to apply to these or other points.
//! - **Files** (LAS/LAZ/COPC, PLY, OBJ, XYZ, streamed whatever their size): [`deform_file`] and
//!   [`FileInfo`], or [`deform_file_with`] and the [`Outputs`] beside the file (a saved field,
//!   the report, a preview; the chunk size); [`solve_files`] solves over tiles and saves a
//!   [`SavedField`], which [`apply_file`] applies to any file with [`ApplyParams`].
//! - **Live edits** (one set of cells, pose after pose): [`Live`], each pose's [`Step`].
//! - **What happened:** [`Report`] (what `--report` writes), and every failure an [`Error`]
//!   whose exit code the command line uses ([`Error::exit_code`]).
//! - **Progress and stopping:** an [`Observer`] ([`Silent`] hears nothing).
//!
//! ```
//! use rigidcells::{Options, Silent, Vect, deform, parse_spec};
//! use std::path::Path;
//!
//! // A 4×1×1 bar of points, 0.1 apart along it and 0.25 across.
//! let points: Vec<Vect<3>> = (0..=40)
//!     .flat_map(|i| (0..=4).flat_map(move |j| (0..=4).map(move |k| (i, j, k))))
//!     .map(|(i, j, k)| Vect::<3>::new(0.1 * i as f64, 0.25 * j as f64, 0.25 * k as f64))
//!     .collect();
//! // Fix the left end, lift the right end by 1.
//! let spec = parse_spec::<3>(
//!     "[[fixed]]\nbox = { min = [-1.0, -1.0, -1.0], max = [0.5, 2.0, 2.0] }\n\
//!      [[handle]]\nbox = { min = [3.5, -1.0, -1.0], max = [5.0, 2.0, 2.0] }\n\
//!      translate = [0.0, 0.0, 1.0]\n",
//!     Path::new("."),
//!     Path::new("edit.toml"),
//! )?;
//! // The user's options, checked, become the parameters (the rest at their defaults).
//! let params = Options { cell_size: Some(0.25), ..Default::default() }.params()?;
//! let (moved, solution, info) = deform(&points, &[], &spec, &params, &Silent)?;
//! assert_eq!(moved.len(), points.len());
//! assert!(info.solver.converged && solution.complex.len() > 50);
//! // The right end went up by 1; the left end stayed.
//! let (a, b) = (points.iter().position(|p| p.x == 4.0).unwrap(), points.iter().position(|p| p.x == 0.0).unwrap());
//! assert!((moved[a].z - points[a].z - 1.0).abs() < 0.05);
//! assert!((moved[b] - points[b]).norm() < 0.02);
//! # Ok::<(), rigidcells::Error>(())
//! ```
//!
//! ## Features
//!
//! The library itself needs none of them (`default-features = false`). `cli` brings the
//! command line's parser and progress bars, `editor` the editor's local web server, `demo` the
//! generated inputs of `rigidcells demo`. All three are on by default, and the `rigidcells`
//! binary requires them.
//!
//! ## In a debug build of your crate
//!
//! A crate's `[profile]` settings do not reach the crates that depend on it, so a debug build
//! of yours compiles rigidcells and its dependencies unoptimized, with overflow checks: the
//! solver then runs 60–70 times slower than in release, and the LAZ codec (the `laz` crate,
//! which relies on wrapping integer arithmetic) panics with "subtract with overflow" on LAZ
//! records of point formats 9 and 10. Build your dependencies as rigidcells builds its own, in
//! your workspace's `Cargo.toml`:
//!
//! ```toml
//! [profile.dev.package."*"]
//! opt-level = 3
//! overflow-checks = false
//! debug-assertions = false
//! ```

pub mod said;

#[doc(hidden)]
pub mod internal;

#[cfg(feature = "editor")]
pub(crate) use internal::edit;
pub(crate) use internal::{
    cells, control, crs, error, estimate, field, human, image, interrupt, io, memory, pipeline,
    progress, render, rigid, solve, spec,
};

pub use cells::Inside;
pub use error::{Error, Result};
pub use field::{FieldMap, Outside, SavedField, Transfer};
pub use memory::Budget;
pub use pipeline::report::Report;
pub use pipeline::{
    ApplyParams, DEFAULT_INTERIOR_STIFFNESS, DeformInfo, DeformParams, FileInfo, Live, Options,
    Outputs, Step, apply_file, deform, deform_file, deform_file_with, solve_files, solve_points,
};
pub use progress::{Observer, Silent};
pub use render::View;
pub use rigid::{Dim, Mat, Rigid, Vect};
pub use solve::{LooseParts, Method, Solution, SolverInfo};
pub use spec::{EditSpec, Entry, HandleMotion, Pin, Region, Target, Trend, parse_spec, read_spec};

/// Runs `f`, which calls faer, on a rayon pool of faer's own.
///
/// faer's parallel kernels go through `spindle`, which runs them inside rayon scopes; measured
/// here, a rayon pool that has run one of them no longer hands work to its second worker, so on
/// the global pool every parallel loop after the first solve ran at one core's speed (pass 2 of
/// a 20M-point LAS took 2.95 s instead of 1.9; `rayon::join` of two 90 ms tasks took 80 ms
/// instead of 40; a Gauss-Newton iteration on that terrain's 1.4k cells 26 ms instead of 13).
/// Every faer call runs on this pool instead, which nothing else uses.
pub(crate) fn with_faer<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    static POOL: std::sync::OnceLock<Option<rayon::ThreadPool>> = std::sync::OnceLock::new();
    match POOL.get_or_init(|| rayon::ThreadPoolBuilder::new().build().ok()) {
        Some(pool) => pool.install(f),
        None => f(),
    }
}
