//! 2D image deformation (paper §7, Fig. 7): the foreground of a picture is the shape, the
//! cells are a quadtree over its pixels with the paper's 2D solver (3 degrees of freedom per
//! cell), and the output is drawn by warping a triangulation of the foreground's pixel grid.
//!
//! - **Shape.** The foreground is every pixel with alpha > 0, or, for an opaque picture, every
//!   pixel not of the named background color. Its samples are the pixel centers, in pixel
//!   coordinates: `x` to the right, `y` down from the top-left corner, so an edit spec's
//!   regions are read off the picture directly (a positive `degrees` turns from `+x` towards
//!   `+y`, clockwise on the screen).
//! - **Drawing.** Each foreground pixel is two triangles over its four corners; the corners
//!   move through the field and each output pixel whose center a warped triangle covers
//!   takes the input's color at the matching point of the unwarped triangle, by bilinear
//!   lookup among foreground texels (premultiplied by alpha, so the shape's border stays
//!   smooth and takes no background color). Neighboring triangles share their warped corners
//!   and edges are drawn inclusively, so the output has no cracks however the field stretches
//!   it, and it stays sharp (no resampling of resampled pixels).
//! - **Transfer.** The blend by default: pixels among fixed cells follow the identity exactly,
//!   so a fixed region's pixels keep their bytes; `--transfer rbf` is smoother between cells.
//!
//! The output has the input's size; corners moved outside it are clipped and counted.

use std::path::Path;

use crate::error::{Error, Result};
use crate::field::{Outside, Transfer, apply};
use crate::pipeline::DeformParams;
use crate::pipeline::stages::Cells;
use crate::progress::Silent;
use crate::rigid::Vect;
use crate::said::{Opt, Said};
use crate::spec::EditSpec;

/// An RGBA picture, 8 bits per channel, straight (not premultiplied) alpha.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Row by row from the top, four bytes per pixel.
    pub rgba: Vec<u8>,
}

impl Raster {
    /// The pixel at column `x`, row `y`.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = 4 * (y as usize * self.width as usize + x as usize);
        self.rgba[i..i + 4].try_into().expect("4 bytes")
    }

    /// Reads a PNG of any color type and bit depth.
    pub fn read_png(path: &Path) -> Result<Self> {
        let bad = |m: String| Error::Format {
            path: path.to_path_buf(),
            message: m,
        };
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
        decoder.set_transformations(png::Transformations::normalize_to_color8());
        let mut reader = decoder.read_info().map_err(|e| bad(e.to_string()))?;
        let size = reader
            .output_buffer_size()
            .ok_or_else(|| bad("the picture is too large".into()))?;
        // The header's dimensions are checked before they size an allocation: a damaged or
        // hostile header can claim 2³¹ rows of a few bytes of data.
        let (w, h) = (reader.info().width, reader.info().height);
        crate::memory::Budget::default().check(
            format!("{}: the {w} × {h} picture", path.display()),
            size as f64 + 4.0 * w as f64 * h as f64,
            "use a smaller picture",
        )?;
        let mut buf = vec![0; size];
        let info = reader
            .next_frame(&mut buf)
            .map_err(|e| bad(e.to_string()))?;
        buf.truncate(info.buffer_size());
        let rgba: Vec<u8> = match info.color_type {
            png::ColorType::Rgba => buf,
            png::ColorType::Rgb => buf
                .chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect(),
            png::ColorType::GrayscaleAlpha => buf
                .chunks_exact(2)
                .flat_map(|p| [p[0], p[0], p[0], p[1]])
                .collect(),
            png::ColorType::Grayscale => buf.iter().flat_map(|&g| [g, g, g, 255]).collect(),
            png::ColorType::Indexed => return Err(bad("unexpanded palette".into())),
        };
        Ok(Self {
            width: info.width,
            height: info.height,
            rgba,
        })
    }

    /// Writes the picture as an RGBA PNG, atomically.
    pub fn write_png(&self, path: &Path) -> Result<()> {
        crate::render::write_png(
            path,
            self.width,
            self.height,
            png::ColorType::Rgba,
            &self.rgba,
        )
    }
}

/// What [`deform_image`] did.
#[derive(Debug, Clone, Default)]
pub struct ImageInfo {
    /// Foreground pixels of the input and of the output.
    pub pixels: (usize, usize),
    /// Cells.
    pub cells: usize,
    /// Solver iterations (local-global and Gauss-Newton).
    pub iterations: usize,
    /// The iterations in words, by kind ([`crate::solve::SolverInfo::iterations_in_words`]).
    pub iterations_in_words: String,
    /// Warped pixel corners outside the picture.
    pub clipped: usize,
    /// Pixel triangles the field turned over (the map folds the picture over itself there).
    pub folded: usize,
    /// Warnings of the cells and constraints.
    pub warnings: Vec<Said>,
}

/// Deforms the foreground of `input` (alpha > 0, or not `background` when given) under the
/// pixel-coordinate `spec`.
pub fn deform_image(
    input: &Raster,
    spec: &EditSpec<2>,
    params: &DeformParams,
    background: Option<[u8; 3]>,
) -> Result<(Raster, ImageInfo)> {
    let (w, h) = (input.width as usize, input.height as usize);
    let opaque = input.rgba.chunks_exact(4).all(|p| p[3] == 255);
    let foreground: Vec<bool> = match (background, opaque) {
        (Some(bg), _) => input
            .rgba
            .chunks_exact(4)
            .map(|p| p[3] > 0 && p[..3] != bg)
            .collect(),
        (None, false) => input.rgba.chunks_exact(4).map(|p| p[3] > 0).collect(),
        (None, true) => {
            return Err(Error::input(
                Said::from(
                    "the picture has no transparent pixels: name its background color with ",
                )
                .set(Opt::Background, "R,G,B"),
            ));
        }
    };
    let samples: Vec<Vect<2>> = (0..w * h)
        .filter(|&i| foreground[i])
        .map(|i| Vect::<2>::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5))
        .collect();
    if samples.is_empty() {
        return Err(Error::input("the picture has no foreground pixels"));
    }
    let cells = Cells::samples(&samples, &[]);
    let staged = crate::pipeline::stages::run(cells, spec, params, &Silent)?;
    let solution = &staged.solution;
    let origin = staged.saved.field.origin;
    let deformer = staged
        .saved
        .deformer(None, params.rbf_tolerance, Outside::Extend)?;
    let mut info = ImageInfo {
        warnings: staged.warnings.clone(),
        cells: solution.complex.len(),
        iterations: solution.info.iterations,
        iterations_in_words: solution.info.iterations_in_words(),
        ..Default::default()
    };

    // The corners of the foreground pixels, numbered on first use, and where they go.
    let mut corner = vec![u32::MAX; (w + 1) * (h + 1)];
    let mut rest: Vec<Vect<2>> = Vec::new();
    let mut number = |x: usize, y: usize, rest: &mut Vec<Vect<2>>| {
        let slot = &mut corner[y * (w + 1) + x];
        if *slot == u32::MAX {
            *slot = rest.len() as u32;
            rest.push(Vect::<2>::new(x as f64, y as f64));
        }
        *slot as usize
    };
    let mut quads = Vec::with_capacity(samples.len());
    for i in (0..w * h).filter(|&i| foreground[i]) {
        let (x, y) = (i % w, i / w);
        quads.push([
            number(x, y, &mut rest),
            number(x + 1, y, &mut rest),
            number(x + 1, y + 1, &mut rest),
            number(x, y + 1, &mut rest),
        ]);
    }
    let mut moved = rest.clone();
    apply(&deformer, &origin, &mut moved);
    crate::pipeline::check_moved(0, &moved)?;
    info.clipped = moved
        .iter()
        .filter(|p| !(p.x >= 0.0 && p.x <= w as f64 && p.y >= 0.0 && p.y <= h as f64))
        .count();

    let mut out = Raster {
        width: input.width,
        height: input.height,
        rgba: match background {
            Some(bg) if opaque => bg
                .iter()
                .chain(&[255])
                .copied()
                .cycle()
                .take(4 * w * h)
                .collect(),
            _ => vec![0; 4 * w * h],
        },
    };
    let lookup = Lookup {
        input,
        foreground: &foreground,
        background: background.filter(|_| opaque),
    };
    for q in &quads {
        for tri in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            let (p, s) = (tri.map(|k| moved[k]), tri.map(|k| rest[k]));
            if (p[1] - p[0]).perp(&(p[2] - p[0])) * (s[1] - s[0]).perp(&(s[2] - s[0])) <= 0.0 {
                info.folded += 1;
            }
            draw(&mut out, &lookup, p, s);
        }
    }
    info.pixels = (
        samples.len(),
        (0..w * h)
            .filter(|&i| {
                out.rgba[4 * i + 3] > 0
                    && background.is_none_or(|bg| out.rgba[4 * i..4 * i + 3] != bg)
            })
            .count(),
    );
    Ok((out, info))
}

/// Bilinear lookup among the foreground texels of the input.
struct Lookup<'a> {
    input: &'a Raster,
    foreground: &'a [bool],
    /// The color under the shape, for opaque pictures.
    background: Option<[u8; 3]>,
}

impl Lookup<'_> {
    /// The color at the input point `s` (pixel coordinates).
    fn at(&self, s: &Vect<2>) -> [u8; 4] {
        let (w, h) = (self.input.width as i64, self.input.height as i64);
        let (u, v) = (s.x - 0.5, s.y - 0.5);
        let (x0, y0) = (u.floor(), v.floor());
        let (fu, fv) = (u - x0, v - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let mut premul = [0.0f64; 3];
        let mut alpha = 0.0;
        for (dx, dy, wt) in [
            (0, 0, (1.0 - fu) * (1.0 - fv)),
            (1, 0, fu * (1.0 - fv)),
            (0, 1, (1.0 - fu) * fv),
            (1, 1, fu * fv),
        ] {
            let (x, y) = (x0 + dx, y0 + dy);
            if wt == 0.0
                || x < 0
                || y < 0
                || x >= w
                || y >= h
                || !self.foreground[(y * w + x) as usize]
            {
                continue;
            }
            let p = self.input.pixel(x as u32, y as u32);
            let a = wt * p[3] as f64 / 255.0;
            for c in 0..3 {
                premul[c] += a * p[c] as f64;
            }
            alpha += a;
        }
        let round = |v: f64| v.round().clamp(0.0, 255.0) as u8;
        match self.background {
            Some(bg) => {
                let c: [u8; 3] =
                    std::array::from_fn(|c| round(premul[c] + (1.0 - alpha) * bg[c] as f64));
                [c[0], c[1], c[2], 255]
            }
            None if alpha > 0.0 => {
                let c: [u8; 3] = std::array::from_fn(|c| round(premul[c] / alpha));
                [c[0], c[1], c[2], round(255.0 * alpha)]
            }
            None => [0; 4],
        }
    }
}

/// Draws the warped triangle `p` of `out`, each covered pixel looked up at the matching point
/// of the rest triangle `s`.
fn draw(out: &mut Raster, lookup: &Lookup, p: [Vect<2>; 3], s: [Vect<2>; 3]) {
    let w = out.width as usize;
    crate::render::raster(p, out.width, out.height, |x, y, [l0, l1, l2]| {
        let color = lookup.at(&(s[0] * l0 + s[1] * l1 + s[2] * l2));
        let i = 4 * (y * w + x);
        out.rgba[i..i + 4].copy_from_slice(&color);
    });
}

/// The default transfer of [`deform_image`]: the blend keeps a fixed region's pixels exact.
pub const IMAGE_TRANSFER: Transfer = Transfer::Blend;
