//! LAS 1.0–1.4 and LAZ, point data record formats 0–10, and COPC outputs.
//!
//! Every point record is read and written as raw bytes; only `X Y Z` (the first 12 bytes of every
//! format) are rewritten, so intensity, flags, classes, GPS time, colors, NIR, wave packet
//! descriptors and extra bytes, described or not, pass through bit for bit (the `las` crate's
//! `Point` type is never used: it loses information).
//!
//! The layers, each below the ones that use it:
//!
//! - [`raw`]: the header and VLR headers as bytes, field by field;
//! - [`header`]: the validated header that everything else reads ([`LasHeader`]);
//! - [`coords`]: world coordinates to record integers and back, in a scale and offset;
//! - [`checks`]: what the `las` and `laz` crates size buffers by, checked before they read;
//! - [`reader`]: [`LasSource`], the records of a LAS or LAZ file;
//! - the writers, none of which knows another: [`mapped_sink`] (LAS → LAS from the memory map,
//!   without the `las` crate; the scale and offset change only when the moved coordinates would
//!   not fit, and the notes say so), [`crate_sink`] (LAZ in or out, through the `las` crate) and
//!   [`copc`] (a COPC, built while streaming);
//! - [`output`]: the one place that picks the writer for an output's name.

mod checks;
mod coords;
pub mod copc;
mod crate_sink;
mod header;
mod mapped_sink;
mod output;
mod raw;
mod reader;

use std::path::Path;
use std::sync::Arc;

use memmap2::Mmap;

pub use coords::{Encoded, decode_coordinates, encode_coordinates, frame_error};
pub use header::{LasHeader, SOFTWARE, VlrInfo, VlrRecord, crs_of};
pub use reader::LasSource;

use crate::error::Result;

/// Points the `las` crate decompresses or compresses per call: its parallel LAZ codec works on
/// the LAZ chunks of one call, so batches much larger than the pipeline's chunks keep both
/// cores busy (64k-point calls made a LAZ copy 45 % slower).
const LAZ_BATCH: usize = 1 << 20;

/// What the writers take from a LAS/LAZ input ([`reader`] makes it, [`output`] hands it on).
struct Input<'a> {
    /// The input file.
    path: &'a Path,
    /// Its parsed header.
    header: &'a LasHeader,
    /// Its records, memory-mapped, when it is uncompressed.
    map: Option<&'a Arc<Mmap>>,
    /// The largest return number read from it so far.
    max_return: u8,
    /// The `las` crate's header of the input, read only by the writers that need it.
    las_header: &'a dyn Fn() -> Result<las::Header>,
}
