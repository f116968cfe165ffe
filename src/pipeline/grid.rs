//! A saved field as a correction grid other tools apply (`rigidcells grid`): the field sampled
//! on a grid (`crate::field::grid`) and written as a GeoTIFF (`crate::io::geotiff`).

use std::path::Path;

use crate::error::{Error, Result};
use crate::field::SavedField;
use crate::field::grid::{GridInfo, GridParams, sample};

/// Writes the field saved in `field` as a GeoTIFF grid of east, north and up offsets at
/// `output` (`.tif` or `.tiff`), for PROJ's `+proj=gridshift`; `epsg` is the CRS of the
/// field's coordinates when known (a projected CRS's code). The output appears whole or not
/// at all; an output that names the field is refused before any work.
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
        return Err(Error::Param(format!(
            "{}: a correction grid is written as a GeoTIFF (.tif)",
            output.display()
        )));
    }
    if epsg.is_some_and(|c| c == 0 || c > 32766) {
        return Err(Error::Param(format!(
            "--epsg {}: a GeoTIFF key holds EPSG codes 1 to 32766",
            epsg.unwrap_or(0)
        )));
    }
    let saved = SavedField::<3>::load(field)?;
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
