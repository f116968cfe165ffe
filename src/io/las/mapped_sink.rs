//! The LAS → LAS writer without the `las` crate: the input's header and VLRs, the records of
//! its memory map with new coordinates, and every byte after the points (internal waveform
//! data, EVLRs) as they were. Only the header's generating software, frame and bounds change.

use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::Path;
use std::sync::Arc;

use memmap2::Mmap;

use super::coords::{Frame, encode, frame_words, on_frame};
use super::header::{LasHeader, SOFTWARE};
use super::raw::{RawHeader, text_field};
use crate::error::{Error, Result};
use crate::io::stream::{Accepted, Chunk, OutFile, ResultSet, Sink, TempFile};
use crate::rigid::Vect;

/// LAS → LAS without the `las` crate: header, VLRs and trailing bytes copied verbatim.
pub(super) struct MappedSink {
    tmp: TempFile,
    out: BufWriter<OutFile>,
    input: Arc<Mmap>,
    header: LasHeader,
    /// The output's header: the input's, with this writer's software, frame and bounds.
    raw: RawHeader,
    lo: [f64; 3],
    hi: [f64; 3],
    buf: Vec<u8>,
    notes: Vec<String>,
}

impl MappedSink {
    /// Starts `output` with the header and VLRs of `input` (the memory map of the file that
    /// `header` was parsed from), framed in `frame`.
    pub(super) fn new(
        output: &Path,
        input: Arc<Mmap>,
        header: LasHeader,
        (scale, offset): Frame,
        notes: Vec<String>,
    ) -> Result<Self> {
        let (tmp, mut out) = TempFile::create(output)?;
        let mut raw = RawHeader::from_bytes(&input).expect("a parsed header");
        raw.generating_software = text_field(SOFTWARE);
        (raw.scale, raw.offset) = (scale, offset);
        let head = raw.to_bytes();
        // The rest of the header block (when it is larger than its version's) and the VLRs.
        let vlrs = &input[head.len()..header.point_offset as usize];
        out.write_all(&head)
            .and_then(|_| out.write_all(vlrs))
            .map_err(|e| Error::write(output, e))?;
        Ok(Self {
            tmp,
            out,
            input,
            header,
            raw,
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
            buf: Vec::new(),
            notes,
        })
    }
}

impl Sink for MappedSink {
    fn written(&self, p: &Vect<3>) -> Vect<3> {
        on_frame(&(self.raw.scale, self.raw.offset), p)
    }

    fn rounding(&self) -> Option<String> {
        Some(frame_words(&(self.raw.scale, self.raw.offset)))
    }

    fn write(
        &mut self,
        chunk: &Chunk,
        moved: &[Vect<3>],
        _normals: &[Vect<3>],
    ) -> Result<Accepted> {
        let rl = self.header.record_len as usize;
        let start = self.header.point_offset as usize + chunk.first as usize * rl;
        self.buf.clear();
        self.buf
            .extend_from_slice(&self.input[start..start + moved.len() * rl]);
        let frame = (self.raw.scale, self.raw.offset);
        let accepted = encode(
            &mut self.buf,
            rl,
            moved,
            &frame,
            (&mut self.lo, &mut self.hi),
        );
        if accepted == Accepted::Yes {
            self.out
                .write_all(&self.buf)
                .map_err(|e| Error::write(self.tmp.target(), e))?;
        }
        Ok(accepted)
    }

    /// The records come from the input's map: the source need not copy them.
    fn needs_raw(&self) -> bool {
        false
    }

    fn finish(self: Box<Self>, set: &ResultSet) -> Result<Vec<String>> {
        let Self {
            tmp,
            mut out,
            input,
            header,
            mut raw,
            lo,
            hi,
            notes,
            ..
        } = *self;
        let target = tmp.target().to_path_buf();
        let io = |e| Error::write(&target, e);
        let end = header.point_offset as usize + header.count as usize * header.record_len as usize;
        out.write_all(&input[end..]).map_err(io)?;
        let mut file = out.into_inner().map_err(|e| io(e.into_error()))?;
        // The header again, with the bounds of the records written.
        (raw.min, raw.max) = (lo, hi);
        file.seek(SeekFrom::Start(0))
            .and_then(|_| file.write_all(&raw.to_bytes()))
            .and_then(|_| file.flush())
            .map_err(io)?;
        drop(file);
        set.stage(tmp)?;
        Ok(notes)
    }
}
