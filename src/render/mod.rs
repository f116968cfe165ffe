//! A small software renderer for looking at inputs and results: no GPU, no window.
//!
//! Orthographic view from an azimuth and elevation, fitted to given bounds so that several
//! pictures (before and after) share one scale. Triangles are rasterized with a z-buffer and
//! flat-shaded by a headlight (two-sided: soups have no consistent orientation); points are
//! square splats, shaded by their normals when they have them and by depth when not, so that a
//! cloud reads as a surface. Images are RGB PNGs written atomically.
//!
//! **Which way is up.** The view turns about the file's vertical axis ([`View::up`]): z for
//! LAS/LAZ and XYZ scans, y for meshes (PLY, OBJ — the convention of the modelling tools and of
//! the Stanford and Blender models), unless a PLY header says otherwise with a comment
//! `up x|y|z` (or `x_up`…, as the demo's files do) or an OBJ comment `# up z` ([`up_of`]).
//!
//! **Annotations** are drawn with a 5×7 pixel font written here: an axis triad (x red, y green,
//! z blue) in the lower left corner, a scale bar of a round length in the lower right, a strain
//! legend with its numbers, and markers for pins and targets.

mod files;

use std::path::Path;

pub use files::{ColoredPoints, RENDER_POINTS, colored_points, render_file, up_of};

use crate::error::{Error, Result};
use crate::rigid::Vect;
use crate::said::{Opt, Said};

/// Where the camera looks from and the picture's size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Degrees about the vertical (z) axis, from the +x side towards +y.
    pub azimuth: f64,
    /// Degrees above the horizon.
    pub elevation: f64,
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// The vertical axis: 0 x, 1 y, 2 z.
    pub up: usize,
    /// Magnification about the picture's center (1: the whole box fits).
    pub zoom: f64,
}

/// Refuses a picture's path that does not name a PNG.
pub fn png_path(path: &Path) -> Result<()> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        Ok(())
    } else {
        Err(Error::param(format!(
            "{}: pictures are written as .png",
            path.display()
        )))
    }
}

impl View {
    /// Refuses a view no picture can have: a size outside 16 to 8192 pixels a side, an angle
    /// that is not finite, a zoom not above 0 or past 1e6.
    pub fn check(&self) -> Result<()> {
        let sides = 16..=8192;
        if !sides.contains(&self.width) || !sides.contains(&self.height) {
            return Err(Error::param(
                Said::new()
                    .set(Opt::Size, format!("{}x{}", self.width, self.height))
                    .text(": 16 to 8192 pixels each way"),
            ));
        }
        if !self.azimuth.is_finite() || !self.elevation.is_finite() {
            return Err(Error::param(
                Said::new()
                    .opt(Opt::Azimuth)
                    .text(" and ")
                    .opt(Opt::Elevation)
                    .text(" must be finite"),
            ));
        }
        if !(self.zoom.is_finite() && self.zoom > 0.0 && self.zoom <= 1e6) {
            return Err(Error::param(
                Said::new()
                    .set(Opt::Zoom, self.zoom)
                    .text(": a factor above 0, at most 1e6"),
            ));
        }
        if self.up > 2 {
            return Err(Error::param(
                Said::new().set(Opt::Up, self.up).text(": an axis, 0 to 2"),
            ));
        }
        Ok(())
    }
}

impl Default for View {
    fn default() -> Self {
        Self {
            azimuth: -60.0,
            elevation: 25.0,
            width: 640,
            height: 480,
            up: 2,
            zoom: 1.0,
        }
    }
}

/// An RGB image.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Row by row from the top, three bytes per pixel.
    pub rgb: Vec<u8>,
}

/// The background of every picture.
pub const BACKGROUND: [u8; 3] = [255, 255, 255];

impl Image {
    /// A `width × height` image of the background color.
    pub fn blank(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            rgb: BACKGROUND.repeat(width as usize * height as usize),
        }
    }

    /// The pixel at column `x`, row `y`.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    fn set(&mut self, x: usize, y: usize, c: [u8; 3]) {
        let i = 3 * (y * self.width as usize + x);
        self.rgb[i..i + 3].copy_from_slice(&c);
    }

    /// Pixels that are not the background.
    pub fn foreground(&self) -> usize {
        self.rgb
            .chunks_exact(3)
            .filter(|p| *p != BACKGROUND)
            .count()
    }

    /// `images` side by side, left to right, separated by a gray line.
    pub fn beside(images: &[Image]) -> Image {
        let gap = 2;
        let height = images.iter().map(|i| i.height).max().unwrap_or(0);
        let width = images.iter().map(|i| i.width).sum::<u32>()
            + gap * images.len().saturating_sub(1) as u32;
        let mut out = Image::blank(width, height);
        let mut left = 0;
        for (k, img) in images.iter().enumerate() {
            if k > 0 {
                for y in 0..height {
                    for g in 0..gap {
                        out.set((left + g) as usize, y as usize, [160, 160, 160]);
                    }
                }
                left += gap;
            }
            for y in 0..img.height {
                let row =
                    &img.rgb[3 * (y * img.width) as usize..3 * ((y + 1) * img.width) as usize];
                let at = 3 * (y * width + left) as usize;
                out.rgb[at..at + row.len()].copy_from_slice(row);
            }
            left += img.width;
        }
        out
    }

    /// Writes the image as a PNG, atomically.
    pub fn write_png(&self, path: &Path) -> Result<()> {
        crate::io::write_atomic(path, &self.png(path)?)
    }

    /// The image encoded as a PNG (`path` names it in errors).
    pub fn png(&self, path: &Path) -> Result<Vec<u8>> {
        png_bytes(
            path,
            self.width,
            self.height,
            png::ColorType::Rgb,
            &self.rgb,
        )
    }
}

/// Writes 8-bit pixels of `color` type as a PNG at `path`, atomically.
pub(crate) fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    color: png::ColorType,
    data: &[u8],
) -> Result<()> {
    crate::io::write_atomic(path, &png_bytes(path, width, height, color, data)?)
}

/// 8-bit pixels of `color` type encoded as a PNG (`path` names it in errors).
pub(crate) fn png_bytes(
    path: &Path,
    width: u32,
    height: u32,
    color: png::ColorType,
    data: &[u8],
) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    let fail = |e: png::EncodingError| Error::write(path, std::io::Error::other(e));
    {
        let mut enc = png::Encoder::new(&mut bytes, width, height);
        enc.set_color(color);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::High);
        let mut w = enc.write_header().map_err(fail)?;
        w.write_image_data(data).map_err(fail)?;
    }
    Ok(bytes)
}

/// An orthographic camera fitted to a box.
#[derive(Debug, Clone, Copy)]
pub struct Camera {
    /// Rows: the view's right, up and towards-the-viewer axes in world coordinates.
    axes: [Vect<3>; 3],
    center: Vect<3>,
    scale: f64,
    view: View,
}

impl Camera {
    /// The camera of `view` that shows the box `lo..hi` whole, with a margin.
    pub fn fit(lo: &Vect<3>, hi: &Vect<3>, view: &View) -> Self {
        let (az, el) = (view.azimuth.to_radians(), view.elevation.to_radians());
        // A right-handed frame (h1, h2, up) about the vertical axis.
        let e = |a: usize| Vect::<3>::from_fn(|i, _| if i == a % 3 { 1.0 } else { 0.0 });
        let u = view.up.min(2);
        let (h1, h2, vertical) = (e(u + 1), e(u + 2), e(u));
        let toward = (h1 * az.cos() + h2 * az.sin()) * el.cos() + vertical * el.sin();
        let right = h2 * az.cos() - h1 * az.sin();
        let up = toward.cross(&right);
        let axes = [right, up, toward];
        let center = (lo + hi) * 0.5;
        let (mut ex, mut ey) = (0.0f64, 0.0f64);
        for k in 0..8 {
            let corner = Vect::<3>::from_fn(|a, _| if k >> a & 1 == 1 { hi[a] } else { lo[a] });
            let d = corner - center;
            ex = ex.max(d.dot(&right).abs());
            ey = ey.max(d.dot(&up).abs());
        }
        let margin = 0.92;
        let zoom = if view.zoom.is_finite() && view.zoom > 0.0 {
            view.zoom
        } else {
            1.0
        };
        let scale = zoom
            * (margin * 0.5 * view.width as f64 / ex.max(1e-300))
                .min(margin * 0.5 * view.height as f64 / ey.max(1e-300));
        Self {
            axes,
            center,
            scale,
            view: *view,
        }
    }

    /// Pixel column, row and depth (larger is nearer the viewer) of `p`.
    pub fn project(&self, p: &Vect<3>) -> (f64, f64, f64) {
        let d = p - self.center;
        (
            0.5 * self.view.width as f64 + self.scale * d.dot(&self.axes[0]),
            0.5 * self.view.height as f64 - self.scale * d.dot(&self.axes[1]),
            d.dot(&self.axes[2]),
        )
    }

    /// The direction towards the viewer.
    pub fn toward(&self) -> Vect<3> {
        self.axes[2]
    }

    /// Pixels per world unit.
    pub fn scale(&self) -> f64 {
        self.scale
    }
}

/// A picture being drawn: the image and its depth buffer.
pub struct Canvas {
    /// The image so far.
    pub image: Image,
    depth: Vec<f64>,
    camera: Camera,
}

impl Canvas {
    /// A blank canvas for `camera`.
    pub fn new(camera: Camera) -> Self {
        let (w, h) = (camera.view.width, camera.view.height);
        Self {
            image: Image::blank(w, h),
            depth: vec![f64::NEG_INFINITY; w as usize * h as usize],
            camera,
        }
    }

    fn plot(&mut self, x: i64, y: i64, z: f64, c: [u8; 3]) {
        let (w, h) = (self.image.width as i64, self.image.height as i64);
        if x < 0 || y < 0 || x >= w || y >= h {
            return;
        }
        let i = (y * w + x) as usize;
        if z > self.depth[i] {
            self.depth[i] = z;
            self.image.set(x as usize, y as usize, c);
        }
    }

    /// Draws the triangles over `points`, flat-shaded, in the colors of their corners
    /// interpolated across them: `color(t, v)` for the corner of triangle `t` at vertex `v`
    /// (per-vertex colors ignore `t`, per-triangle colors `v`).
    pub fn triangles(
        &mut self,
        points: &[Vect<3>],
        triangles: &[[u32; 3]],
        color: impl Fn(usize, usize) -> [u8; 3],
    ) {
        let toward = self.camera.toward();
        for (t, tri) in triangles.iter().enumerate() {
            let [a, b, c] = tri.map(|i| points[i as usize]);
            let n = (b - a).cross(&(c - a));
            let len = n.norm();
            if len.is_nan() || len <= 0.0 {
                continue;
            }
            let light = 0.3 + 0.7 * (n.dot(&toward) / len).abs();
            let colors = tri.map(|v| color(t, v as usize).map(|c| c as f64 * light));
            let p = [a, b, c].map(|v| self.camera.project(&v));
            let corners = p.map(|q| Vect::<2>::new(q.0, q.1));
            let (w, h) = (self.image.width, self.image.height);
            raster(corners, w, h, |x, y, l| {
                let z = l[0] * p[0].2 + l[1] * p[1].2 + l[2] * p[2].2;
                let shade = std::array::from_fn(|k| {
                    (l[0] * colors[0][k] + l[1] * colors[1][k] + l[2] * colors[2][k])
                        .round()
                        .clamp(0.0, 255.0) as u8
                });
                self.plot(x as i64, y as i64, z, shade);
            });
        }
    }

    /// Draws `points` as square splats of `radius` pixels, `color(i)` for point `i`, shaded by
    /// `normals` (one per point) or, without them, by depth within `depth_range`.
    pub fn points(
        &mut self,
        points: &[Vect<3>],
        normals: Option<&[Vect<3>]>,
        radius: i64,
        depth_range: (f64, f64),
        color: impl Fn(usize) -> [u8; 3],
    ) {
        for (i, p) in points.iter().enumerate() {
            let normal = normals.map(|n| &n[i]);
            self.splat(p, radius, normal, depth_range, color(i));
        }
    }

    /// Draws a square of half edge `halves[i]` (world units) about each of `centers`, facing the
    /// viewer, in `color(i)`, shaded by depth within `depth_range`: cells seen from outside.
    pub fn squares(
        &mut self,
        centers: &[Vect<3>],
        halves: &[f64],
        depth_range: (f64, f64),
        color: impl Fn(usize) -> [u8; 3],
    ) {
        for (i, (c, h)) in centers.iter().zip(halves).enumerate() {
            let radius = (h * self.camera.scale).round().max(0.0) as i64;
            self.splat(c, radius, None, depth_range, color(i));
        }
    }

    /// One square splat of `radius` pixels about `p`, shaded by its `normal` when it has one and
    /// by depth within `(near, far)` when not.
    fn splat(
        &mut self,
        p: &Vect<3>,
        radius: i64,
        normal: Option<&Vect<3>>,
        (near, far): (f64, f64),
        color: [u8; 3],
    ) {
        let (x, y, z) = self.camera.project(p);
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            return;
        }
        let light = match normal {
            Some(n) if n.norm() > 0.0 => {
                0.3 + 0.7 * (n.dot(&self.camera.toward()) / n.norm()).abs()
            }
            _ => 0.45 + 0.55 * ((z - far) / (near - far).max(1e-300)).clamp(0.0, 1.0),
        };
        let shade = color.map(|v| (v as f64 * light).round() as u8);
        let (cx, cy) = (x.floor() as i64, y.floor() as i64);
        for dy in -radius..=radius {
            for dx in -radius..=radius {
                self.plot(cx + dx, cy + dy, z, shade);
            }
        }
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Sets pixel `(x, y)` regardless of depth (annotations), when it lies in the picture.
    pub fn paint(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && x < self.image.width as i64 && y < self.image.height as i64 {
            self.image.set(x as usize, y as usize, c);
        }
    }

    /// A line from `a` to `b` (pixels), `width` pixels wide, over everything.
    pub fn line(&mut self, a: (f64, f64), b: (f64, f64), width: i64, c: [u8; 3]) {
        let steps = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as i64).clamp(1, 100_000);
        for s in 0..=steps {
            let t = s as f64 / steps as f64;
            let (x, y) = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
            for dy in 0..width {
                for dx in 0..width {
                    self.paint(
                        x.round() as i64 + dx - width / 2,
                        y.round() as i64 + dy - width / 2,
                        c,
                    );
                }
            }
        }
    }

    /// `text` in the 5×7 font at pixel `(x, y)` (its top left), scaled by `size`, over a
    /// white box so that it reads over anything.
    pub fn text(&mut self, x: i64, y: i64, text: &str, size: i64, c: [u8; 3]) {
        let w = text_width(text, size);
        for dy in -size..8 * size {
            for dx in -size..w + size {
                self.paint(x + dx, y + dy, BACKGROUND);
            }
        }
        for (k, ch) in text.chars().enumerate() {
            let rows = glyph(ch);
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..5 {
                    if bits >> (4 - col) & 1 == 1 {
                        for sy in 0..size {
                            for sx in 0..size {
                                self.paint(
                                    x + (k as i64 * 6 + col) * size + sx,
                                    y + r as i64 * size + sy,
                                    c,
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// A marker at the world point `p`: a ring of `radius` pixels in `c`.
    pub fn marker(&mut self, p: &Vect<3>, radius: f64, c: [u8; 3]) {
        let (x, y, _) = self.camera.project(p);
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        let n = (radius * 8.0).ceil().max(8.0) as usize;
        for k in 0..n {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            for r in [radius, radius + 1.0] {
                self.paint(
                    (x + r * a.cos()).round() as i64,
                    (y + r * a.sin()).round() as i64,
                    c,
                );
            }
        }
        self.paint(x.round() as i64, y.round() as i64, c);
    }

    /// The annotations every picture carries: the axis triad (x red, y green, z blue) in the
    /// lower left corner and a scale bar of a round length in the lower right.
    pub fn annotate(&mut self) {
        let h = self.image.height as f64;
        let w = self.image.width as f64;
        let size = if self.image.width >= 480 { 2 } else { 1 };
        let arm = 20.0 * size as f64;
        let origin = (14.0 + arm, h - 14.0 - arm);
        let colors = [[220, 40, 40], [30, 160, 30], [40, 70, 230]];
        for (a, name) in ["x", "y", "z"].iter().enumerate() {
            let d = Vect::<3>::from_fn(|i, _| if i == a { 1.0 } else { 0.0 });
            let (dx, dy) = (d.dot(&self.camera.axes[0]), -d.dot(&self.camera.axes[1]));
            let tip = (origin.0 + arm * dx, origin.1 + arm * dy);
            self.line(origin, tip, size, colors[a]);
            // The label beyond the tip, unless the axis points at the viewer.
            let len = dx.hypot(dy);
            if len > 0.25 {
                let reach = arm * len + 7.0 * size as f64;
                let at = (origin.0 + reach * dx / len, origin.1 + reach * dy / len);
                self.text(
                    at.0 as i64 - 2 * size,
                    at.1 as i64 - 3 * size,
                    name,
                    size,
                    colors[a],
                );
            }
        }
        // A scale bar of 1, 2 or 5 times a power of ten, about a sixth of the width.
        let want = w / 6.0 / self.camera.scale;
        if want.is_finite() && want > 0.0 {
            let p = 10f64.powf(want.log10().floor());
            let len = [1.0, 2.0, 5.0, 10.0]
                .iter()
                .map(|m| m * p)
                .rfind(|l| *l <= want)
                .unwrap_or(p);
            let px = len * self.camera.scale;
            let (x1, y) = (w - 12.0, h - 12.0 - 4.0 * size as f64);
            let x0 = x1 - px;
            let ink = [40, 40, 40];
            self.line((x0, y), (x1, y), size, ink);
            self.line((x0, y - 4.0), (x0, y + 4.0), size, ink);
            self.line((x1, y - 4.0), (x1, y + 4.0), size, ink);
            let label = number(len);
            let tw = text_width(&label, size);
            self.text(
                ((x0 + x1) * 0.5) as i64 - tw / 2,
                (y - 6.0 - 8.0 * size as f64) as i64,
                &label,
                size,
                ink,
            );
        }
    }

    /// A vertical color bar for values 0..`top` colored by [`heat`], with its numbers, at the
    /// right edge: the strain legend.
    pub fn legend(&mut self, top: f64, title: &str) {
        let size = if self.image.width >= 480 { 2 } else { 1 };
        let (w, h) = (self.image.width as i64, self.image.height as i64);
        let (bar_w, bar_h) = (8 * size, (h / 2).max(20));
        let x = w - 12 - bar_w - text_width(&number(top), size);
        let y0 = (h - bar_h) / 2;
        for dy in 0..bar_h {
            let c = heat(1.0 - dy as f64 / (bar_h - 1).max(1) as f64);
            for dx in 0..bar_w {
                self.paint(x + dx, y0 + dy, c);
            }
        }
        let ink = [40, 40, 40];
        self.text(x + bar_w + 3, y0 - 3 * size, &number(top), size, ink);
        self.text(x + bar_w + 3, y0 + bar_h - 4 * size, "0", size, ink);
        let tw = text_width(title, size);
        self.text(x + bar_w / 2 - tw / 2, y0 - 12 * size, title, size, ink);
    }

    /// The depth range of `points` in this camera: (nearest, farthest).
    pub fn depth_range(&self, points: &[Vect<3>]) -> (f64, f64) {
        points.iter().fold((f64::MIN, f64::MAX), |(n, f), p| {
            let z = self.camera.project(p).2;
            (n.max(z), f.min(z))
        })
    }
}

/// Calls `f(x, y, [l0, l1, l2])` for every pixel of a `width × height` picture whose center
/// lies in the triangle `p` (pixel coordinates), with the center's barycentric coordinates.
/// Edges are inclusive to a tolerance of rounding, so triangles that share an edge leave no
/// crack between them (the pixels on it are drawn by both); degenerate triangles draw nothing.
/// The one rasterizer of the renderer and of the 2D picture warp.
pub(crate) fn raster(
    p: [Vect<2>; 3],
    width: u32,
    height: u32,
    mut f: impl FnMut(usize, usize, [f64; 3]),
) {
    let area = (p[1] - p[0]).perp(&(p[2] - p[0]));
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let lo = p[0].inf(&p[1]).inf(&p[2]);
    let hi = p[0].sup(&p[1]).sup(&p[2]);
    let span = |lo: f64, hi: f64, n: u32| {
        (
            (lo - 0.5).ceil().max(0.0) as i64,
            ((hi - 0.5).floor() as i64).min(n as i64 - 1),
        )
    };
    let ((x0, x1), (y0, y1)) = (span(lo.x, hi.x, width), span(lo.y, hi.y, height));
    let eps = -1e-9;
    for y in y0..=y1 {
        for x in x0..=x1 {
            let c = Vect::<2>::new(x as f64 + 0.5, y as f64 + 0.5);
            let l0 = (p[1] - c).perp(&(p[2] - c)) / area;
            let l1 = (p[2] - c).perp(&(p[0] - c)) / area;
            let l2 = 1.0 - l0 - l1;
            if l0 >= eps && l1 >= eps && l2 >= eps {
                f(x as usize, y as usize, [l0, l1, l2]);
            }
        }
    }
}

/// The width in pixels of `text` in the 5×7 font at `size`.
pub fn text_width(text: &str, size: i64) -> i64 {
    (text.chars().count() as i64 * 6 - 1).max(0) * size
}

/// A number for a label: up to three significant digits, in exponent form when very large or
/// small.
pub fn number(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        return "0".into();
    }
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.2e}");
    }
    let decimals = (2 - a.log10().floor() as i64).clamp(0, 6) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// The rows of the 5×7 glyph of `c` (bit 4 the leftmost column); unknown characters are
/// blank.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_lowercase() {
        '0' => [0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e],
        '1' => [0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e],
        '2' => [0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f],
        '3' => [0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e],
        '4' => [0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02],
        '5' => [0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e],
        '6' => [0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e],
        '7' => [0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e],
        '9' => [0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c],
        '.' => [0, 0, 0, 0, 0, 0x0c, 0x0c],
        '-' => [0, 0, 0, 0x1f, 0, 0, 0],
        '+' => [0, 0x04, 0x04, 0x1f, 0x04, 0x04, 0],
        'a' => [0, 0, 0x0e, 0x01, 0x0f, 0x11, 0x0f],
        'e' => [0, 0, 0x0e, 0x11, 0x1f, 0x10, 0x0e],
        'i' => [0x04, 0, 0x0c, 0x04, 0x04, 0x04, 0x0e],
        'n' => [0, 0, 0x16, 0x19, 0x11, 0x11, 0x11],
        'p' => [0, 0, 0x1e, 0x11, 0x1e, 0x10, 0x10],
        'r' => [0, 0, 0x16, 0x19, 0x10, 0x10, 0x10],
        's' => [0, 0, 0x0e, 0x10, 0x0e, 0x01, 0x1e],
        't' => [0x08, 0x08, 0x1c, 0x08, 0x08, 0x09, 0x06],
        'g' => [0, 0, 0x0f, 0x11, 0x0f, 0x01, 0x0e],
        'x' => [0, 0, 0x11, 0x0a, 0x04, 0x0a, 0x11],
        'y' => [0, 0, 0x11, 0x11, 0x0f, 0x01, 0x0e],
        'z' => [0, 0, 0x1f, 0x02, 0x04, 0x08, 0x1f],
        _ => [0; 7],
    }
}

/// Blue (0) through purple to red (1): the paper's strain colors.
pub fn heat(t: f64) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    [(40.0 + 215.0 * t) as u8, 40, (255.0 - 215.0 * t) as u8]
}

/// A splat radius in pixels for `n` points spread over `area` square pixels: splats about as
/// wide as the points' spacing, so that a surface reads closed, from 1 to 9 pixels across.
pub fn splat_radius(n: usize, area: f64) -> i64 {
    (0.75 * (area / n.max(1) as f64).sqrt())
        .round()
        .clamp(0.0, 4.0) as i64
}

/// The bounds of the finite ones among `points`, or `None` for none: a picture frames what it
/// can draw, where an input's own bounds ([`crate::cells::bounds`]) refuse a point that is not
/// finite.
pub fn finite_bounds(points: &[Vect<3>]) -> Option<(Vect<3>, Vect<3>)> {
    points
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .fold(None, |acc, p| match acc {
            None => Some((*p, *p)),
            Some((lo, hi)) => Some((lo.inf(p), hi.sup(p))),
        })
}

/// Renders a mesh (with `triangles`) or a point cloud (without), colored `color`, in `view`
/// fitted to `fit` (the points' own bounds when `None`). `color(t, v)` colors the corner of
/// triangle `t` at vertex `v` (interpolated across the triangle), or point `v` of a cloud
/// (`t == v`).
pub fn render(
    points: &[Vect<3>],
    triangles: &[[u32; 3]],
    normals: Option<&[Vect<3>]>,
    color: impl Fn(usize, usize) -> [u8; 3],
    view: &View,
    fit: Option<(Vect<3>, Vect<3>)>,
) -> Image {
    let Some((lo, hi)) = fit.or_else(|| finite_bounds(points)) else {
        return Image::blank(view.width, view.height);
    };
    let mut canvas = Canvas::new(Camera::fit(&lo, &hi, view));
    if triangles.is_empty() {
        let range = canvas.depth_range(points);
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in points {
            let (x, y, _) = canvas.camera.project(p);
            (lo, hi) = ([lo[0].min(x), lo[1].min(y)], [hi[0].max(x), hi[1].max(y)]);
        }
        let area = ((hi[0] - lo[0]) * (hi[1] - lo[1])).max(1.0);
        canvas.points(
            points,
            normals,
            splat_radius(points.len(), area),
            range,
            |i| color(i, i),
        );
    } else {
        canvas.triangles(points, triangles, color);
    }
    canvas.image
}

/// [`render`] with the axis triad and the scale bar ([`Canvas::annotate`]): what `rigidcells
/// render` writes.
pub fn render_annotated(
    points: &[Vect<3>],
    triangles: &[[u32; 3]],
    normals: Option<&[Vect<3>]>,
    color: impl Fn(usize, usize) -> [u8; 3],
    view: &View,
) -> Image {
    let Some((lo, hi)) = finite_bounds(points) else {
        return Image::blank(view.width, view.height);
    };
    let camera = Camera::fit(&lo, &hi, view);
    let mut canvas = Canvas {
        image: render(points, triangles, normals, color, view, Some((lo, hi))),
        depth: Vec::new(),
        camera,
    };
    canvas.annotate();
    canvas.image
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(at: Vect<3>) -> (Vec<Vect<3>>, Vec<[u32; 3]>) {
        let p: Vec<Vect<3>> = (0..8)
            .map(|k| at + Vect::<3>::new((k & 1) as f64, (k >> 1 & 1) as f64, (k >> 2 & 1) as f64))
            .collect();
        let tris = crate::cells::BOX_QUADS
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        (p, tris)
    }

    /// A unit cube seen from the front fills the middle of the picture and not its corners; its
    /// copy moved right (in a view fitted to both) lights pixels further right.
    #[test]
    fn a_cube_lands_where_the_camera_puts_it_and_moves_with_it() {
        let view = View {
            azimuth: -90.0,
            elevation: 0.0,
            width: 200,
            height: 100,
            ..Default::default()
        };
        let (p, t) = cube(Vect::<3>::zeros());
        let fit = Some((Vect::<3>::zeros(), Vect::<3>::new(3.0, 1.0, 1.0)));
        let image = render(&p, &t, None, |_, _| [200, 200, 200], &view, fit);
        // Looking along +y from −y: x runs left to right over the fitted 0..3.
        let column = |img: &Image| {
            let (mut sum, mut n) = (0.0, 0usize);
            for y in 0..img.height {
                for x in 0..img.width {
                    if img.pixel(x, y) != BACKGROUND {
                        sum += x as f64;
                        n += 1;
                    }
                }
            }
            sum / n as f64
        };
        assert_ne!(image.pixel(100 - 56, 50), BACKGROUND, "the cube's middle");
        assert_eq!(image.pixel(2, 2), BACKGROUND);
        assert_eq!(image.pixel(197, 50), BACKGROUND);
        let width = 0.92 * 200.0 / 3.0;
        assert!((image.foreground() as f64 - width * width).abs() < 0.05 * width * width);
        let (moved, _) = cube(Vect::<3>::new(2.0, 0.0, 0.0));
        let shifted = render(&moved, &t, None, |_, _| [200, 200, 200], &view, fit);
        assert_ne!(shifted, image);
        let shift = column(&shifted) - column(&image);
        assert!((shift - 2.0 * width).abs() < 2.0, "moved {shift} px");
        // As points, the cube's corners light splats at its corners.
        let cloud = render(&p, &[], None, |_, _| [0, 0, 200], &view, fit);
        assert!(cloud.foreground() > 8);
    }
}
