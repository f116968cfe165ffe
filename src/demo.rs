//! The demo's inputs (`rigidcells demo`): a bar, a non-manifold soup with loose parts, and the
//! 2D picture of the paper's Fig. 7, each with its edit spec — generated and written here, so
//! that the command line, Rust callers and Python make the same files; the caller deforms
//! them ([`crate::pipeline::deform_file`], [`crate::image::deform_image`]) and reports.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::field::Transfer;
use crate::pipeline::{DeformParams, Options};

/// The edit of the bar and the soup: the left end fixed, the right end turned 90° upwards.
pub(crate) const BEND_SPEC: &str = "# Bend the bar 90 degrees upwards: fix the left end, turn the right end.\n\
    [[fixed]]\nbox = { min = [-0.1, -0.1, -0.1], max = [0.5, 1.1, 1.1] }\n\n\
    [[handle]]\nbox = { min = [9.5, -0.1, -0.1], max = [10.1, 1.1, 1.1] }\n\
    rotate = { axis = [0.0, 1.0, 0.0], degrees = -90.0 }\n\
    translate = [-3.4, 0.0, 5.9]\n";

/// One deformation of the demo: its input, output and edit spec, and how to run it.
#[derive(Debug, Clone)]
pub struct DemoJob {
    /// The generated input.
    pub input: PathBuf,
    /// Where its result goes.
    pub output: PathBuf,
    /// The edit spec.
    pub edit: PathBuf,
    /// The parameters (the bar with the PU transfer, the soup with the blend; the picture with
    /// [`crate::image::IMAGE_TRANSFER`]).
    pub params: DeformParams,
}

/// The demo's jobs: the two 3D shapes, then the picture.
#[derive(Debug, Clone)]
pub struct Demo {
    /// `bar.ply` and `soup.ply`, bent by `bend.toml`.
    pub shapes: Vec<DemoJob>,
    /// `gingerbread.png`, its arms moved by `gingerbread.toml`.
    pub picture: DemoJob,
}

/// Writes the demo's inputs and edit specs into `out` (created if missing).
pub fn prepare(out: &Path) -> Result<Demo> {
    std::fs::create_dir_all(out).map_err(|e| Error::write(out, e))?;
    let size = [10.0, 1.0, 1.0];
    let edit = out.join("bend.toml");
    crate::io::write_atomic(&edit, BEND_SPEC.as_bytes())?;
    let mut shapes = Vec::new();
    for (name, mesh, transfer) in [
        ("bar", data_gen::bar(size, 8.0), Transfer::Pu),
        ("soup", data_gen::soup(size, 8.0), Transfer::Blend),
    ] {
        let input = out.join(format!("{name}.ply"));
        data_gen::write_ply(&input, &mesh, true).map_err(|e| Error::write(&input, e))?;
        shapes.push(DemoJob {
            output: out.join(format!("{name}_bent.ply")),
            input,
            edit: edit.clone(),
            params: Options {
                cell_size: Some(0.25),
                transfer,
                ..Default::default()
            }
            .params()?,
        });
    }
    // The 2D picture of paper Fig. 7: a gingerbread figure with its arms moved.
    let (width, height, rgba) = data_gen::gingerbread();
    let figure = crate::image::Raster {
        width,
        height,
        rgba,
    };
    let picture = DemoJob {
        input: out.join("gingerbread.png"),
        output: out.join("gingerbread_bent.png"),
        edit: out.join("gingerbread.toml"),
        params: Options {
            transfer: crate::image::IMAGE_TRANSFER,
            ..Default::default()
        }
        .params()?,
    };
    figure.write_png(&picture.input)?;
    crate::io::write_atomic(&picture.edit, data_gen::GINGERBREAD_SPEC.as_bytes())?;
    Ok(Demo { shapes, picture })
}
