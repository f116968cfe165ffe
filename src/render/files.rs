//! What the pictures draw of files: which way is up in a file ([`up_of`]), a file drawn whole
//! or decimated (`rigidcells render`, [`render_file`]), and a streamed file's samples with
//! their colors and classes ([`colored_points`], for pictures and the editor).

use std::path::Path;

use super::{Image, View, render_annotated};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// The vertical axis of the file at `path` (module docs): a PLY or OBJ comment that names it,
/// else y for meshes and z for everything else.
pub fn up_of(path: &Path) -> usize {
    let ext = crate::io::extension(path).unwrap_or_default();
    if ext != "ply" && ext != "obj" {
        return 2;
    }
    // The header, or the first comments of an OBJ.
    let mut head = vec![0u8; 64 * 1024];
    let n = std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut head))
        .unwrap_or(0);
    let text = String::from_utf8_lossy(&head[..n]).to_ascii_lowercase();
    for line in text.lines() {
        let comment = match ext.as_str() {
            "ply" => line.trim().strip_prefix("comment "),
            _ => line.trim().strip_prefix('#'),
        };
        let Some(c) = comment else {
            if ext == "ply" && line.starts_with("end_header") {
                break;
            }
            continue;
        };
        let words: Vec<&str> = c
            .split(|ch: char| !ch.is_ascii_alphanumeric())
            .filter(|w| !w.is_empty())
            .collect();
        for (i, w) in words.iter().enumerate() {
            let axis = |a: &str| ["x", "y", "z"].iter().position(|x| *x == a);
            // `up z`, `z up`, `z_up`, `zup`.
            let named = match *w {
                "up" => words.get(i + 1).and_then(|a| axis(a)),
                "xup" | "yup" | "zup" => axis(&w[..1]),
                _ if words.get(i + 1) == Some(&"up") => axis(w),
                _ => None,
            };
            if let Some(a) = named {
                return a;
            }
        }
    }
    1
}

/// Samples [`render_file`] draws of a streamed file at most (every k-th sample).
pub const RENDER_POINTS: usize = 2_000_000;

/// What `rigidcells render` draws of the file `input`: a PLY, OBJ or XYZ file read whole
/// ([`crate::io::Document`]), its triangles or points in a PLY's vertex or face colors, else
/// gray; a LAS/LAZ scan streamed and decimated to [`RENDER_POINTS`], in its RGB or intensity;
/// with the triad and scale bar.
pub fn render_file(input: &Path, view: &View) -> Result<Image> {
    use crate::io::Colors;
    match crate::io::Document::read(input) {
        Ok(doc) => {
            // A PLY's vertex colors (a `cells` output's roles or strain, interpolated across
            // each triangle) or face colors, else gray.
            let triangles = doc.triangles();
            let colors = match crate::io::extension(input).as_deref() {
                Some("ply") => crate::io::colors(input)?,
                _ => None,
            }
            .filter(|c| match c {
                Colors::Vertices(v) => v.len() == doc.positions().len(),
                Colors::Triangles(t) => t.len() == triangles.len(),
            });
            let color = |t: usize, v: usize| match &colors {
                Some(Colors::Vertices(c)) => c[v],
                Some(Colors::Triangles(c)) => c[t],
                None => [200, 200, 200],
            };
            Ok(render_annotated(
                doc.positions(),
                triangles,
                doc.normals(),
                color,
                view,
            ))
        }
        Err(Error::UnsupportedFormat { .. }) => {
            let p = colored_points(input, RENDER_POINTS, &crate::progress::Silent)?;
            Ok(render_annotated(
                &p.points,
                &[],
                None,
                |_, i| p.colors[i],
                view,
            ))
        }
        Err(e) => Err(e),
    }
}

/// Every k-th sample of a streamed file with its color and LAS class: a decimated proxy for
/// pictures and the editor.
#[derive(Debug, Clone, Default)]
pub struct ColoredPoints {
    /// World coordinates.
    pub points: Vec<Vect<3>>,
    /// LAS RGB when the point format has it, else LAS intensity as gray, else a neutral gray;
    /// RGB scaled by the file's largest value, intensities by their 99th percentile (a few
    /// bright returns would leave the rest of a scan nearly black).
    pub colors: Vec<[u8; 3]>,
    /// LAS classes (empty for formats without them).
    pub classes: Vec<u8>,
    /// Samples from one kept to the next.
    pub stride: u64,
    /// Samples in the file.
    pub total: u64,
}

/// The intensity shown white: the 99th percentile of `intensities`, at least 1.
fn intensity_white(intensities: impl Iterator<Item = u16>) -> u16 {
    let mut all: Vec<u16> = intensities.collect();
    if all.is_empty() {
        return 1;
    }
    let k = (all.len() - 1) * 99 / 100;
    let (_, &mut white, _) = all.select_nth_unstable(k);
    white.max(1)
}

/// Every k-th sample of a streamed file (at most `max`) with its color and class
/// ([`ColoredPoints`]).
pub fn colored_points(
    input: &Path,
    max: usize,
    observer: &dyn crate::progress::Observer,
) -> Result<ColoredPoints> {
    let mut source = crate::io::open(input)?;
    let total = source.len();
    let stride = (total as usize).div_ceil(max.max(1)).max(1);
    let las = crate::io::LasHeader::read(input).ok();
    let mut chunk = crate::io::Chunk::default();
    let mut out = ColoredPoints {
        stride: stride as u64,
        total,
        ..Default::default()
    };
    let mut raw_colors = Vec::new();
    let mut index = 0usize;
    observer.stage("reading", total);
    loop {
        let n = source.read(1 << 16, &mut chunk)?;
        if n == 0 {
            break;
        }
        let first = (stride - index % stride) % stride;
        for i in (first..n).step_by(stride) {
            out.points.push(chunk.positions[i]);
            if let Some(&c) = chunk.classes.get(i) {
                out.classes.push(c);
            }
            let rec = (chunk.record_len > 0)
                .then(|| &chunk.raw[i * chunk.record_len..(i + 1) * chunk.record_len]);
            raw_colors.push(las.as_ref().zip(rec).map(|(h, r)| h.color(r)));
        }
        index += n;
        observer.advance(n as u64);
    }
    observer.finish();
    let top = match &las {
        Some(h) if !h.has_rgb() => intensity_white(raw_colors.iter().flatten().map(|c| c[0])),
        _ => raw_colors
            .iter()
            .flatten()
            .flatten()
            .fold(1u16, |a, &b| a.max(b)),
    };
    out.colors = raw_colors
        .into_iter()
        .map(|c| match c {
            Some(rgb) => rgb.map(|v| (v as u32 * 255 / top as u32).min(255) as u8),
            None => [200, 200, 200],
        })
        .collect();
    Ok(out)
}
