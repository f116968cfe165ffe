//! The commands: each calls the library and prints what it returns.

use std::path::Path;

use anyhow::Context;
use rigidcells::Error;
use rigidcells::Transfer;
use rigidcells::internal::io::refuse_overwrite;
use rigidcells::internal::pipeline::report::Summary;
use rigidcells::internal::pipeline::{self, CHUNK, DeformParams};
use rigidcells::internal::render::{self, View};
use rigidcells::read_spec;

use super::progress::Bar;
use super::*;

pub(super) fn run_cells(
    input: &Path,
    output: &Path,
    edit: Option<&Path>,
    cells: &CellArgs,
    quiet: bool,
) -> anyhow::Result<()> {
    refuse_overwrite(input, output)?;
    rigidcells::internal::io::check_folders([output])?;
    let ply = output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    if !ply {
        return Err(Error::param(format!(
            "{}: the cells are written as .ply",
            output.display()
        ))
        .into());
    }
    let spec = edit.map(read_spec::<3>).transpose()?;
    let params = cells.deform_params(Transfer::default())?;
    let (complex, info, solution, warnings) = pipeline::file_cells(
        input,
        spec.as_ref(),
        &params,
        CHUNK,
        &rigidcells::internal::progress::Silent,
    )?;
    pipeline::write_cells(output, &complex, solution.as_ref(), render::up_of(input))?;
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
        rigidcells::internal::human::length(shown.grid.finest_size(), shown.grid.finest_size())
    );
    Ok(())
}

/// Refuses, before any work, `outputs` (each with its option) that would replace one of
/// `inputs` or each other, or that lie in no folder.
fn refuse_clashes(inputs: &[PathBuf], outputs: &[(&str, &Path)]) -> anyhow::Result<()> {
    for input in inputs {
        for (_, output) in outputs {
            refuse_overwrite(input, output)?;
        }
    }
    rigidcells::internal::io::refuse_same_outputs(outputs)?;
    rigidcells::internal::io::check_folders(outputs.iter().map(|(_, path)| *path))?;
    Ok(())
}

pub(super) fn run_deform(args: &DeformArgs) -> anyhow::Result<()> {
    let outputs = args.reports.named(&[
        ("-o", Some(&args.output)),
        ("--save-field", args.save_field.as_deref()),
    ]);
    refuse_clashes(std::slice::from_ref(&args.input), &outputs)?;
    rigidcells::internal::io::check_output_format(&args.input, &args.output)?;
    let chunk = pipeline::check_chunk(args.chunk)?;
    if is_xy(&args.input) {
        return run_deform_xy(args);
    }
    let params = args.params()?;
    let outputs = pipeline::Outputs {
        chunk: Some(chunk),
        ..args
            .reports
            .outputs(args.save_field.as_deref(), &args.input)?
    };
    let files = (
        args.input.as_path(),
        args.output.as_path(),
        args.edit.as_path(),
    );
    deform_file(files, &params, &outputs, args.quiet)
}

/// `deform` of the file `input` into `output` under the spec in `edit`, with the `outputs`
/// beside it; prints the warnings and the summary unless `quiet`.
fn deform_file(
    (input, output, edit): (&Path, &Path, &Path),
    params: &DeformParams,
    outputs: &pipeline::Outputs,
    quiet: bool,
) -> anyhow::Result<()> {
    let spec = read_spec::<3>(edit)?;
    let bar = Bar::new(quiet);
    let (_, info, summary) =
        pipeline::deform_file_with(input, output, &spec, params, outputs, &bar)?;
    if !quiet {
        for w in &summary.warnings {
            eprintln!("warning: {w}");
        }
        print!(
            "{}",
            Summary {
                report: &summary,
                file: &info
            }
        );
    }
    Ok(())
}

pub(super) fn is_xy(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("xy"))
}

/// `deform` of a 2D point set (`.xy`) under a 2D edit spec: the whole set in memory.
pub(super) fn run_deform_xy(args: &DeformArgs) -> anyhow::Result<()> {
    for (flag, set) in [
        ("--save-field", args.save_field.is_some()),
        ("--report", args.reports.report.is_some()),
        ("--preview", args.reports.preview.is_some()),
    ] {
        if set {
            return Err(
                Error::param(format!("{flag} is for 3D inputs, not .xy point sets")).into(),
            );
        }
    }
    let spec = read_spec::<2>(&args.edit)?;
    let params = args.params()?;
    let bar = Bar::new(args.quiet);
    let (solution, info, points) =
        pipeline::deform_xy_file(&args.input, &args.output, &spec, &params, &bar)?;
    if !args.quiet {
        for w in &info.warnings {
            eprintln!("warning: {w}");
        }
        println!(
            "{} -> {}: {} points, {} cells, {}, energy {}",
            args.input.display(),
            args.output.display(),
            points,
            solution.complex.len(),
            solution.info.iterations_in_words(),
            rigidcells::internal::human::figure(
                solution.info.energies.last().copied().unwrap_or(0.0)
            )
        );
        print_control_points(&info);
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
pub(super) fn run_image(
    input: &Path,
    edit: &Path,
    output: &Path,
    background: Option<&str>,
    transfer: Transfer,
    cells: &CellArgs,
    quiet: bool,
) -> anyhow::Result<()> {
    let params = cells.deform_params(transfer)?;
    image_job(input, edit, output, background, &params, quiet)
}

/// `image` with its parameters: deform the picture, write it, print what happened.
pub(super) fn image_job(
    input: &Path,
    edit: &Path,
    output: &Path,
    background: Option<&str>,
    params: &DeformParams,
    quiet: bool,
) -> anyhow::Result<()> {
    refuse_overwrite(input, output)?;
    rigidcells::internal::io::check_folders([output])?;
    rigidcells::internal::render::png_path(output)?;
    let background = background.map(parse_color).transpose()?;
    let spec = read_spec::<2>(edit)?;
    let raster = rigidcells::internal::image::Raster::read_png(input)?;
    let (out, info) = rigidcells::internal::image::deform_image(&raster, &spec, params, background)
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
            "{} -> {}: {} foreground pixels ({} after), {} cells, {}",
            input.display(),
            output.display(),
            info.pixels.0,
            info.pixels.1,
            info.cells,
            info.iterations_in_words
        );
    }
    Ok(())
}

/// `R,G,B` with each in 0–255.
pub(super) fn parse_color(text: &str) -> anyhow::Result<[u8; 3]> {
    let parts: Vec<Option<u8>> = text.split(',').map(|v| v.trim().parse().ok()).collect();
    match parts.as_slice() {
        [Some(r), Some(g), Some(b)] => Ok([*r, *g, *b]),
        _ => Err(Error::param(format!(
            "--background {text}: expected R,G,B with each 0–255"
        ))
        .into()),
    }
}

pub(super) fn run_render(input: &Path, output: &Path, view: &View) -> anyhow::Result<()> {
    refuse_overwrite(input, output)?;
    rigidcells::internal::io::check_folders([output])?;
    rigidcells::internal::render::png_path(output)?;
    let image = render::render_file(input, view)?;
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

pub(super) fn run_apply(
    field: &Path,
    input: &Path,
    output: &Path,
    params: &pipeline::ApplyParams,
    quiet: bool,
) -> anyhow::Result<()> {
    refuse_overwrite(input, output)?;
    rigidcells::internal::io::check_folders([output])?;
    rigidcells::internal::io::check_output_format(input, output)?;
    let bar = Bar::new(quiet);
    let info = pipeline::apply_file(field, input, output, params, CHUNK, &bar)?;
    if !quiet {
        for w in &info.deform.warnings {
            eprintln!("warning: {w}");
        }
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

/// `--extent MINX,MINY,MAXX,MAXY` as four numbers.
pub(super) fn parse_extent(text: Option<&str>) -> anyhow::Result<Option<[f64; 4]>> {
    let Some(text) = text else {
        return Ok(None);
    };
    let numbers: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .unwrap_or_default();
    match <[f64; 4]>::try_from(numbers) {
        Ok(extent) => Ok(Some(extent)),
        Err(_) => Err(Error::param(format!(
            "--extent {text}: expected MINX,MINY,MAXX,MAXY, e.g. 636000,849000,637000,850000"
        ))
        .into()),
    }
}

/// `grid`: a saved field as a GeoTIFF of offsets for PROJ.
pub(super) fn run_grid(
    field: &Path,
    output: &Path,
    params: &rigidcells::internal::field::grid::GridParams,
    epsg: Option<u32>,
    quiet: bool,
) -> anyhow::Result<()> {
    let epsg = match epsg.map(u16::try_from) {
        None => None,
        Some(Ok(code)) => Some(code),
        Some(Err(_)) => Some(u16::MAX),
    };
    let info = pipeline::grid_file(field, output, params, epsg)?;
    if quiet {
        return Ok(());
    }
    let length = |v: f64| rigidcells::internal::human::length(v, info.cell);
    let place = |[x, y]: [f64; 2]| format!("{}, {}", length(x), length(y));
    // A deviation that rounds to nothing at the cells' precision has no place worth naming.
    let deviation = |d: rigidcells::internal::field::grid::Deviation| match length(d.value) {
        zero if zero == "0" => zero,
        text => format!("{text} at ({})", place(d.at)),
    };
    println!(
        "{} -> {}: {} × {} nodes {} apart, from ({}) to ({})",
        field.display(),
        output.display(),
        info.columns,
        info.rows,
        length(info.spacing),
        place(info.south_west),
        place(info.north_east)
    );
    if info.no_value > 0 {
        println!(
            "note: {} nodes lie beyond the field's margin and have no value; PROJ refuses \
             points next to them",
            rigidcells::internal::human::count(info.no_value as u64)
        );
    }
    println!(
        "largest offset: {} horizontal, {} vertical",
        length(info.largest_horizontal),
        length(info.largest_vertical)
    );
    println!(
        "largest deviation between nodes: horizontal {}, vertical {}",
        deviation(info.horizontal),
        deviation(info.vertical)
    );
    let absolute = std::path::absolute(output).unwrap_or_else(|_| output.to_path_buf());
    println!(
        "apply with PROJ: +proj=gridshift +grids={}",
        absolute.display()
    );
    Ok(())
}

/// `solve`: the field of an edit over several files taken as one, with the report and the
/// preview beside it; prints the warnings and `deform`'s summary.
pub(super) fn run_solve(args: &SolveArgs) -> anyhow::Result<()> {
    let outputs = args
        .reports
        .named(&[("--save-field", Some(&args.save_field))]);
    refuse_clashes(&args.inputs, &outputs)?;
    let chunk = pipeline::check_chunk(args.chunk)?;
    let spec = read_spec::<3>(&args.edit)?;
    let params = args.params()?;
    let outputs = pipeline::Outputs {
        chunk: Some(chunk),
        ..args
            .reports
            .outputs(Some(&args.save_field), &args.inputs[0])?
    };
    let bar = Bar::new(args.quiet);
    let (_, info, report) = pipeline::solve_files(
        &args.inputs,
        &spec,
        &params,
        (&outputs, args.same_crs),
        &bar,
    )?;
    if !args.quiet {
        for w in &report.warnings {
            eprintln!("warning: {w}");
        }
        print!(
            "{}",
            Summary {
                report: &report,
                file: &info
            }
        );
    }
    Ok(())
}

pub(super) fn run_info(input: &Path) -> anyhow::Result<()> {
    let info = rigidcells::internal::info::describe(input, &Bar::new(false))?;
    print!("{info}");
    Ok(())
}

/// The control points' table: the ten largest residuals and the RMSE.
pub(super) fn print_control_points(info: &rigidcells::internal::pipeline::DeformInfo) {
    let table = rigidcells::internal::control::table(
        &info.control_points,
        10,
        info.control_rounding.as_deref(),
    );
    if !table.is_empty() {
        println!("{table}");
    }
}

pub(super) fn run_demo(out: &Path, quiet: bool) -> anyhow::Result<()> {
    let demo = rigidcells::internal::demo::prepare(out)?;
    for job in &demo.shapes {
        let files = (
            job.input.as_path(),
            job.output.as_path(),
            job.edit.as_path(),
        );
        deform_file(files, &job.params, &Default::default(), quiet)?;
    }
    let p = &demo.picture;
    image_job(&p.input, &p.edit, &p.output, None, &p.params, quiet)?;
    if !quiet {
        println!(
            "demo: wrote bar.ply, soup.ply (inputs), bar_bent.ply (partition-of-unity RBF), soup_bent.ply (blend), bend.toml, \
             gingerbread.png, gingerbread.toml and gingerbread_bent.png in {}",
            out.display()
        );
    }
    Ok(())
}

/// `edit`: load the proxy, build the cells, serve the page until interrupted; the page's files
/// go into `out_dir` (default: the input's folder), checked before any work.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_edit(
    input: &Path,
    (port, out_dir): (u16, Option<&Path>),
    open: bool,
    proxy: usize,
    transfer: Transfer,
    cells: &CellArgs,
    quiet: bool,
) -> anyhow::Result<()> {
    if proxy == 0 {
        return Err(Error::param("--proxy 0: the page needs samples to show").into());
    }
    if let Some(dir) = out_dir {
        rigidcells::internal::edit::server::OutputFolder::new(input, Some(dir))?;
    }
    let options = cells.options(transfer);
    options.params()?;
    let scene = rigidcells::internal::edit::Scene::load(input, proxy, &Bar::new(quiet))?;
    let editor = rigidcells::internal::edit::Editor::new(scene, options)?;
    let mut server = rigidcells::internal::edit::server::Server::bind(editor, port, out_dir)?;
    if !quiet {
        server = server.logging(std::sync::Arc::new(|line: &str| eprintln!("{line}")));
    }
    println!("{}", server.url());
    if open {
        let _ = std::process::Command::new("xdg-open")
            .arg(server.url())
            .spawn();
    }
    server.run()?;
    Ok(())
}
