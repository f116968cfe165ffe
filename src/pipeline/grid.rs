//! A saved field as a correction grid other tools apply (`rigidcells grid`): the field sampled
//! on a grid (`crate::field::grid`) and written as a GeoTIFF (`crate::io::geotiff`).

use std::path::Path;

use crate::crs::{Crs, Unit};
use crate::error::{Error, Result};
use crate::field::SavedField;
use crate::field::grid::{GridInfo, GridParams, sample};
use crate::said::{Opt, Said};

/// Writes the field saved in `field` as a GeoTIFF grid of east, north and up offsets at
/// `output` (`.tif` or `.tiff`), for PROJ's `+proj=gridshift`; `epsg` is the CRS of the
/// field's coordinates when the user names it (a projected CRS's code), else the one the field
/// records (`grid_epsg`). The output appears whole or not at all; an output that names the
/// field is refused before any work.
pub fn grid_file(
    field: &Path,
    output: &Path,
    params: &GridParams,
    epsg: Option<u16>,
) -> Result<GridInfo> {
    super::files::refuse_clobbering(&[field], &[("the output", output)])?;
    let tiff = output
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff"));
    if !tiff {
        return Err(Error::param(format!(
            "{}: a correction grid is written as a GeoTIFF (.tif)",
            output.display()
        )));
    }
    if epsg.is_some_and(|c| c == 0 || c > 32766) {
        return Err(Error::param(
            Said::new()
                .set(Opt::Epsg, epsg.unwrap_or(0))
                .text(": a GeoTIFF key holds EPSG codes 1 to 32766"),
        ));
    }
    let saved = SavedField::<3>::load(field)?;
    let epsg = grid_epsg(field, saved.crs.as_ref(), epsg)?;
    let (grid, info) = sample(saved, params)?;
    let name = field.file_name().unwrap_or_default().to_string_lossy();
    let description = format!(
        "east, north and up offsets of the rigidcells field {name} (add them to a point of the \
         scan to move it as `rigidcells apply` does)"
    );
    crate::io::write_atomic(
        output,
        &crate::io::geotiff::offsets_tiff(&grid, epsg, &description),
    )?;
    Ok(info)
}

/// The EPSG code the grid declares: `asked` (`--epsg`), else the code of the system the field
/// records. A field solved in longitude and latitude is refused (the grid holds east and north
/// offsets in lengths), and so is an `--epsg` other than the code the field records.
fn grid_epsg(field: &Path, crs: Option<&Crs>, asked: Option<u16>) -> Result<Option<u16>> {
    let Some(crs) = crs else {
        return Ok(asked);
    };
    if crs.unit == Some(Unit::Degree) {
        return Err(Error::param(format!(
            "{}: the field was solved in longitude and latitude ({crs}); a grid of east and \
             north offsets needs projected coordinates: solve on the scan projected",
            field.display()
        )));
    }
    match (asked, crs.epsg) {
        (Some(a), Some(recorded)) if u32::from(a) != recorded => Err(Error::param(
            Said::new()
                .set(Opt::Epsg, a)
                .text(format!(
                    ": {} was solved in EPSG:{recorded} ({crs}); leave ",
                    field.display()
                ))
                .opt(Opt::Epsg)
                .text(" out to declare that system"),
        )),
        (Some(a), _) => Ok(Some(a)),
        (None, recorded) => Ok(recorded
            .and_then(|c| u16::try_from(c).ok())
            .filter(|&c| c <= 32766)),
    }
}
