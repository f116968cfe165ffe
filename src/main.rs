//! The `rigidcells` command line: parse, call the library, report. See `rigidcells --help`.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use rigidcells::Error;
use rigidcells::cells::{BuildParams, Inside};
use rigidcells::field::Transfer;
use rigidcells::io::{Document, refuse_overwrite};
use rigidcells::pipeline::{DeformInfo, DeformParams, deform};
use rigidcells::progress::Observer;
use rigidcells::solve::SolveParams;
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
    /// Deform a PLY mesh/point cloud or an XYZ point cloud under an edit spec.
    Deform(DeformArgs),
    /// Generate a bar and a non-manifold soup, bend them, and write inputs and results.
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
    /// Input file (.ply, .xyz).
    input: PathBuf,
    /// Output file (same format as the input).
    #[arg(short, long)]
    output: PathBuf,
    /// Edit spec (TOML): fixed regions, handles, pins, targets, stiffness.
    #[arg(long)]
    edit: PathBuf,
    /// Edge length of the finest cells, in input units [default: longest extent / 32].
    #[arg(long)]
    cell_size: Option<f64>,
    /// Octree levels above the finest cells [default: enough to span the input].
    #[arg(long)]
    max_level: Option<u8>,
    /// Transfer of the cells' motions to the samples.
    #[arg(long, value_enum, default_value_t = TransferArg::Rbf)]
    transfer: TransferArg,
    /// Split cells whose strain exceeds this threshold, and solve again.
    #[arg(long)]
    refine_strain: Option<f64>,
    /// Keep only cells that hold samples (a shell; no interior cells).
    #[arg(long)]
    shell: bool,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum TransferArg {
    /// Inverse-distance blend of the 4 nearest cells (fast preview).
    Blend,
    /// Triharmonic RBF interpolation (smooth, final).
    Rbf,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Deform(args) => run_deform(&args),
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
fn exit_code(e: &anyhow::Error) -> u8 {
    match e.downcast_ref::<Error>() {
        Some(
            Error::Io { .. }
            | Error::Format { .. }
            | Error::UnsupportedFormat { .. }
            | Error::Input(_),
        ) => 3,
        Some(
            Error::Spec { .. }
            | Error::Param(_)
            | Error::NoConstraints
            | Error::ConstraintConflict { .. }
            | Error::GridTooLarge { .. },
        ) => 4,
        _ => 1,
    }
}

fn run_deform(args: &DeformArgs) -> anyhow::Result<()> {
    refuse_overwrite(&args.input, &args.output)?;
    let params = DeformParams {
        build: BuildParams {
            cell_size: args.cell_size,
            max_level: args.max_level,
            inside: if args.shell {
                Inside::None
            } else {
                Inside::Flood
            },
        },
        solve: SolveParams {
            refine_strain: args.refine_strain,
            ..Default::default()
        },
        transfer: match args.transfer {
            TransferArg::Blend => Transfer::Blend,
            TransferArg::Rbf => Transfer::Rbf,
        },
    };
    deform_file(&args.input, &args.output, &args.edit, &params, args.quiet)
}

fn deform_file(
    input: &Path,
    output: &Path,
    edit: &Path,
    params: &DeformParams,
    quiet: bool,
) -> anyhow::Result<()> {
    let spec = read_spec::<3>(edit)?;
    let doc = Document::read(input)?;
    let bar = Bar::new(quiet);
    let (moved, _, info) = deform(doc.positions(), doc.triangles(), &spec, params, &bar)?;
    doc.write(&moved, output)?;
    if !quiet {
        report(input, output, doc.positions().len(), &info);
    }
    Ok(())
}

fn report(input: &Path, output: &Path, points: usize, info: &DeformInfo) {
    for w in &info.warnings {
        eprintln!("warning: {w}");
    }
    let s = &info.solver;
    println!(
        "{} -> {}: {points} points, {} cells ({} boundary, {} interior){}",
        input.display(),
        output.display(),
        s.cells_final,
        info.build.boundary_cells,
        info.build.interior_cells,
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
}

fn run_demo(out: &Path, quiet: bool) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let size = [10.0, 1.0, 1.0];
    let shapes = [
        ("bar", data_gen::bar(size, 8.0), Transfer::Rbf),
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
        deform_file(&input, &output, &edit, &params, quiet)?;
    }
    if !quiet {
        println!(
            "demo: wrote bar.ply, soup.ply (inputs), bar_bent.ply (RBF), soup_bent.ply (blend) and bend.toml in {}",
            out.display()
        );
    }
    Ok(())
}

/// A progress bar on a terminal; silent otherwise.
struct Bar(Option<ProgressBar>);

impl Bar {
    fn new(quiet: bool) -> Self {
        Self((!quiet && std::io::stderr().is_terminal()).then(|| {
            let b = ProgressBar::hidden();
            b.set_style(
                ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} {elapsed}")
                    .expect("valid template"),
            );
            b
        }))
    }
}

impl Observer for Bar {
    fn stage(&self, name: &str, len: u64) {
        if let Some(b) = &self.0 {
            b.set_draw_target(indicatif::ProgressDrawTarget::stderr());
            b.set_message(name.to_string());
            b.set_length(len);
            b.set_position(0);
        }
    }
    fn advance(&self, n: u64) {
        if let Some(b) = &self.0 {
            b.inc(n);
        }
    }
    fn finish(&self) {
        if let Some(b) = &self.0 {
            b.finish_and_clear();
        }
    }
}
