//! Pass 1 of a streamed file: its bounds, the finest cell size when `--cells N` asks for a
//! count, and one pass that fills the cells' occupancy, gathers what the spec's regions
//! select and keeps the preview proxy.

use std::borrow::Cow;

use crate::cells::{BuildInfo, CellComplex, Decimation, Occupancy};
use crate::error::{Error, Result};
use crate::io::{Bounds, Chunk, Source};
use crate::progress::Observer;
use crate::rigid::Vect;
use crate::said::Said;
use crate::solve::Selections;
use crate::spec::EditSpec;

use super::checks::check_finite;
use super::{DeformParams, Proxy};

/// Pass 1 of [`deform_file`]: the cell complex of `source` (rerunning the pass with the
/// samples' own bounds when they overflow the header's) and what the spec's regions select.
/// With `solving`, the cells' forecast is checked against the solve's least memory
/// ([`crate::estimate::check_forecast`]) before the empty space is classified.
#[allow(clippy::too_many_arguments)]
pub(super) fn first_pass_cells(
    source: &mut dyn Source,
    spec: &EditSpec<3>,
    params: &DeformParams,
    chunk: usize,
    proxy_max: usize,
    solving: bool,
    notes: &mut Vec<Said>,
    observer: &dyn Observer,
) -> Result<(CellComplex<3>, BuildInfo, Selections<3>, Proxy)> {
    // What the spec asks of the input (its classes, its samples' indices), before any pass.
    Selections::new(spec, source.has_classes(), source.len())?;
    let (lo, hi) = match source.bounds_hint() {
        Some(b) => b,
        None => scan_bounds(source, chunk)?,
    };
    spec.check_polygons(
        ([lo.x, lo.y], [hi.x, hi.y]),
        source.crs().as_ref(),
        source.path(),
    )?;
    let target = params.build.target_cells;
    if target.is_some() {
        observer.stage("sizing", 0);
    }
    let mut proxy_bounds = None;
    let crate::cells::Sized {
        params: build,
        note,
        built,
    } = crate::cells::sized(&params.build, params.memory, || {
        let (points, triangles) = size_proxy(source, (lo, hi), chunk)?;
        proxy_bounds = Some(crate::cells::bounds(&points)?);
        Ok((points, triangles))
    })?;
    if target.is_some() {
        observer.finish();
    }
    notes.extend(note);
    // A mesh's proxy is all its vertices: when the file's bounds are theirs, the search's last
    // complex is the one this pass would fill.
    let built = built
        .filter(|_| !source.triangles().is_empty() && proxy_bounds.is_some_and(|b| b == (lo, hi)));
    let sized = &DeformParams { build, ..*params };
    let fill = built.is_none();
    let mut pass = first_pass(
        source,
        spec,
        sized,
        (lo, hi),
        chunk,
        proxy_max,
        fill,
        observer,
    )?;
    if let Some((complex, build_info)) = built {
        let FirstPass {
            selections, proxy, ..
        } = pass;
        notes.extend(crate::cells::shortfall(target, complex.len()));
        return Ok((complex, build_info, selections, proxy));
    }
    if pass.outside > 0 {
        notes.push(Said::from(format!(
            "{} samples lie outside the bounds in the file's header; the cells use the samples' \
             own bounds",
            pass.outside
        )));
        let b = pass.bounds;
        pass = first_pass(source, spec, sized, b, chunk, proxy_max, true, observer)?;
    }
    let FirstPass {
        mut occupancy,
        selections,
        positions,
        proxy,
        ..
    } = pass;
    observer.stage("voxelizing", 0);
    occupancy.add_triangles(&positions, source.triangles())?;
    drop(positions);
    let check = |forecast: &crate::cells::Forecast| match solving {
        true => params.check_forecast(forecast),
        false => Ok(()),
    };
    let (complex, build_info) = occupancy.finish_checked(&check)?;
    observer.finish();
    notes.extend(crate::cells::shortfall(target, complex.len()));
    Ok((complex, build_info, selections, proxy))
}

/// The points a cell size for `--cells N` is searched on ([`crate::cells::sized`]), gathered in
/// one extra pass over `source`: meshes keep their vertices (their triangles need them), point
/// clouds are decimated to one sample per occupied voxel of 1/1024 of the longest extent.
#[allow(clippy::type_complexity)]
fn size_proxy<'a>(
    source: &'a mut dyn Source,
    (lo, hi): Bounds,
    chunk_len: usize,
) -> Result<(Cow<'a, [Vect<3>]>, &'a [[u32; 3]])> {
    source.rewind()?;
    let keep_all = !source.triangles().is_empty();
    let mut proxy = Decimation::new(&lo, &hi);
    let mut chunk = Chunk::default();
    while source.read_samples(chunk_len, &mut chunk)? > 0 {
        check_finite(source.path(), &chunk)?;
        proxy.add(&chunk.positions, keep_all);
    }
    let source: &'a dyn Source = source;
    Ok((Cow::Owned(proxy.kept), source.triangles()))
}

struct FirstPass {
    occupancy: Occupancy<3>,
    selections: Selections<3>,
    /// All positions, kept only when the source has triangles.
    positions: Vec<Vect<3>>,
    /// The decimated samples (none when its bound is 0).
    proxy: Proxy,
    bounds: Bounds,
    outside: usize,
}

fn scan_bounds(source: &mut dyn Source, chunk_len: usize) -> Result<Bounds> {
    source.rewind()?;
    let mut chunk = Chunk::default();
    let mut lo = Vect::<3>::repeat(f64::INFINITY);
    let mut hi = Vect::<3>::repeat(f64::NEG_INFINITY);
    while source.read_samples(chunk_len, &mut chunk)? > 0 {
        check_finite(source.path(), &chunk)?;
        for p in &chunk.positions {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
    }
    if lo[0] > hi[0] {
        return Err(Error::format(source.path(), "the file holds no samples"));
    }
    Ok((lo, hi))
}

/// One pass over `source`: what the spec's regions select, the preview proxy, the samples'
/// bounds and, with `fill`, the cells' occupancy (and a mesh's positions for its triangles).
#[allow(clippy::too_many_arguments)]
fn first_pass(
    source: &mut dyn Source,
    spec: &EditSpec<3>,
    params: &DeformParams,
    (lo, hi): Bounds,
    chunk_len: usize,
    proxy_max: usize,
    fill: bool,
    observer: &dyn Observer,
) -> Result<FirstPass> {
    source.rewind()?;
    let mut occupancy = Occupancy::new(&lo, &hi, &params.build, params.memory)?;
    let mut selections = Selections::new(spec, source.has_classes(), source.len())?;
    let keep = fill && !source.triangles().is_empty();
    let mut positions = Vec::new();
    let mut proxy = (proxy_max > 0).then(|| Proxy::new(source.len(), proxy_max));
    let mut bounds = (
        Vect::<3>::repeat(f64::INFINITY),
        Vect::<3>::repeat(f64::NEG_INFINITY),
    );
    let mut outside = 0;
    let mut chunk = Chunk::default();
    observer.stage("reading", source.len());
    while source.read_samples(chunk_len, &mut chunk)? > 0 {
        check_finite(source.path(), &chunk)?;
        for p in &chunk.positions {
            bounds.0 = bounds.0.inf(p);
            bounds.1 = bounds.1.sup(p);
        }
        outside += if !fill {
            0
        } else if chunk.normals.is_empty() {
            occupancy.add_points(&chunk.positions)?
        } else {
            occupancy.add_oriented_points(&chunk.positions, &chunk.normals)?
        };
        let classes = (!chunk.classes.is_empty()).then_some(&chunk.classes[..]);
        selections.add(
            spec,
            occupancy.grid(),
            chunk.first,
            &chunk.positions,
            classes,
        );
        if keep {
            positions.extend_from_slice(&chunk.positions);
        }
        if let Some(proxy) = proxy.as_mut() {
            proxy.gather(&chunk);
        }
        observer.advance(chunk.len() as u64);
        crate::progress::stop_if_cancelled(observer)?;
    }
    observer.finish();
    Ok(FirstPass {
        occupancy,
        selections,
        positions,
        proxy: proxy.unwrap_or_default(),
        bounds,
        outside,
    })
}
