//! The `rigidcells` command line: parse, call the library, report. See `rigidcells --help`.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use rigidcells::Error;
use rigidcells::cells::{BuildParams, Inside, write_cells_ply};
use rigidcells::field::{Outside, Transfer};
use rigidcells::io::{LasHeader, refuse_overwrite};
use rigidcells::pipeline::{self, CHUNK, DeformParams, FileInfo};
use rigidcells::progress::Observer;
use rigidcells::render::{self, View};
use rigidcells::report::Report;
use rigidcells::rigid::Vect;
use rigidcells::solve::Solution;
use rigidcells::solve::{Method, SolveParams};
use rigidcells::spec::read_spec;

#[derive(Parser)]
#[command(
    name = "rigidcells",
    version,
    about = "Adaptive space deformations based on rigid cells (Botsch, Pauly, Wicke, Gross 2007)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Deform a LAS/LAZ scan, a PLY or OBJ mesh or point cloud, an XYZ point cloud, or a 2D
    /// point set (.xy, with a 2D spec) under an edit spec.
    Deform(DeformArgs),
    /// Apply a field saved by `deform --save-field` to a file (the same, a denser one, a tile).
    Apply {
        /// The field file.
        field: PathBuf,
        /// Input file.
        input: PathBuf,
        /// Output file.
        #[arg(short, long)]
        output: PathBuf,
        /// Transfer of the cells' motions to the samples [default: the one the field was
        /// saved with by `deform --transfer`].
        #[arg(long, value_enum)]
        transfer: Option<TransferArg>,
        #[command(flatten)]
        tolerance: ToleranceArg,
        /// Samples farther outside the field's cells than its margin (the size of the cells on
        /// its boundary): refuse (exit 4, nothing written), keep (they keep their coordinates;
        /// the shape tears at the margin), or extend (the transfer is extrapolated: the RBF's
        /// linear part grows with the distance, the blend follows the nearest cells).
        #[arg(long, value_enum, default_value_t = OutsideArg::Refuse)]
        outside: OutsideArg,
        #[command(flatten)]
        memory: MemoryArg,
        /// Print nothing but errors.
        #[arg(short, long)]
        quiet: bool,
    },
    /// Export the cell complex of a file as a PLY of boxes (per-cell level, kind, role, strain
    /// and color); with `--edit`, solved and drawn in the solved pose, colored by strain.
    Cells {
        /// Input file.
        input: PathBuf,
        /// Output PLY file.
        #[arg(short, long)]
        output: PathBuf,
        /// Edit spec (TOML) to solve before exporting.
        #[arg(long)]
        edit: Option<PathBuf>,
        #[command(flatten)]
        cells: CellArgs,
        /// Print nothing but errors.
        #[arg(short, long)]
        quiet: bool,
    },
    /// Render a file to a PNG: meshes and soups as shaded triangles, point clouds as shaded
    /// splats (LAS RGB, or intensity, when present).
    Render {
        /// Input file.
        input: PathBuf,
        /// Output PNG.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        view: ViewArgs,
    },
    /// Deform the foreground of a PNG (alpha > 0, or not the --background color) under an edit
    /// spec in pixel coordinates (x right, y down), on a quadtree of 2D rigid cells.
    Image {
        /// Input PNG.
        input: PathBuf,
        /// Edit spec (TOML) in pixel coordinates.
        #[arg(long)]
        edit: PathBuf,
        /// Output PNG.
        #[arg(short, long)]
        output: PathBuf,
        /// The background color of an opaque picture, R,G,B (0–255 each).
        #[arg(long)]
        background: Option<String>,
        /// Transfer of the cells' motions to the pixels (the blend keeps fixed pixels exact).
        #[arg(long, value_enum, default_value_t = TransferArg::Blend)]
        transfer: TransferArg,
        #[command(flatten)]
        cells: CellArgs,
        /// Print nothing but errors.
        #[arg(short, long)]
        quiet: bool,
    },
    /// Describe a file (LAS/LAZ, PLY, OBJ, XYZ, .xy, .png, .field): format, counts, bounds and
    /// centroid to the file's precision, CRS by name and EPSG code, record fields, a saved
    /// field's cells, levels and transfer.
    Info {
        /// Input file.
        input: PathBuf,
    },
    /// Generate a bar, a non-manifold soup and a 2D picture, deform them, and write inputs and
    /// results.
    Demo {
        /// Folder for the files (created if missing).
        #[arg(long, default_value = "rigidcells-demo")]
        out: PathBuf,
        /// Print nothing but errors.
        #[arg(short, long)]
        quiet: bool,
    },
}

#[derive(clap::Args)]
struct DeformArgs {
    /// Input file (.las, .laz, .ply, .obj, .xyz; .xy for 2D points).
    input: PathBuf,
    /// Output file (the input's format; .las and .laz convert into each other).
    #[arg(short, long)]
    output: PathBuf,
    /// Edit spec (TOML): fixed regions, handles, pins, targets, stiffness.
    #[arg(long)]
    edit: PathBuf,
    #[command(flatten)]
    cells: CellArgs,
    /// Transfer of the cells' motions to the samples.
    #[arg(long, value_enum, default_value_t = TransferArg::Pu)]
    transfer: TransferArg,
    #[command(flatten)]
    tolerance: ToleranceArg,
    /// Split cells whose strain exceeds this threshold, and solve again.
    #[arg(long)]
    refine_strain: Option<f64>,
    /// Also write the solved field to this file, for `rigidcells apply`.
    #[arg(long)]
    save_field: Option<PathBuf>,
    /// Also write a JSON report: counts, cell levels, iterations, energies, residuals,
    /// fold-overs, timings per stage, peak memory.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Also write a PNG of the input and the output side by side (a decimated proxy of the
    /// samples: fixed regions gray, handles yellow, the rest blue).
    #[arg(long)]
    preview: Option<PathBuf>,
    /// Add a third panel to the preview: the deformed cells colored by strain, blue (none) to
    /// red (the most).
    #[arg(long, requires = "preview")]
    strain: bool,
    #[command(flatten)]
    view: ViewArgs,
    /// Samples per streamed chunk (1 to 16,777,216; larger values are taken as the largest).
    #[arg(long, default_value_t = CHUNK)]
    chunk: usize,
    /// Check the control points (`[[target]]`): solve again without each in turn and report
    /// how far the others predict it (leave-one-out).
    #[arg(long)]
    check_gcp: bool,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

impl DeformArgs {
    /// The library's parameters for these arguments, keeping a proxy of `proxy_samples`.
    fn params(&self, proxy_samples: Option<usize>) -> Result<DeformParams, Error> {
        let (build, solve) = self.cells.params()?;
        Ok(DeformParams {
            build,
            solve: SolveParams {
                refine_strain: self.refine_strain,
                ..solve
            },
            transfer: self.transfer.into(),
            rbf_tolerance: self.tolerance.rbf_tolerance,
            proxy_samples,
            check_control_points: self.check_gcp,
        })
    }
}

/// The RBF's far-field evaluation.
#[derive(clap::Args)]
struct ToleranceArg {
    /// With the RBF transfer: sum far groups of cells through a Barnes–Hut expansion wherever
    /// its error bound keeps each output coordinate within this length (model units) of the
    /// exact RBF's. On real models that is only far outside the model (90 extents away at 1 %
    /// of the extent on the dragon, BENCHMARKS.md); elsewhere every cell is summed exactly, at
    /// the same speed.
    #[arg(long, value_name = "LENGTH")]
    rbf_tolerance: Option<f64>,
}

impl ToleranceArg {
    /// Refuses a tolerance given with a transfer other than the RBF, or not a length.
    fn check(&self, transfer: TransferArg) -> anyhow::Result<()> {
        match self.rbf_tolerance {
            Some(_) if !matches!(transfer, TransferArg::Rbf) => {
                Err(Error::Param("--rbf-tolerance applies to --transfer rbf only".into()).into())
            }
            Some(t) => Ok(rigidcells::field::Rbf::<3>::check_tolerance(t)?),
            None => Ok(()),
        }
    }
}

/// Where pictures are seen from.
#[derive(clap::Args)]
struct ViewArgs {
    /// Degrees about the vertical (z) axis of the view direction.
    #[arg(long, default_value_t = -60.0, allow_hyphen_values = true)]
    azimuth: f64,
    /// Degrees above the horizon of the view direction.
    #[arg(long, default_value_t = 25.0, allow_hyphen_values = true)]
    elevation: f64,
    /// Picture size in pixels, WIDTHxHEIGHT (a preview has two of them side by side).
    #[arg(long, default_value = "640x480")]
    size: String,
    /// The vertical axis [default: z for LAS/LAZ and XYZ, y for PLY and OBJ meshes unless
    /// their header names another with a comment such as `up z`].
    #[arg(long, value_enum)]
    up: Option<UpArg>,
    /// Magnify about the picture's center (2 shows the middle half of the box).
    #[arg(long, default_value_t = 1.0)]
    zoom: f64,
}

#[derive(Clone, Copy, ValueEnum)]
enum UpArg {
    X,
    Y,
    Z,
}

impl ViewArgs {
    /// The view of these arguments for pictures of `input` (whose file decides the default
    /// vertical axis).
    fn view(&self, input: &Path) -> anyhow::Result<View> {
        let bad = || {
            Error::Param(format!(
                "--size {}: expected WIDTHxHEIGHT, e.g. 640x480",
                self.size
            ))
        };
        let (w, h) = self.size.split_once('x').ok_or_else(bad)?;
        let (width, height): (u32, u32) =
            (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
        if !(16..=8192).contains(&width) || !(16..=8192).contains(&height) {
            return Err(
                Error::Param(format!("--size {}: 16 to 8192 pixels each way", self.size)).into(),
            );
        }
        if !self.azimuth.is_finite() || !self.elevation.is_finite() {
            return Err(Error::Param("--azimuth and --elevation must be finite".into()).into());
        }
        if !(self.zoom.is_finite() && self.zoom > 0.0 && self.zoom <= 1e6) {
            return Err(Error::Param(format!(
                "--zoom {}: a factor above 0, at most 1e6",
                self.zoom
            ))
            .into());
        }
        Ok(View {
            azimuth: self.azimuth,
            elevation: self.elevation,
            width,
            height,
            up: match self.up {
                Some(UpArg::X) => 0,
                Some(UpArg::Y) => 1,
                Some(UpArg::Z) => 2,
                None => render::up_of(input),
            },
            zoom: self.zoom,
        })
    }
}

/// How the cell complex is built.
#[derive(clap::Args)]
struct CellArgs {
    /// Edge length of the finest cells, in input units [default: longest extent / 32].
    #[arg(long)]
    cell_size: Option<f64>,
    /// About this many cells: picks the finest cell size (overrides --cell-size).
    #[arg(long)]
    cells: Option<usize>,
    /// Adaptive cells: built at this size, merged up to 8× it wherever one role holds (the
    /// edit's regions keep their borders), solved, and split again, round by round, where the
    /// solved strain is high (above a quarter of the largest), down to this size.
    #[arg(long, value_name = "S", conflicts_with_all = ["cell_size", "cells"])]
    min_cell_size: Option<f64>,
    /// Octree levels above the finest cells [default: enough for the largest cell that fits the
    /// input's shortest extent].
    #[arg(long)]
    max_level: Option<u8>,
    /// Keep only cells that hold samples (a shell; no interior cells); same as `--inside none`.
    #[arg(long)]
    shell: bool,
    /// Inside classification of empty cells: winding numbers for meshes, soups and point
    /// clouds with normals, exterior flood fill for point clouds without (auto), or as named.
    #[arg(long, value_enum, default_value_t = InsideArg::Auto)]
    inside: InsideArg,
    /// How the solver's Gauss-Newton systems are solved: a sparse Cholesky factorization, or
    /// conjugate gradients with a rigid-motion multigrid (the same minimum, memory linear in
    /// the cells; BENCHMARKS.md says which is faster where).
    #[arg(long, value_enum, default_value_t = SolverArg::Auto)]
    solver: SolverArg,
    /// Parts of the shape that no constraint reaches (leaves, fittings, a loose piece of a
    /// soup): carried rigidly by the nearest constrained part, or kept where they were.
    #[arg(long, value_enum, default_value_t = LooseArg::Carry)]
    loose_parts: LooseArg,
    #[command(flatten)]
    memory: MemoryArg,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
enum LooseArg {
    /// Each rides along rigidly with the nearest cell of a constrained part.
    Carry,
    /// Each keeps its rest pose.
    Rest,
}

#[derive(Clone, Copy, ValueEnum)]
enum SolverArg {
    /// Multilevel for cells of one size past 100,000 free cells; else the factorization where it
    /// fits the memory budget, else multilevel.
    Auto,
    /// Sparse Cholesky factorization (fill-in: memory grows faster than the cells).
    Direct,
    /// Conjugate gradients with a rigid-motion multigrid (memory linear in the cells).
    Multilevel,
}

/// The memory budget.
#[derive(clap::Args, Clone, Copy)]
struct MemoryArg {
    /// Stop with an error, before allocating, when the cell grid, the solver or the RBF would
    /// need more memory than this (e.g. 8G, 512M) [default: three quarters of the machine's
    /// memory, at most half of `ulimit -v`].
    #[arg(long, value_name = "SIZE", value_parser = parse_memory)]
    memory_limit: Option<u64>,
}

fn parse_memory(text: &str) -> Result<u64, String> {
    rigidcells::memory::parse_size(text)
}

impl CellArgs {
    /// The solver's parameters: the defaults, with the memory budget.
    fn solve_params(&self) -> SolveParams {
        SolveParams {
            memory_limit: self.memory.memory_limit,
            method: match self.solver {
                SolverArg::Auto => Method::Auto,
                SolverArg::Direct => Method::Direct,
                SolverArg::Multilevel => Method::Multilevel,
            },
            carry_loose: self.loose_parts == LooseArg::Carry,
            ..Default::default()
        }
    }

    /// The build's and the solver's parameters; with `--min-cell-size`, those of an adaptive
    /// solve ([`rigidcells::solve::adaptive`]).
    fn params(&self) -> Result<(BuildParams, SolveParams), Error> {
        let (build, solve) = (self.build_params(), self.solve_params());
        match self.min_cell_size {
            Some(size) => rigidcells::solve::adaptive(size, &build, &solve),
            None => Ok((build, solve)),
        }
    }

    fn build_params(&self) -> BuildParams {
        BuildParams {
            cell_size: self.cell_size,
            target_cells: self.cells,
            memory_limit: self.memory.memory_limit,
            max_level: self.max_level,
            inside: match (self.shell, self.inside) {
                (true, _) | (_, InsideArg::None) => Inside::None,
                (_, InsideArg::Auto) => Inside::Auto,
                (_, InsideArg::Winding) => Inside::Winding,
                (_, InsideArg::Flood) => Inside::Flood,
            },
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum InsideArg {
    /// Winding numbers when the input has triangles or normals, flood fill otherwise.
    Auto,
    /// Generalized winding number of the triangles or oriented points.
    Winding,
    /// Exterior flood fill on the finest grid.
    Flood,
    /// No interior cells (a shell).
    None,
}

#[derive(Clone, Copy, ValueEnum)]
enum OutsideArg {
    /// Fail with exit code 4, naming how many samples and how far; write nothing.
    Refuse,
    /// Samples beyond the margin keep their coordinates bit for bit.
    Keep,
    /// The transfer is evaluated beyond the margin as anywhere.
    Extend,
}

#[derive(Clone, Copy, ValueEnum)]
enum TransferArg {
    /// Continuous blend of the 4 nearest cells (fast preview).
    Blend,
    /// The paper's inverse-distance blend of the 4 nearest cells (seams where the set changes).
    BlendIdw,
    /// Triharmonic RBF interpolation (smooth, final).
    Rbf,
    /// Partition-of-unity RBF: triharmonic fits on overlapping patches blended smoothly (C²),
    /// for any number of cells.
    Pu,
}

fn main() -> ExitCode {
    rigidcells::interrupt::remove_temporaries_on_signals();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Deform(args) => run_deform(&args),
        Command::Apply {
            field,
            input,
            output,
            transfer,
            tolerance,
            outside,
            memory,
            quiet,
        } => tolerance
            .check(transfer.unwrap_or(TransferArg::Rbf))
            .and_then(|()| {
                let params = pipeline::ApplyParams {
                    transfer: transfer.map(Into::into),
                    rbf_tolerance: tolerance.rbf_tolerance,
                    outside: match outside {
                        OutsideArg::Refuse => Outside::Refuse,
                        OutsideArg::Keep => Outside::Keep,
                        OutsideArg::Extend => Outside::Extend,
                    },
                    memory_limit: memory.memory_limit,
                };
                run_apply(&field, &input, &output, &params, quiet)
            }),
        Command::Info { input } => run_info(&input),
        Command::Image {
            input,
            edit,
            output,
            background,
            transfer,
            cells,
            quiet,
        } => run_image(
            &input,
            &edit,
            &output,
            background.as_deref(),
            transfer.into(),
            &cells,
            quiet,
        ),
        Command::Render {
            input,
            output,
            view,
        } => view
            .view(&input)
            .and_then(|v| run_render(&input, &output, &v)),
        Command::Cells {
            input,
            output,
            edit,
            cells,
            quiet,
        } => run_cells(&input, &output, edit.as_deref(), &cells, quiet),
        Command::Demo { out, quiet } => run_demo(&out, quiet),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(exit_code(&e))
        }
    }
}

/// 3: unreadable or malformed input; 4: a bad edit spec or parameter; 1: anything else.
/// The largest `--chunk`: a chunk's buffers are sized by what it holds, but 2⁶⁴ − 1 overflowed
/// the index arithmetic of the readers.
const MAX_CHUNK: usize = 1 << 24;

fn exit_code(e: &anyhow::Error) -> u8 {
    e.downcast_ref::<Error>().map_or(1, Error::exit_code)
}

fn run_cells(
    input: &Path,
    output: &Path,
    edit: Option<&Path>,
    cells: &CellArgs,
    quiet: bool,
) -> anyhow::Result<()> {
    refuse_overwrite(input, output)?;
    let ply = output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    if !ply {
        return Err(Error::Param(format!(
            "{}: the cells are written as .ply",
            output.display()
        ))
        .into());
    }
    let spec = edit.map(read_spec::<3>).transpose()?;
    let (build, solve) = cells.params()?;
    let params = DeformParams {
        build,
        solve,
        ..Default::default()
    };
    let (complex, info, solution, warnings) = pipeline::file_cells(
        input,
        spec.as_ref(),
        &params,
        CHUNK,
        &rigidcells::progress::Silent,
    )?;
    write_cells_ply(output, &complex, solution.as_ref(), render::up_of(input))?;
    if quiet {
        return Ok(());
    }
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let shown = solution.as_ref().map_or(&complex, |s| &s.complex);
    println!(
        "{} -> {}: {} cells ({} boundary, {} interior), finest cell {}",
        input.display(),
        output.display(),
        shown.len(),
        info.boundary_cells,
        info.interior_cells,
        shown.grid.finest_size()
    );
    Ok(())
}

fn run_deform(args: &DeformArgs) -> anyhow::Result<()> {
    refuse_overwrite(&args.input, &args.output)?;
    args.tolerance.check(args.transfer)?;
    for extra in [&args.save_field, &args.report, &args.preview]
        .into_iter()
        .flatten()
    {
        refuse_overwrite(&args.input, extra)?;
    }
    let outputs: Vec<(&str, &Path)> = [
        ("-o", Some(&args.output)),
        ("--save-field", args.save_field.as_ref()),
        ("--report", args.report.as_ref()),
        ("--preview", args.preview.as_ref()),
    ]
    .into_iter()
    .filter_map(|(option, path)| Some((option, path?.as_path())))
    .collect();
    rigidcells::io::refuse_same_outputs(&outputs)?;
    if is_xy(&args.input) {
        return run_deform_xy(args);
    }
    // The proxy serves the fold-over check, the report's residual and the preview (which
    // draws a mesh's triangles when it holds every vertex).
    let proxy = match args.preview {
        Some(_) => pipeline::PROXY_SAMPLES,
        None => pipeline::FOLDOVER_SAMPLES,
    };
    let params = args.params(Some(proxy))?;
    let view = args.view.view(&args.input)?;
    if let Some(p) = &args.preview {
        png_path(p)?;
    }
    deform_file(
        &args.input,
        &args.output,
        &args.edit,
        &params,
        args.chunk.clamp(1, MAX_CHUNK),
        args.save_field.as_deref(),
        args.report.as_deref(),
        args.preview.as_deref().map(|p| (p, view, args.strain)),
        args.quiet,
    )
}

impl From<TransferArg> for Transfer {
    fn from(t: TransferArg) -> Self {
        match t {
            TransferArg::Blend => Transfer::Blend,
            TransferArg::BlendIdw => Transfer::BlendIdw,
            TransferArg::Rbf => Transfer::Rbf,
            TransferArg::Pu => Transfer::Pu,
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn deform_file(
    input: &Path,
    output: &Path,
    edit: &Path,
    params: &DeformParams,
    chunk: usize,
    save_field: Option<&Path>,
    report_to: Option<&Path>,
    preview: Option<(&Path, View, bool)>,
    quiet: bool,
) -> anyhow::Result<()> {
    let start = std::time::Instant::now();
    let spec = read_spec::<3>(edit)?;
    let bar = Bar::new(quiet);
    let (solution, info) =
        pipeline::deform_file(input, output, &spec, params, chunk, save_field, &bar)?;
    let summary = Report::new(
        input,
        output,
        &solution,
        &info,
        start.elapsed().as_secs_f64(),
    );
    if let Some(path) = report_to {
        summary.write(path)?;
    }
    if let Some((path, view, strain)) = preview {
        preview_image(&solution, &info, &view, strain).write_png(path)?;
    }
    if !quiet {
        report(input, output, &info);
        let checked = if summary.residual_samples > 0 {
            format!(
                "  constraints: fixed samples within {:.3e} of their rest positions, handle \
                 samples within {:.3e} of where they were sent ({} checked);",
                summary.residual_fixed_max, summary.residual_handle_max, summary.residual_samples,
            )
        } else {
            " ".to_string()
        };
        println!(
            "{checked} total {:.2} s{}",
            summary.timings_s.total,
            summary
                .peak_memory_bytes
                .map_or(String::new(), |b| format!(", peak memory {} MB", b >> 20))
        );
    }
    Ok(())
}

/// `path`, when it names a PNG.
fn png_path(path: &Path) -> anyhow::Result<()> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        Ok(())
    } else {
        Err(Error::Param(format!("{}: pictures are written as .png", path.display())).into())
    }
}

/// The preview of a deformation: the proxy before and after, side by side in one view fitted
/// to both, each sample colored by its cell's role; with `strain`, the deformed cells colored
/// by their strain beside them.
fn preview_image(
    solution: &Solution<3>,
    info: &FileInfo,
    view: &View,
    strain: bool,
) -> render::Image {
    rigidcells::preview::preview(solution, &info.proxy, view, strain)
}

fn is_xy(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("xy"))
}

/// `deform` of a 2D point set (`.xy`) under a 2D edit spec: the whole set in memory.
fn run_deform_xy(args: &DeformArgs) -> anyhow::Result<()> {
    if !is_xy(&args.output) {
        return Err(Error::Param(format!(
            "{}: a .xy point set is written as .xy",
            args.output.display()
        ))
        .into());
    }
    for (flag, set) in [
        ("--save-field", args.save_field.is_some()),
        ("--report", args.report.is_some()),
        ("--preview", args.preview.is_some()),
    ] {
        if set {
            return Err(
                Error::Param(format!("{flag} is for 3D inputs, not .xy point sets")).into(),
            );
        }
    }
    let file = rigidcells::io::XyFile::read(&args.input)?;
    let spec = read_spec::<2>(&args.edit)?;
    let params = args.params(None)?;
    let bar = Bar::new(args.quiet);
    let (moved, solution, info) = pipeline::deform(file.points(), &[], &spec, &params, &bar)?;
    file.write(&args.output, &moved)?;
    if !args.quiet {
        for w in &info.warnings {
            eprintln!("warning: {w}");
        }
        println!(
            "{} -> {}: {} points, {} cells, {} Gauss-Newton iterations, energy {:.3e}",
            args.input.display(),
            args.output.display(),
            moved.len(),
            solution.complex.len(),
            solution.info.iterations,
            solution.info.energies.last().copied().unwrap_or(0.0)
        );
        print_control_points(&info.control_points);
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn run_image(
    input: &Path,
    edit: &Path,
    output: &Path,
    background: Option<&str>,
    transfer: Transfer,
    cells: &CellArgs,
    quiet: bool,
) -> anyhow::Result<()> {
    refuse_overwrite(input, output)?;
    png_path(output)?;
    let background = background.map(parse_color).transpose()?;
    let spec = read_spec::<2>(edit)?;
    let raster = rigidcells::image::Raster::read_png(input)?;
    let (build, solve) = cells.params()?;
    let params = DeformParams {
        build,
        solve,
        transfer,
        ..Default::default()
    };
    let (out, info) = rigidcells::image::deform_image(&raster, &spec, &params, background)
        .with_context(|| format!("deforming {}", input.display()))?;
    out.write_png(output)?;
    if !quiet {
        for w in &info.warnings {
            eprintln!("warning: {w}");
        }
        if info.folded > 0 {
            eprintln!(
                "warning: the edit folds the picture over itself at {} pixel triangles",
                info.folded
            );
        }
        if info.clipped > 0 {
            eprintln!(
                "warning: {} pixel corners moved outside the {}x{} picture and were clipped",
                info.clipped, out.width, out.height
            );
        }
        println!(
            "{} -> {}: {} foreground pixels ({} after), {} cells, {} Gauss-Newton iterations",
            input.display(),
            output.display(),
            info.pixels.0,
            info.pixels.1,
            info.cells,
            info.iterations
        );
    }
    Ok(())
}

/// `R,G,B` with each in 0–255.
fn parse_color(text: &str) -> anyhow::Result<[u8; 3]> {
    let parts: Vec<Option<u8>> = text.split(',').map(|v| v.trim().parse().ok()).collect();
    match parts.as_slice() {
        [Some(r), Some(g), Some(b)] => Ok([*r, *g, *b]),
        _ => Err(Error::Param(format!(
            "--background {text}: expected R,G,B with each 0–255"
        ))
        .into()),
    }
}

fn run_render(input: &Path, output: &Path, view: &View) -> anyhow::Result<()> {
    refuse_overwrite(input, output)?;
    png_path(output)?;
    let image = match rigidcells::io::Document::read(input) {
        Ok(doc) => {
            // A PLY's vertex colors (a `cells` output's roles or strain), else gray; a
            // triangle takes its first vertex's.
            use rigidcells::io::Colors;
            let triangles = doc.triangles();
            let colors = match rigidcells::io::extension(input).as_deref() {
                Some("ply") => rigidcells::io::colors(input)?,
                _ => None,
            }
            .filter(|c| match c {
                Colors::Vertices(v) => v.len() == doc.positions().len(),
                Colors::Triangles(t) => t.len() == triangles.len(),
            });
            let color = |i: usize| match &colors {
                Some(Colors::Vertices(c)) if triangles.is_empty() => c[i],
                Some(Colors::Vertices(c)) => c[triangles[i][0] as usize],
                Some(Colors::Triangles(c)) => c[i],
                None => [200, 200, 200],
            };
            render::render_annotated(doc.positions(), triangles, doc.normals(), color, view)
        }
        Err(Error::UnsupportedFormat { .. }) => {
            let (points, colors) = read_colored_points(input, RENDER_POINTS)?;
            render::render_annotated(&points, &[], None, |i| colors[i], view)
        }
        Err(e) => return Err(e.into()),
    };
    image.write_png(output)?;
    println!(
        "{} -> {}: {}x{}, {} pixels drawn",
        input.display(),
        output.display(),
        image.width,
        image.height,
        image.foreground()
    );
    Ok(())
}

/// Points `render` draws of a streamed file at most (every k-th sample).
const RENDER_POINTS: usize = 2_000_000;

/// Every k-th sample of a streamed file (at most `max`) with its color: LAS RGB when the point
/// format has it, else LAS intensity as gray, else a neutral gray.
fn read_colored_points(input: &Path, max: usize) -> anyhow::Result<(Vec<Vect<3>>, Vec<[u8; 3]>)> {
    let mut source = rigidcells::io::open(input)?;
    let stride = (source.len() as usize).div_ceil(max).max(1);
    let las = LasHeader::read(input).ok();
    let mut chunk = rigidcells::io::Chunk::default();
    let (mut points, mut raw_colors) = (Vec::new(), Vec::new());
    let mut index = 0usize;
    loop {
        let n = source.read(CHUNK, &mut chunk)?;
        if n == 0 {
            break;
        }
        for i in 0..n {
            if (index + i).is_multiple_of(stride) {
                points.push(chunk.positions[i]);
                let rec = (chunk.record_len > 0)
                    .then(|| &chunk.raw[i * chunk.record_len..(i + 1) * chunk.record_len]);
                raw_colors.push(las.as_ref().zip(rec).map(|(h, r)| h.color(r)));
            }
        }
        index += n;
    }
    // Intensities and 16-bit RGB are scaled by the file's own range.
    let top = raw_colors
        .iter()
        .flatten()
        .flatten()
        .fold(1u16, |a, &b| a.max(b));
    let colors = raw_colors
        .into_iter()
        .map(|c| match c {
            Some(rgb) => rgb.map(|v| (v as u32 * 255 / top as u32) as u8),
            None => [200, 200, 200],
        })
        .collect();
    Ok((points, colors))
}

fn run_apply(
    field: &Path,
    input: &Path,
    output: &Path,
    params: &pipeline::ApplyParams,
    quiet: bool,
) -> anyhow::Result<()> {
    refuse_overwrite(input, output)?;
    let bar = Bar::new(quiet);
    let info = pipeline::apply_file(field, input, output, params, CHUNK, &bar)?;
    if !quiet {
        for n in &info.notes {
            println!("note: {n}");
        }
        println!(
            "{} -> {}: {} samples, {:.2} s",
            input.display(),
            output.display(),
            info.samples,
            info.seconds_write
        );
    }
    Ok(())
}

fn run_info(input: &Path) -> anyhow::Result<()> {
    let info = rigidcells::info::describe(input, &Bar::new(false))?;
    print!("{info}");
    Ok(())
}

fn report(input: &Path, output: &Path, file: &FileInfo) {
    let info = &file.deform;
    let points = file.samples;
    for w in &info.warnings {
        eprintln!("warning: {w}");
    }
    for n in &file.notes {
        println!("note: {n}");
    }
    let s = &info.solver;
    println!(
        "{} -> {}: {points} points, {} cells ({} boundary, {} interior by {}){}",
        input.display(),
        output.display(),
        s.cells_final,
        info.build.boundary_cells,
        info.build.interior_cells,
        match info.build.inside {
            Inside::Winding => "winding number",
            Inside::Flood => "flood fill",
            _ => "none",
        },
        if s.refinements.is_empty() {
            String::new()
        } else {
            format!(
                ", refined from {} to {} cells",
                s.cells_initial, s.cells_final
            )
        }
    );
    println!(
        "  solve: {} load steps, {} Gauss-Newton iterations, energy {:.3e}, {:.2} s ({:.1} ms/iteration){}",
        s.load_steps,
        s.iterations,
        s.energies.last().copied().unwrap_or(0.0),
        s.seconds,
        1e3 * s.seconds_per_iteration(),
        if s.converged {
            ""
        } else {
            ", stopped at the iteration limit"
        }
    );
    println!(
        "  cells {:.2} s, transfer {:.2} s",
        info.build.seconds, info.seconds_transfer
    );
    let (checked, folded) = info.foldovers;
    if checked > 0 {
        println!("  fold-overs: {folded} of {checked} samples checked");
    }
    print_control_points(&info.control_points);
}

/// The control points' table: the ten largest residuals and the RMSE.
fn print_control_points(points: &[rigidcells::control::ControlPoint]) {
    let table = rigidcells::control::table(points, 10);
    if !table.is_empty() {
        println!("{table}");
    }
}

fn run_demo(out: &Path, quiet: bool) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let size = [10.0, 1.0, 1.0];
    let shapes = [
        ("bar", data_gen::bar(size, 8.0), Transfer::Pu),
        ("soup", data_gen::soup(size, 8.0), Transfer::Blend),
    ];
    let edit = out.join("bend.toml");
    let spec = "# Bend the bar 90 degrees upwards: fix the left end, turn the right end.\n\
        [[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\n\
        [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n\
        rotate = { axis = [0.0, 1.0, 0.0], degrees = -90.0 }\n\
        translate = [-3.4, 0.0, 5.9]\n";
    rigidcells::io::write_atomic(&edit, spec.as_bytes())?;
    for (name, mesh, transfer) in shapes {
        let input = out.join(format!("{name}.ply"));
        let output = out.join(format!("{name}_bent.ply"));
        data_gen::write_ply(&input, &mesh, true)
            .with_context(|| format!("writing {}", input.display()))?;
        let params = DeformParams {
            build: BuildParams {
                cell_size: Some(0.25),
                ..Default::default()
            },
            transfer,
            ..Default::default()
        };
        deform_file(
            &input, &output, &edit, &params, CHUNK, None, None, None, quiet,
        )?;
    }
    // The 2D picture of paper Fig. 7: a gingerbread figure with its arms moved.
    let (width, height, rgba) = data_gen::gingerbread();
    let figure = rigidcells::image::Raster {
        width,
        height,
        rgba,
    };
    let (png_in, png_out, png_edit) = (
        out.join("gingerbread.png"),
        out.join("gingerbread_bent.png"),
        out.join("gingerbread.toml"),
    );
    figure.write_png(&png_in)?;
    rigidcells::io::write_atomic(&png_edit, data_gen::GINGERBREAD_SPEC.as_bytes())?;
    run_image(
        &png_in,
        &png_edit,
        &png_out,
        None,
        rigidcells::image::IMAGE_TRANSFER,
        &CellArgs {
            cell_size: None,
            cells: None,
            min_cell_size: None,
            max_level: None,
            shell: false,
            inside: InsideArg::Auto,
            solver: SolverArg::Auto,
            loose_parts: LooseArg::Carry,
            memory: MemoryArg { memory_limit: None },
        },
        quiet,
    )?;
    if !quiet {
        println!(
            "demo: wrote bar.ply, soup.ply (inputs), bar_bent.ply (partition-of-unity RBF), soup_bent.ply (blend), bend.toml, \
             gingerbread.png, gingerbread.toml and gingerbread_bent.png in {}",
            out.display()
        );
    }
    Ok(())
}

/// A progress bar on a terminal (a spinner for stages of unknown length), a new one for each
/// stage (a finished bar draws no more); silent otherwise.
struct Bar {
    shown: bool,
    bar: std::sync::Mutex<Option<ProgressBar>>,
}

impl Bar {
    fn new(quiet: bool) -> Self {
        Self {
            shown: !quiet && std::io::stderr().is_terminal(),
            bar: std::sync::Mutex::new(None),
        }
    }

    fn with(&self, f: impl FnOnce(&ProgressBar)) {
        if let Some(b) = self.bar.lock().expect("not poisoned").as_ref() {
            f(b);
        }
    }
}

impl Observer for Bar {
    fn stage(&self, name: &str, len: u64) {
        if !self.shown {
            return;
        }
        let template = if len == 0 {
            "{prefix:>11} {spinner} {elapsed} {msg}"
        } else {
            "{prefix:>11} [{bar:20}] {pos}/{len} {elapsed} {msg}"
        };
        let b = ProgressBar::with_draw_target(Some(len), indicatif::ProgressDrawTarget::stderr())
            .with_style(ProgressStyle::with_template(template).expect("valid template"))
            .with_prefix(name.to_string());
        if len == 0 {
            b.enable_steady_tick(std::time::Duration::from_millis(120));
        }
        if let Some(old) = self.bar.lock().expect("not poisoned").replace(b) {
            old.finish_and_clear();
        }
    }
    fn advance(&self, n: u64) {
        self.with(|b| b.inc(n));
    }
    fn message(&self, text: &str) {
        self.with(|b| b.set_message(text.to_string()));
    }
    fn finish(&self) {
        if let Some(b) = self.bar.lock().expect("not poisoned").take() {
            b.finish_and_clear();
        }
    }
}
