//! The one place that picks the writer of a LAS/LAZ input's output, by the output's name:
//!
//! - `*.copc.laz`: [`CopcSink`], a COPC built while streaming;
//! - `*.las` from an uncompressed (memory-mapped) input: [`MappedSink`], the input's bytes with
//!   new coordinates, without the `las` crate;
//! - any other `*.las` or `*.laz`: [`CrateSink`], through the `las` crate's LAZ codec.
//!
//! It also fixes the output's frame (scale and offset): the input's, re-framed on the axes where
//! the moved coordinates (known after a first attempt overflowed) do not fit it.

use std::path::Path;

use super::Input;
use super::coords::{Frame, reframe};
use super::copc::{CopcSink, is_copc};
use super::crate_sink::CrateSink;
use super::header::{LasHeader, VlrRecord};
use super::mapped_sink::MappedSink;
use crate::error::{Error, Result};
use crate::io::extension;
use crate::io::stream::{Bounds, Sink};

/// A sink writing `output` (`.las`, `.laz` or `.copc.laz`) for `input`; `bounds`: the moved
/// samples' bounds when known (after a first attempt overflowed the input's frame).
pub(super) fn sink(input: &Input, output: &Path, bounds: Option<Bounds>) -> Result<Box<dyn Sink>> {
    let out_laz = match extension(output).as_deref() {
        Some("laz") => true,
        Some("las") => false,
        _ => {
            return Err(Error::param(format!(
                "{}: a LAS/LAZ input is written as .las or .laz",
                output.display()
            )));
        }
    };
    let mut notes = Vec::new();
    let frame = output_frame(input.header, bounds, &mut notes);
    if is_copc(output) {
        let records = (input.las_header)()
            .map(|h| VlrRecord::all_of(&h))
            .unwrap_or_default();
        return Ok(Box::new(CopcSink::new(
            output,
            input.header.clone(),
            records,
            frame,
            notes,
        )?));
    }
    match (input.map, out_laz) {
        (Some(map), false) => Ok(Box::new(MappedSink::new(
            output,
            map.clone(),
            input.header.clone(),
            frame,
            notes,
        )?)),
        _ => Ok(Box::new(CrateSink::new(
            input, output, out_laz, frame, notes,
        )?)),
    }
}

/// The output's scale and offset: the input's, unless `bounds` (of the moved samples, known
/// after an overflow) do not fit them.
fn output_frame(header: &LasHeader, bounds: Option<Bounds>, notes: &mut Vec<String>) -> Frame {
    match bounds {
        None => (header.scale, header.offset),
        Some(bounds) => reframe((header.scale, header.offset), bounds, notes),
    }
}
