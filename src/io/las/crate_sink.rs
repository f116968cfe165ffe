//! The writer of LAZ outputs, and of LAS outputs from a LAZ input, through the `las` crate
//! (its parallel LAZ codec): the header and VLRs are rebuilt by the crate from the input's,
//! without the LASzip VLR (the writer adds its own) and without COPC VLRs/EVLRs (a rewritten
//! file is no longer COPC-ordered); the global encoding word, which the crate reduces, and the
//! bounds, which the crate rounds outwards to a whole step of the scale (a step past the
//! records where the division by the scale falls short of the record's integer), are set after
//! writing: the bounds to those of the records as stored.

use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use las::{Builder, LazParallelism, PointData, PointDataBuilder, WriterOptions};

use super::coords::{Frame, encode, frame_words, on_frame};
use super::header::{SOFTWARE, return_number};
use super::raw::{HEADER_1_4, RawHeader};
use super::{Input, LAZ_BATCH};
use crate::error::{Error, Result};
use crate::io::stream::{Accepted, Chunk, OutFile, ResultSet, Sink, TempFile};
use crate::rigid::Vect;

/// LAZ in or out, through the `las` crate's raw slab path.
pub(super) struct CrateSink {
    tmp: Option<TempFile>,
    writer: Option<las::Writer<BufWriter<OutFile>>>,
    /// Records waiting to be written, [`LAZ_BATCH`] at a time.
    pending: Vec<u8>,
    record_len: usize,
    /// The records of one batch, in the writer's format and transforms; reused.
    slab: PointData,
    scale: [f64; 3],
    offset: [f64; 3],
    /// The bounds of the records written, as they decode.
    lo: [f64; 3],
    hi: [f64; 3],
    global_encoding: u16,
    /// The header is LAS 1.0–1.3, whose return counts stop at 5: a record with return 6 or 7
    /// makes the writer fail at the end ([`Accepted::Restart`] at once instead).
    legacy_returns: bool,
    notes: Vec<String>,
}

impl CrateSink {
    /// Starts `output` (LAZ when `out_laz`) with the header and VLRs of `source`, framed in
    /// `frame`; `notes` gets what the output changes of the input's header.
    pub(super) fn new(
        source: &Input,
        output: &Path,
        out_laz: bool,
        (scale, offset): Frame,
        mut notes: Vec<String>,
    ) -> Result<Self> {
        let (input, header, max_return) = (source.path, source.header, source.max_return);
        let mut b = Builder::from((source.las_header)()?);
        b.point_format.is_compressed = out_laz;
        b.generating_software = SOFTWARE.to_string();
        if max_return > 5 && header.version.1 < 4 {
            // The `las` writer cannot count returns 6 and 7 in a legacy header.
            b.version = las::Version::new(1, 4);
            notes.push(format!(
                "return numbers up to {max_return} do not fit a LAS 1.{} header's counts; the output header is LAS 1.4",
                header.version.1
            ));
        }
        let legacy_returns = b.version < las::Version::new(1, 4);
        let before = b.vlrs.len() + b.evlrs.len();
        b.vlrs.retain(|v| {
            !(v.user_id == "laszip encoded" && v.record_id == 22204) && v.user_id != "copc"
        });
        b.evlrs.retain(|v| v.user_id != "copc");
        let copc = before - b.vlrs.len() - b.evlrs.len() > usize::from(header.compressed);
        if copc {
            notes.push(
                "the COPC index is dropped: the output is a plain LAZ in the input's point order \
                 (name it *.copc.laz for a COPC)"
                    .into(),
            );
        }
        for a in 0..3 {
            let t = las::Transform {
                scale: scale[a],
                offset: offset[a],
            };
            match a {
                0 => b.transforms.x = t,
                1 => b.transforms.y = t,
                _ => b.transforms.z = t,
            }
        }
        let las_header = b
            .into_header()
            .map_err(|e| Error::format(input, format!("header: {e}")))?;
        let slab = PointDataBuilder::new()
            .with_format(*las_header.point_format())
            .with_transforms(*las_header.transforms())
            .build();
        let (tmp, out) = TempFile::create(output)?;
        let writer = las::Writer::with_options(
            out,
            las_header,
            WriterOptions::default().with_laz_parallelism(LazParallelism::Yes),
        )
        .map_err(|e| write_error(output, e))?;
        Ok(Self {
            tmp: Some(tmp),
            writer: Some(writer),
            pending: Vec::new(),
            record_len: 0,
            slab,
            scale,
            offset,
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
            global_encoding: header.global_encoding,
            legacy_returns,
            notes,
        })
    }
}

impl CrateSink {
    /// Writes the pending records.
    fn flush(&mut self) -> Result<()> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let target = self.target();
        let n = self.pending.len() / self.record_len;
        self.slab.resize_for(n).copy_from_slice(&self.pending);
        self.pending.clear();
        self.writer
            .as_mut()
            .expect("writer open until finish")
            .write_points(&self.slab)
            .map_err(|e| write_error(&target, e))
    }

    fn target(&self) -> PathBuf {
        self.tmp
            .as_ref()
            .map(|t| t.target().to_path_buf())
            .unwrap_or_default()
    }
}

impl Sink for CrateSink {
    fn written(&self, p: &Vect<3>) -> Vect<3> {
        on_frame(&(self.scale, self.offset), p)
    }

    fn rounding(&self) -> Option<String> {
        Some(frame_words(&(self.scale, self.offset)))
    }

    fn write(
        &mut self,
        chunk: &Chunk,
        moved: &[Vect<3>],
        _normals: &[Vect<3>],
    ) -> Result<Accepted> {
        if self.legacy_returns
            && (chunk.raw.chunks_exact(chunk.record_len)).any(|r| return_number(r, true) > 5)
        {
            return Ok(Accepted::Restart);
        }
        let start = self.pending.len();
        self.pending.extend_from_slice(&chunk.raw);
        self.record_len = chunk.record_len;
        let (mut lo, mut hi) = (self.lo, self.hi);
        let accepted = encode(
            &mut self.pending[start..],
            chunk.record_len,
            moved,
            &(self.scale, self.offset),
            (&mut lo, &mut hi),
        );
        if accepted != Accepted::Yes {
            return Ok(accepted);
        }
        (self.lo, self.hi) = (lo, hi);
        if self.pending.len() >= LAZ_BATCH * chunk.record_len {
            self.flush()?;
        }
        Ok(accepted)
    }

    fn finish(mut self: Box<Self>, set: &ResultSet) -> Result<Vec<String>> {
        self.flush()?;
        let target = self.target();
        let mut writer = self.writer.take().expect("writer open until finish");
        if let Err(e) = writer.close() {
            std::mem::forget(writer);
            return Err(Error::format(&target, format!("{e}")));
        }
        drop(writer);
        // Restore the global encoding word (waveform bits) that the crate reduces, and set the
        // bounds of the records as stored.
        let written = self.lo[0] <= self.hi[0];
        let restore = || -> std::io::Result<()> {
            let tmp = self.tmp.as_ref().expect("open until finish");
            let mut file = tmp.handle().map_err(std::io::Error::other)?;
            file.seek(SeekFrom::Start(0))?;
            let mut head = Vec::with_capacity(HEADER_1_4);
            (&mut file).take(HEADER_1_4 as u64).read_to_end(&mut head)?;
            let mut raw = RawHeader::from_bytes(&head).ok_or(std::io::ErrorKind::UnexpectedEof)?;
            raw.global_encoding = self.global_encoding;
            if written {
                (raw.min, raw.max) = (self.lo, self.hi);
            }
            file.seek(SeekFrom::Start(0))?;
            file.write_all(&raw.to_bytes())
        };
        restore().map_err(|e| Error::write(&target, e))?;
        set.stage(self.tmp.take().expect("open until finish"))?;
        Ok(std::mem::take(&mut self.notes))
    }
}

impl Drop for CrateSink {
    fn drop(&mut self) {
        // An abandoned writer is closed quietly; one whose close fails is leaked, because the
        // crate's own drop would panic.
        if let Some(mut w) = self.writer.take()
            && w.close().is_err()
        {
            std::mem::forget(w);
        }
    }
}

/// An error of the `las` crate's writer on `output`: its I/O errors are errors writing the
/// output (exit 1), the others the crate refusing what it was given.
fn write_error(output: &Path, e: las::Error) -> Error {
    match e {
        las::Error::Io(e) => Error::write(output, e),
        other => Error::format(output, other.to_string()),
    }
}
