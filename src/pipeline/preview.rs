//! The `--preview` picture of a deformation: the input and the output side by side (and the
//! deformed cells colored by strain), all in one camera so that they share scale and framing.
//!
//! Samples are colored by the role of their cell: fixed gray, handles yellow, the rest blue;
//! a mesh's triangles are drawn shaded (its vertices when the proxy holds them all), each
//! vertex's color interpolated across them, so a triangle spanning two regions shows both. Pins are magenta rings, soft targets
//! (control points) orange: at their points before, at where they were sent after. The strain
//! panel carries a legend with its numbers; every panel an axis triad and a scale bar.

use super::Proxy;
use crate::render::{self, Camera, Canvas, Image, View};
use crate::rigid::Vect;
use crate::solve::{Role, Solution};

/// Fixed samples.
pub const FIXED: [u8; 3] = [150, 150, 150];
/// Handle samples.
pub const HANDLE: [u8; 3] = [240, 200, 30];
/// The other samples.
pub const FREE: [u8; 3] = [90, 140, 220];
/// Pins.
pub const PIN: [u8; 3] = [200, 30, 200];
/// Soft targets.
pub const TARGET: [u8; 3] = [240, 120, 0];

/// The preview of `solution` over the samples of `proxy` (module docs), each panel `view`.
pub fn preview(solution: &Solution<3>, proxy: &Proxy, view: &View, strain: bool) -> Image {
    let origin = solution.constraints.origin;
    let colors: Vec<[u8; 3]> = proxy
        .before
        .iter()
        .map(|p| match solution.role_at(p) {
            Some(Role::Fixed) => FIXED,
            Some(Role::Handle(_)) => HANDLE,
            _ => FREE,
        })
        .collect();
    let complex = &solution.complex;
    // The cells as deformed: their centers and half sizes (for the frame and the strain panel).
    let centers: Vec<Vect<3>> = solution.motions.iter().map(|m| m.pos + origin).collect();
    let halves: Vec<f64> = complex.cells.iter().map(|c| c.half).collect();
    let mut framed: Vec<Vect<3>> = proxy.before.iter().chain(&proxy.after).copied().collect();
    if strain {
        for (c, h) in centers.iter().zip(&halves) {
            framed.push(c.add_scalar(-h));
            framed.push(c.add_scalar(*h));
        }
    }
    let Some((lo, hi)) = render::finite_bounds(&framed) else {
        let blank = Image::blank(view.width, view.height);
        return Image::beside(&[blank.clone(), blank]);
    };
    let camera = Camera::fit(&lo, &hi, view);
    let c = &solution.constraints;
    let pins: Vec<(Vect<3>, Vect<3>)> = c
        .pins
        .iter()
        .map(|p| (p.point + origin, p.wanted + origin))
        .collect();
    let targets: Vec<(Vect<3>, Vect<3>)> = c
        .targets
        .iter()
        .map(|t| (t.from + origin, t.wanted + origin))
        .collect();
    let side = |points: &[Vect<3>], after: bool| {
        let mut canvas = Canvas::new(camera);
        if proxy.triangles.is_empty() {
            let range = canvas.depth_range(points);
            let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
            for p in points {
                let (x, y, _) = camera.project(p);
                (lo, hi) = ([lo[0].min(x), lo[1].min(y)], [hi[0].max(x), hi[1].max(y)]);
            }
            let area = ((hi[0] - lo[0]) * (hi[1] - lo[1])).max(1.0);
            let radius = render::splat_radius(points.len(), area);
            canvas.points(points, None, radius, range, |i| colors[i]);
        } else {
            canvas.triangles(points, &proxy.triangles, |_, v| colors[v]);
        }
        let ring = 4.0 + view.width as f64 / 160.0;
        for (list, color) in [(&pins, PIN), (&targets, TARGET)] {
            for (from, to) in list {
                canvas.marker(if after { to } else { from }, ring, color);
            }
        }
        canvas.annotate();
        canvas.image
    };
    let mut panels = vec![side(&proxy.before, false), side(&proxy.after, true)];
    if strain {
        let values = crate::solve::cell_strain(complex, &solution.motions);
        let top = values.iter().cloned().fold(0.0, f64::max);
        let mut canvas = Canvas::new(camera);
        let range = canvas.depth_range(&centers);
        let scale = top.max(f64::MIN_POSITIVE);
        canvas.squares(&centers, &halves, range, |i| {
            render::heat(values[i] / scale)
        });
        canvas.legend(top, "strain");
        canvas.annotate();
        panels.push(canvas.image);
    }
    Image::beside(&panels)
}
