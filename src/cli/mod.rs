//! The command line: argument definitions and dispatch. The commands themselves
//! (`commands.rs`) call the library and print what it returns; the progress bar is
//! `progress.rs`.

mod choice;
mod commands;
mod progress;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use rigidcells::Budget;
use rigidcells::Error;
use rigidcells::Inside;
use rigidcells::internal::pipeline::{self, CHUNK, DeformParams};
use rigidcells::internal::render::{self, View};
use rigidcells::{LooseParts, Method};
use rigidcells::{Outside, Transfer};

use choice::choice;
use commands::*;

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
        #[arg(long, value_parser = choice::<Transfer>())]
        transfer: Option<Transfer>,
        #[command(flatten)]
        tolerance: ToleranceArg,
        /// Samples farther outside the field's cells than its margin (the size of the cells on
        /// its boundary): refuse (exit 4, nothing written), keep (they keep their coordinates;
        /// the shape tears at the margin), or extend (the transfer is extrapolated: the RBF's
        /// linear part grows with the distance, the blend follows the nearest cells).
        #[arg(long, value_parser = choice::<Outside>(), default_value_t = Outside::Refuse)]
        outside: Outside,
        /// Take the input to be in the coordinate system the field was solved in. Without it, a
        /// field and an input that declare different systems (EPSG codes, else WKT texts) are
        /// refused (exit 4); one that declares none beside one that does is a warning.
        #[arg(long)]
        same_crs: bool,
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
        #[arg(long, value_parser = choice::<Transfer>(), default_value_t = Transfer::Blend)]
        transfer: Transfer,
        #[command(flatten)]
        cells: CellArgs,
        /// Print nothing but errors.
        #[arg(short, long)]
        quiet: bool,
    },
    /// Solve an edit over several files taken as one (the tiles of a scan) and write only the
    /// field; `apply` it to each tile: together they give what `deform` gives on the merged
    /// file, record for record. The summary, `--report`, `--preview` and `--check-gcp` are what
    /// `deform` gives for the merged file.
    Solve(SolveArgs),
    /// Write a saved field as a GeoTIFF grid of east, north and up offsets that PROJ applies
    /// without rigidcells (`+proj=gridshift +grids=correction.tif`: PROJ 9.4 and later, and so
    /// GDAL, PDAL and QGIS). The offsets are where `apply` moves a point minus where it was,
    /// sampled at each node's ground (or --height); between nodes the tools interpolate
    /// bilinearly, and the largest deviation of that from the field is printed: halve the
    /// spacing to cut it about fourfold.
    Grid {
        /// The field file (`deform --save-field`, `solve --save-field`).
        field: PathBuf,
        /// The GeoTIFF to write (.tif).
        #[arg(short, long)]
        output: PathBuf,
        /// Distance between the grid's nodes, in the field's units [default: the finest cells'
        /// edge].
        #[arg(long, value_name = "LENGTH")]
        spacing: Option<f64>,
        /// The area the grid covers, in the field's coordinates; the nodes lie at whole
        /// multiples of the spacing [default: the field's cells].
        #[arg(long, value_name = "MINX,MINY,MAXX,MAXY", allow_hyphen_values = true)]
        extent: Option<String>,
        /// Sample the field at this height everywhere [default: at each node, the middle of
        /// the lowest cell over it, a scan's ground; nodes beside the cells take the nearest
        /// such height].
        #[arg(long, value_name = "Z", allow_hyphen_values = true)]
        height: Option<f64>,
        /// EPSG code of the projected CRS of the field's coordinates, written in the grid's
        /// GeoKeys [default: the code of the system the field records, else none; PROJ needs
        /// none]. A code other than the field's is refused.
        #[arg(long, value_name = "CODE")]
        epsg: Option<u32>,
        #[command(flatten)]
        memory: MemoryArg,
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
    /// Edit interactively in the browser: select fixed and handle regions on a proxy of the
    /// input, drag the handle and see the shape follow; save the edit spec, or apply it to the
    /// whole file. Serves on 127.0.0.1 only, behind a random token in the printed address.
    Edit {
        /// Input file (LAS/LAZ, PLY, OBJ, XYZ).
        input: PathBuf,
        /// Port to listen on (0: any free one).
        #[arg(long, default_value_t = 0)]
        port: u16,
        /// The folder the page's Save edit and Apply write into, under plain file names
        /// (default: the input's folder).
        #[arg(long)]
        out_dir: Option<PathBuf>,
        /// Open the page in the system's browser.
        #[arg(long)]
        open: bool,
        /// The most samples in the proxy the page shows and the cells are built from.
        #[arg(long, default_value_t = pipeline::PROXY_SAMPLES)]
        proxy: usize,
        /// Transfer of the cells' motions to the samples on release and on Apply.
        #[arg(long, value_parser = choice::<Transfer>(), default_value_t = Transfer::Pu)]
        transfer: Transfer,
        #[command(flatten)]
        cells: CellArgs,
        /// Print nothing but the address and errors.
        #[arg(short, long)]
        quiet: bool,
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
    #[arg(long, value_parser = choice::<Transfer>(), default_value_t = Transfer::Pu)]
    transfer: Transfer,
    #[command(flatten)]
    tolerance: ToleranceArg,
    /// Split cells whose strain exceeds this threshold, and solve again.
    #[arg(long, allow_negative_numbers = true)]
    refine_strain: Option<f64>,
    /// Also write the solved field to this file, for `rigidcells apply`.
    #[arg(long)]
    save_field: Option<PathBuf>,
    #[command(flatten)]
    reports: ReportArgs,
    /// Samples per streamed chunk (1 to 16,777,216; larger values are taken as the largest).
    #[arg(long, default_value_t = CHUNK)]
    chunk: usize,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

impl DeformArgs {
    /// The library's parameters for these arguments.
    fn params(&self) -> Result<DeformParams, Error> {
        pipeline::Options {
            refine_strain: self.refine_strain,
            rbf_tolerance: self.tolerance.rbf_tolerance,
            check_control_points: self.reports.check_gcp,
            ..self.cells.options(self.transfer)
        }
        .params()
    }
}

/// What `deform` and `solve` write and check beside their result (for `solve`, what `deform`
/// gives for the tiles merged: the tiles as the report's `inputs`, the field as its `output`).
#[derive(clap::Args)]
struct ReportArgs {
    /// Also write a JSON report: counts, cell levels, iterations, energies, residuals,
    /// fold-overs, control points, timings per stage, peak memory.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Also write a PNG of the input and the output side by side (a decimated proxy of the
    /// samples, across all tiles for `solve`: fixed regions gray, handles yellow, the rest
    /// blue).
    #[arg(long)]
    preview: Option<PathBuf>,
    /// Add a third panel to the preview: the deformed cells colored by strain, blue (none) to
    /// red (the most).
    #[arg(long, requires = "preview")]
    strain: bool,
    #[command(flatten)]
    view: ViewArgs,
    /// Check the control points (`[[target]]`): solve again without each in turn and report
    /// how far the others predict it (leave-one-out).
    #[arg(long)]
    check_gcp: bool,
}

impl ReportArgs {
    /// The run's outputs beside `named` (the output, the field) with their options, for
    /// refusing clashes before any work.
    fn named<'a>(
        &'a self,
        named: &[(&'static str, Option<&'a Path>)],
    ) -> Vec<(&'static str, &'a Path)> {
        named
            .iter()
            .copied()
            .chain([
                ("--report", self.report.as_deref()),
                ("--preview", self.preview.as_deref()),
            ])
            .filter_map(|(option, path)| Some((option, path?)))
            .collect()
    }

    /// The library's outputs: these beside `save_field`, the preview seen as the view options
    /// say for `input`'s bounds.
    fn outputs<'a>(
        &'a self,
        save_field: Option<&'a Path>,
        input: &Path,
    ) -> anyhow::Result<pipeline::Outputs<'a>> {
        let view = self.view.view(input)?;
        Ok(pipeline::Outputs {
            save_field,
            report: self.report.as_deref(),
            preview: self.preview.as_deref().map(|p| (p, view, self.strain)),
            keep_existing: false,
            chunk: None,
        })
    }
}

#[derive(clap::Args)]
struct SolveArgs {
    /// Input files (LAS/LAZ, XYZ, PLY point clouds), read in this order as one.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Edit spec (TOML).
    #[arg(long)]
    edit: PathBuf,
    /// The field to write, for `rigidcells apply`.
    #[arg(long)]
    save_field: PathBuf,
    #[command(flatten)]
    cells: CellArgs,
    /// The transfer `apply` will use (and the field is made for).
    #[arg(long, value_parser = choice::<Transfer>(), default_value_t = Transfer::Pu)]
    transfer: Transfer,
    #[command(flatten)]
    reports: ReportArgs,
    /// Samples per streamed chunk (1 to 16,777,216; larger values are taken as the largest).
    #[arg(long, default_value_t = CHUNK)]
    chunk: usize,
    /// Take the tiles to be in one coordinate system. Without it, tiles that declare
    /// different systems (EPSG codes, else WKT texts) are refused (exit 4); one that declares
    /// none beside one that does is a warning. The field records the system.
    #[arg(long)]
    same_crs: bool,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

impl SolveArgs {
    /// The library's parameters for these arguments.
    fn params(&self) -> Result<DeformParams, Error> {
        pipeline::Options {
            check_control_points: self.reports.check_gcp,
            ..self.cells.options(self.transfer)
        }
        .params()
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
    #[arg(long, value_name = "LENGTH", allow_negative_numbers = true)]
    rbf_tolerance: Option<f64>,
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
            Error::param(format!(
                "--size {}: expected WIDTHxHEIGHT, e.g. 640x480",
                self.size
            ))
        };
        let (w, h) = self.size.split_once('x').ok_or_else(bad)?;
        let (width, height): (u32, u32) =
            (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
        let view = View {
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
        };
        view.check()?;
        Ok(view)
    }
}

/// How the cell complex is built.
#[derive(clap::Args)]
struct CellArgs {
    /// Edge length of the finest cells, in input units [default: longest extent / 32].
    #[arg(long, allow_negative_numbers = true)]
    cell_size: Option<f64>,
    /// About this many cells: picks the finest cell size.
    #[arg(long, conflicts_with = "cell_size")]
    cells: Option<usize>,
    /// Adaptive cells: built at this size, merged up to 8× it wherever one role holds (the
    /// edit's regions keep their borders), solved, and split again, round by round, where the
    /// solved strain is high (above a quarter of the largest), down to this size.
    #[arg(long, value_name = "S", conflicts_with_all = ["cell_size", "cells"], allow_negative_numbers = true)]
    min_cell_size: Option<f64>,
    /// Octree levels above the finest cells [default: enough for the largest cell that fits the
    /// input's shortest extent]. Fewer make the largest cells smaller than the shape, and its
    /// inside takes as many of them as its box holds (counted against --memory-limit first).
    #[arg(long)]
    max_level: Option<u8>,
    /// Keep only cells that hold samples (a shell; no interior cells); same as `--inside none`.
    #[arg(long)]
    shell: bool,
    /// Inside classification of empty cells: winding numbers for meshes, soups and point
    /// clouds with normals, exterior flood fill for point clouds without (auto), or as named.
    #[arg(long, value_parser = choice::<Inside>(), default_value_t = Inside::Auto)]
    inside: Inside,
    /// Stiffness of the cells inside the shape against those on its surface: the default 0.05
    /// spreads a twist along a thin neck as a surface does and keeps most of a bend's volume;
    /// 1 is the paper's uniform solid, whose bends keep their volume best and whose twists
    /// gather where it is thinnest; 0.0001 to 10000, not with --shell.
    #[arg(
        long,
        value_name = "S",
        default_value_t = rigidcells::DEFAULT_INTERIOR_STIFFNESS,
        allow_negative_numbers = true
    )]
    interior_stiffness: f64,
    /// How the solver's Gauss-Newton systems are solved: a sparse Cholesky factorization, or
    /// conjugate gradients with a rigid-motion multigrid (the same minimum, memory linear in
    /// the cells; BENCHMARKS.md says which is faster where).
    #[arg(long, value_parser = choice::<Method>(), default_value_t = Method::Auto)]
    solver: Method,
    /// Solve by local-global iterations with each global step split into this many subdomains
    /// of the cells (conjugate gradients with a two-level Schwarz preconditioner, each
    /// subdomain's block factored alone): how a solve spread over processes runs, here in
    /// one; the Python package's `rigidcells.dask.solve_tiles` gives the blocks to Dask
    /// workers. 0: as --solver says.
    #[arg(long, value_name = "K", default_value_t = 0)]
    subdomains: usize,
    /// Stop each load step at the first full Gauss-Newton step that moves no corner of any
    /// cell by more than this many finest cell sizes, or that lowers the energy by less than a
    /// millionth of it (a thousandth in the load steps before the last); 0 keeps only the
    /// energy test.
    #[arg(
        long,
        value_name = "F",
        default_value_t = rigidcells::internal::solve::MOVE_TOLERANCE,
        allow_negative_numbers = true
    )]
    tolerance: f64,
    /// Solve this many coarser complexes first (each cell's parents, then theirs), each
    /// starting the next finer one at its solution, so that the cells' own Gauss-Newton
    /// iterations only correct; 0 solves the cells from rest [default: from 2,000 cells, as
    /// many as bring the coarsest under 20,000 cells (one at least, at most 3); none for fewer
    /// cells or with --refine-strain]
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=8))]
    coarse_levels: Option<u8>,
    /// Parts of the shape that no constraint reaches (leaves, fittings, a loose piece of a
    /// soup): carried rigidly by the nearest constrained part, or kept where they were.
    #[arg(long, value_parser = choice::<LooseParts>(), default_value_t = LooseParts::Carry)]
    loose_parts: LooseParts,
    #[command(flatten)]
    memory: MemoryArg,
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

impl MemoryArg {
    fn budget(self) -> anyhow::Result<Budget> {
        Ok(Budget::checked(self.memory_limit)?)
    }
}

fn parse_memory(text: &str) -> Result<u64, String> {
    rigidcells::internal::memory::parse_size(text)
}

impl CellArgs {
    /// The library's options of these arguments, with `transfer`.
    fn options(&self, transfer: Transfer) -> pipeline::Options {
        pipeline::Options {
            cell_size: self.cell_size,
            cells: self.cells,
            min_cell_size: self.min_cell_size,
            max_level: self.max_level,
            shell: self.shell,
            inside: self.inside,
            interior_stiffness: self.interior_stiffness,
            solver: self.solver,
            subdomains: self.subdomains,
            tolerance: self.tolerance,
            coarse_levels: self.coarse_levels,
            loose_parts: self.loose_parts,
            transfer,
            memory_limit: self.memory.memory_limit,
            ..Default::default()
        }
    }

    /// The parameters of a command that takes only the cells' options and a transfer.
    fn deform_params(&self, transfer: Transfer) -> Result<DeformParams, Error> {
        self.options(transfer).params()
    }
}

/// Parses the command line, runs the command, prints an error and gives the exit code.
pub(crate) fn main() -> ExitCode {
    rigidcells::internal::interrupt::remove_temporaries_on_signals();
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
            same_crs,
            memory,
            quiet,
        } => memory.budget().and_then(|memory| {
            let params = pipeline::ApplyParams {
                transfer,
                rbf_tolerance: tolerance.rbf_tolerance,
                outside,
                memory,
                same_crs,
            };
            run_apply(&field, &input, &output, &params, quiet)
        }),
        Command::Grid {
            field,
            output,
            spacing,
            extent,
            height,
            epsg,
            memory,
            quiet,
        } => parse_extent(extent.as_deref()).and_then(|extent| {
            let params = rigidcells::internal::field::grid::GridParams {
                spacing,
                extent,
                height,
                memory: memory.budget()?,
            };
            run_grid(&field, &output, &params, epsg, quiet)
        }),
        Command::Info { input } => run_info(&input),
        Command::Solve(args) => run_solve(&args),
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
            transfer,
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
        Command::Edit {
            input,
            port,
            out_dir,
            open,
            proxy,
            transfer,
            cells,
            quiet,
        } => run_edit(
            &input,
            (port, out_dir.as_deref()),
            open,
            proxy,
            transfer,
            &cells,
            quiet,
        ),
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
fn exit_code(e: &anyhow::Error) -> u8 {
    e.downcast_ref::<Error>().map_or(1, Error::exit_code)
}
