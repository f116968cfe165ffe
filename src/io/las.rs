//! LAS 1.0–1.4 and LAZ, point data record formats 0–10.
//!
//! Every point record is read and written as raw bytes; only `X Y Z` (the first 12 bytes of every
//! format) are rewritten, so intensity, flags, classes, GPS time, colors, NIR, wave packet
//! descriptors and extra bytes, described or not, pass through bit for bit (the `las` crate's
//! `Point` type is never used: it loses information, see CRATES.md).
//!
//! - **LAS → LAS** is handled here without the `las` crate: the input is memory-mapped, the output
//!   is the input's header and VLRs byte for byte, the records with new coordinates, and every
//!   byte after the points (internal waveform data, EVLRs) byte for byte. Only the header's
//!   bounds change, and scale/offset when the moved coordinates would not fit (then the offset
//!   moves, and the scale doubles only if the range needs it; the notes say so).
//! - **LAZ in or out** goes through `las`/`laz` (parallel chunk (de)compression): the header
//!   and VLRs are rebuilt by the crate from the input's, without the LASzip VLR (the writer adds
//!   its own) and without COPC VLRs/EVLRs (a rewritten file is no longer COPC-ordered); the
//!   global encoding word, which the crate reduces, is restored after writing.
//!
//! The header is parsed here for every input: it gives precise errors for malformed files
//! (counts that lie, VLRs that overrun the point data, truncated bodies, LAS 1.5).

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use las::{Builder, LazParallelism, PointData, PointDataBuilder, ReaderOptions, WriterOptions};
use memmap2::Mmap;

use super::mapped;
use super::stream::{Accepted, Bounds, Chunk, Sink, Source, TempFile};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// Minimum record length of each point data record format.
const RECORD_LEN: [u16; 11] = [20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67];

/// One variable-length record's header.
#[derive(Debug, Clone, PartialEq)]
pub struct VlrInfo {
    /// User id.
    pub user_id: String,
    /// Record id.
    pub record_id: u16,
    /// Payload length in bytes.
    pub len: u64,
    /// Description.
    pub description: String,
}

/// A variable-length record with its payload.
#[derive(Debug, Clone, PartialEq)]
pub struct VlrRecord {
    /// User id.
    pub user_id: String,
    /// Record id.
    pub record_id: u16,
    /// Description.
    pub description: String,
    /// Payload.
    pub data: Vec<u8>,
    /// Whether it is (or must be written as) an extended VLR.
    pub extended: bool,
}

impl VlrRecord {
    /// Whether it is the record `user_id`/`record_id`.
    pub fn is(&self, user_id: &str, record_id: u16) -> bool {
        self.user_id == user_id && self.record_id == record_id
    }
}

impl VlrInfo {
    /// Whether this record describes a coordinate reference system.
    pub fn is_crs(&self) -> bool {
        self.user_id == "LASF_Projection"
    }
}

/// The fields of a LAS header that rigidcells reads or rewrites.
#[derive(Debug, Clone, PartialEq)]
pub struct LasHeader {
    /// Major and minor version.
    pub version: (u8, u8),
    /// Header size in bytes.
    pub header_size: u16,
    /// Offset of the first point record.
    pub point_offset: u32,
    /// Point data record format (0–10).
    pub format: u8,
    /// Whether the points are LAZ-compressed.
    pub compressed: bool,
    /// Bytes per record.
    pub record_len: u16,
    /// Number of points.
    pub count: u64,
    /// Scale per axis.
    pub scale: [f64; 3],
    /// Offset per axis.
    pub offset: [f64; 3],
    /// Declared minimum per axis.
    pub min: [f64; 3],
    /// Declared maximum per axis.
    pub max: [f64; 3],
    /// Global encoding word.
    pub global_encoding: u16,
    /// The VLRs.
    pub vlrs: Vec<VlrInfo>,
    /// Number of EVLRs (LAS 1.4).
    pub evlr_count: u32,
    /// The LASzip compressor type (1 point-wise, 2 point-wise chunked, 3 layered chunked).
    pub laz_compressor: Option<u16>,
    /// The LASzip VLR's data, when there is one.
    pub laszip_vlr: Option<Vec<u8>>,
    /// System identifier.
    pub system: String,
    /// Generating software.
    pub software: String,
    /// File source ID.
    pub file_source_id: u16,
    /// Project ID (GUID).
    pub guid: [u8; 16],
    /// File creation day of the year and year.
    pub creation: (u16, u16),
}

fn le_u16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}
fn le_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}
fn le_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}
fn le_f64(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}
/// A NUL-terminated text field (bytes after the first NUL are padding).
fn text(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).trim().to_string()
}

impl LasHeader {
    /// Parses the header and VLRs at the start of a file of `file_len` bytes; `prefix` holds at
    /// least the bytes up to the first point record (or the whole file if shorter).
    pub fn parse(path: &Path, prefix: &[u8], file_len: u64) -> Result<Self> {
        let err = |m: String| Error::format(path, m);
        if file_len == 0 {
            return Err(err("the file is empty".into()));
        }
        if !prefix.starts_with(b"LASF") {
            return Err(err("not a LAS/LAZ file (no `LASF` signature)".into()));
        }
        if prefix.len() < 227 {
            return Err(err(format!(
                "the header is truncated ({} bytes; a LAS header has at least 227)",
                prefix.len()
            )));
        }
        let version = (prefix[24], prefix[25]);
        if version.0 != 1 || version.1 > 4 {
            return Err(err(format!(
                "LAS {}.{} is not supported (rigidcells reads LAS 1.0 to 1.4)",
                version.0, version.1
            )));
        }
        let header_size = le_u16(prefix, 94);
        let needed = match version.1 {
            0..=2 => 227,
            3 => 235,
            _ => 375,
        };
        if (header_size as usize) < needed || (header_size as usize) > prefix.len() {
            return Err(err(format!(
                "header size {header_size} is wrong for LAS {}.{} (at least {needed}) or the header is truncated",
                version.0, version.1
            )));
        }
        let point_offset = le_u32(prefix, 96);
        if point_offset < header_size as u32 || point_offset as u64 > file_len {
            return Err(err(format!(
                "the offset to the point data ({point_offset}) lies outside the file ({file_len} bytes) or inside the header"
            )));
        }
        if (point_offset as usize) > prefix.len() {
            return Err(err("the VLRs are truncated".into()));
        }
        let vlr_count = le_u32(prefix, 100);
        let mut vlrs = Vec::new();
        let mut laz_compressor = None;
        let mut laszip_vlr = None;
        let mut at = header_size as usize;
        for k in 0..vlr_count {
            if at + 54 > point_offset as usize {
                return Err(err(format!(
                    "VLR {} of {vlr_count} would start past the point data at byte {point_offset}: the header's VLR count or a VLR length is wrong",
                    k + 1
                )));
            }
            let len = le_u16(prefix, at + 20) as u64;
            if text(&prefix[at + 2..at + 18]) == "laszip encoded"
                && le_u16(prefix, at + 18) == 22204
                && len >= 2
                && at + 56 <= point_offset as usize
            {
                laz_compressor = Some(le_u16(prefix, at + 54));
                laszip_vlr = Some(
                    prefix[at + 54..(at + 54 + len as usize).min(point_offset as usize)].to_vec(),
                );
            }
            vlrs.push(VlrInfo {
                user_id: text(&prefix[at + 2..at + 18]),
                record_id: le_u16(prefix, at + 18),
                len,
                description: text(&prefix[at + 22..at + 54]),
            });
            at += 54 + len as usize;
            if at > point_offset as usize {
                return Err(err(format!(
                    "VLR {} of {vlr_count} runs past the start of the point data (byte {point_offset})",
                    k + 1
                )));
            }
        }
        let format_byte = prefix[104];
        let format = format_byte & 0x3f;
        let compressed = format_byte & 0x80 != 0
            || vlrs
                .iter()
                .any(|v| v.user_id == "laszip encoded" && v.record_id == 22204);
        if format > 10 {
            return Err(err(format!(
                "point data record format {format} is not 0–10"
            )));
        }
        let record_len = le_u16(prefix, 105);
        if record_len < RECORD_LEN[format as usize] {
            return Err(err(format!(
                "records of {record_len} bytes are too short for point format {format} (at least {})",
                RECORD_LEN[format as usize]
            )));
        }
        let legacy = le_u32(prefix, 107) as u64;
        let count = if version.1 >= 4 && le_u64(prefix, 247) != 0 {
            le_u64(prefix, 247)
        } else {
            legacy
        };
        if count == 0 {
            return Err(err("the file holds no points".into()));
        }
        let f3 = |at: usize| {
            [
                le_f64(prefix, at),
                le_f64(prefix, at + 8),
                le_f64(prefix, at + 16),
            ]
        };
        let scale = f3(131);
        let offset = f3(155);
        // A frame that could not hold the moved coordinates is refused here, before the solve.
        if let Some(why) = frame_error(&scale, &offset) {
            return Err(err(why));
        }
        let b = |at: usize| le_f64(prefix, at);
        let max = [b(179), b(195), b(211)];
        let min = [b(187), b(203), b(219)];
        if !compressed {
            let body = file_len - point_offset as u64;
            let need = count.saturating_mul(record_len as u64);
            if body < need {
                return Err(err(format!(
                    "truncated: the header says {count} points of {record_len} bytes but the file holds {} complete records",
                    body / record_len as u64
                )));
            }
        }
        let evlr_count = if version.1 >= 4 {
            le_u32(prefix, 243)
        } else {
            0
        };
        Ok(Self {
            version,
            header_size,
            point_offset,
            format,
            compressed,
            record_len,
            count,
            scale,
            offset,
            min,
            max,
            global_encoding: le_u16(prefix, 6),
            vlrs,
            evlr_count,
            laz_compressor,
            laszip_vlr,
            system: text(&prefix[26..58]),
            software: text(&prefix[58..90]),
            file_source_id: le_u16(prefix, 4),
            guid: prefix[8..24].try_into().expect("16 bytes"),
            creation: (le_u16(prefix, 90), le_u16(prefix, 92)),
        })
    }

    /// Reads and parses the header of `path` without reading the points.
    pub fn read(path: &Path) -> Result<Self> {
        let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        let mut prefix = vec![0u8; len.min(375) as usize];
        file.read_exact(&mut prefix)
            .map_err(|e| Error::io(path, e))?;
        if prefix.len() >= 100 && prefix.starts_with(b"LASF") {
            let offset = le_u32(&prefix, 96) as u64;
            if offset > prefix.len() as u64 && offset <= len {
                // The VLRs up to the point data, after the bytes already read.
                let have = prefix.len();
                prefix.resize(offset as usize, 0);
                file.read_exact(&mut prefix[have..])
                    .map_err(|e| Error::io(path, e))?;
            }
        }
        Self::parse(path, &prefix, len)
    }

    /// Byte offset of the class in a record.
    fn class_at(&self) -> usize {
        if self.format >= 6 { 16 } else { 15 }
    }

    /// A record's color for pictures: its 16-bit RGB when the point format has one, else its
    /// intensity three times.
    pub fn color(&self, record: &[u8]) -> [u16; 3] {
        let u16_at = |at: usize| u16::from_le_bytes([record[at], record[at + 1]]);
        let rgb_at = match self.format {
            2 => Some(20),
            3 | 5 => Some(28),
            7 | 8 | 10 => Some(30),
            _ => None,
        };
        match rgb_at {
            Some(at) if record.len() >= at + 6 => [u16_at(at), u16_at(at + 2), u16_at(at + 4)],
            _ => [u16_at(12); 3],
        }
    }
}

enum Body {
    Mapped(Arc<Mmap>),
    /// The reader, its last batch of decoded records, and how many of them were handed out.
    Laz(Box<las::Reader>, PointData, usize),
    /// Point-wise LAZ (compressor 1): one stream without a chunk table, decoded sequentially.
    PointWise(Box<laz::LasZipDecompressor<'static, BufReader<File>>>),
}

/// Points the `las` crate decompresses or compresses per call: its parallel LAZ codec works on
/// the LAZ chunks of one call, so batches much larger than the pipeline's chunks keep both
/// cores busy (64k-point calls made a LAZ copy 45 % slower).
const LAZ_BATCH: usize = 1 << 20;

/// A sequential decompressor over the point data of a point-wise LAZ file.
fn point_wise(
    path: &Path,
    header: &LasHeader,
    vlr: laz::LazVlr,
) -> Result<laz::LasZipDecompressor<'static, BufReader<File>>> {
    let err = |e: laz::LasZipError| Error::format(path, laz_message("", &e));
    let chunked = vlr.uses_variable_size_chunks();
    let mut file =
        BufReader::with_capacity(1 << 20, File::open(path).map_err(|e| Error::io(path, e))?);
    file.seek(SeekFrom::Start(header.point_offset as u64))
        .map_err(|e| Error::io(path, e))?;
    let decompressor = laz::LasZipDecompressor::new(file, vlr).map_err(err)?;
    if chunked {
        // laz panics on this contradiction: a point-wise stream has no chunks at all.
        return Err(Error::format(
            path,
            "LAZ: the LASzip VLR says point-wise compression but variable-size chunks",
        ));
    }
    Ok(decompressor)
}

/// A LAS or LAZ file as a [`Source`].
pub struct LasSource {
    path: PathBuf,
    header: LasHeader,
    body: Body,
    next: u64,
    /// The largest return number seen so far.
    max_return: u8,
}

impl LasSource {
    /// Opens `path` (LAS or LAZ, decided by the header).
    pub fn open(path: &Path) -> Result<Self> {
        let header = LasHeader::read(path)?;
        check_evlrs(path, &header)?;
        let body = if header.laz_compressor == Some(1) {
            let vlr = check_laz(path, &header)?;
            let d =
                crate::interrupt::guarded(path, "opening it", || point_wise(path, &header, vlr))?;
            Body::PointWise(Box::new(d))
        } else if header.compressed {
            check_laz(path, &header)?;
            let file = File::open(path).map_err(|e| Error::io(path, e))?;
            let reader = crate::interrupt::guarded(path, "opening it", || {
                las::Reader::with_options(
                    BufReader::with_capacity(1 << 20, file),
                    ReaderOptions::default().with_laz_parallelism(LazParallelism::Yes),
                )
                .map_err(|e| Error::format(path, las_message("", &e)))
            })?;
            let slab = PointDataBuilder::new().for_header(reader.header()).build();
            Body::Laz(Box::new(reader), slab, 0)
        } else {
            Body::Mapped(Arc::new(mapped::map(path)?))
        };
        Ok(Self {
            path: path.to_path_buf(),
            header,
            body,
            next: 0,
            max_return: 0,
        })
    }

    /// The parsed header.
    pub fn header(&self) -> &LasHeader {
        &self.header
    }

    /// Every VLR, then every EVLR, with its payload (none when the `las` crate cannot read the
    /// header). A VLR too long for a VLR's 16-bit length is marked extended.
    pub fn vlr_records(&self) -> Vec<VlrRecord> {
        let Ok(h) = self.las_header() else {
            return Vec::new();
        };
        let record = |v: &las::Vlr, extended: bool| VlrRecord {
            user_id: v.user_id.clone(),
            record_id: v.record_id,
            description: v.description.clone(),
            data: v.data.clone(),
            extended: extended || v.data.len() > u16::MAX as usize,
        };
        h.vlrs()
            .iter()
            .map(|v| record(v, false))
            .chain(h.evlrs().iter().map(|v| record(v, true)))
            .collect()
    }

    /// The `las` crate's header: the open LAZ reader's, or read for an uncompressed input.
    fn las_header(&self) -> Result<las::Header> {
        let err = |e: las::Error| Error::format(&self.path, format!("{e}"));
        match &self.body {
            Body::Laz(reader, ..) => Ok(reader.header().clone()),
            Body::Mapped(_) => {
                let file = File::open(&self.path).map_err(|e| Error::io(&self.path, e))?;
                las::Reader::new(BufReader::new(file))
                    .map(|r| r.header().clone())
                    .map_err(err)
            }
            Body::PointWise(_) => {
                // `las::Reader` insists on a chunk table: header and VLRs are read raw.
                let mut file =
                    BufReader::new(File::open(&self.path).map_err(|e| Error::io(&self.path, e))?);
                let raw = las::raw::Header::read_from(&mut file).map_err(err)?;
                file.seek(SeekFrom::Start(self.header.header_size as u64))
                    .map_err(|e| Error::io(&self.path, e))?;
                let mut b = Builder::new(raw).map_err(err)?;
                for _ in 0..self.header.vlrs.len() {
                    let vlr = las::raw::Vlr::read_from(&mut file, false).map_err(err)?;
                    b.vlrs.push(las::Vlr::new(vlr));
                }
                b.into_header().map_err(err)
            }
        }
    }
}

impl Source for LasSource {
    fn path(&self) -> &Path {
        &self.path
    }

    fn len(&self) -> u64 {
        self.header.count
    }

    fn bounds_hint(&self) -> Option<Bounds> {
        let h = &self.header;
        let ok =
            (0..3).all(|a| h.min[a].is_finite() && h.max[a].is_finite() && h.min[a] <= h.max[a]);
        ok.then(|| (Vect::<3>::from(h.min), Vect::<3>::from(h.max)))
    }

    fn has_classes(&self) -> bool {
        true
    }

    fn rewind(&mut self) -> Result<()> {
        if let Body::Laz(reader, slab, used) = &mut self.body {
            let path = &self.path;
            crate::interrupt::guarded(path, "seeking in it", || {
                reader
                    .seek(0)
                    .map_err(|e| Error::format(path, las_message("", &e)))
            })?;
            slab.resize_for(0);
            *used = 0;
        }
        if let Body::PointWise(d) = &mut self.body {
            **d = point_wise(
                &self.path,
                &self.header,
                laszip_vlr(&self.path, &self.header)?,
            )?;
        }
        self.next = 0;
        Ok(())
    }

    fn read(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        self.read_records(max, chunk, true)
    }

    fn read_samples(&mut self, max: usize, chunk: &mut Chunk) -> Result<usize> {
        self.read_records(max, chunk, false)
    }

    fn sink(&self, output: &Path, bounds: Option<Bounds>) -> Result<Box<dyn Sink>> {
        let ext = super::extension(output);
        let out_laz = match ext.as_deref() {
            Some("laz") => true,
            Some("las") => false,
            _ => {
                return Err(Error::Param(format!(
                    "{}: a LAS/LAZ input is written as .las or .laz",
                    output.display()
                )));
            }
        };
        let mut notes = Vec::new();
        let (scale, offset) = output_frame(&self.header, bounds, &mut notes);
        if super::copc::is_copc(output) {
            return Ok(Box::new(super::copc::CopcSink::new(
                output,
                self.header.clone(),
                self.vlr_records(),
                (scale, offset),
                notes,
            )?));
        }
        match (&self.body, out_laz) {
            (Body::Mapped(map), false) => Ok(Box::new(RawSink::new(
                output,
                map.clone(),
                self.header.clone(),
                scale,
                offset,
                notes,
            )?)),
            _ => Ok(Box::new(CrateSink::new(
                self,
                output,
                out_laz,
                (scale, offset),
                notes,
            )?)),
        }
    }
}

impl LasSource {
    /// Reads up to `max` records into `chunk`: their samples, and with `keep_raw` their bytes
    /// (memory-mapped records are decoded from the map, so without `keep_raw` they are not
    /// copied at all).
    fn read_records(&mut self, max: usize, chunk: &mut Chunk, keep_raw: bool) -> Result<usize> {
        let h = &self.header;
        let rl = h.record_len as usize;
        let mut n = (h.count - self.next).min(max as u64) as usize;
        chunk.clear(self.next);
        chunk.record_len = rl;
        if n == 0 {
            return Ok(0);
        }
        // Mapped records are decoded straight from the map; the others from `chunk.raw`.
        let ret = match &mut self.body {
            Body::Mapped(map) => {
                let start = h.point_offset as usize + self.next as usize * rl;
                let records = &map[start..start + n * rl];
                if keep_raw {
                    chunk.raw.extend_from_slice(records);
                }
                Some(decode(h, records, &mut chunk.positions, &mut chunk.classes))
            }
            Body::Laz(reader, slab, used) => {
                if *used * rl == slab.raw_bytes().len() {
                    let want = (h.count - self.next).min(LAZ_BATCH as u64);
                    let (path, next) = (&self.path, self.next);
                    let got = crate::interrupt::guarded(path, "decompressing it", || {
                        reader.fill_points(want, slab).map_err(|e| {
                            let m = las_message(&format!("point {next} onwards: "), &e);
                            Error::format(path, m)
                        })
                    })?;
                    if got != want {
                        return Err(Error::format(
                            &self.path,
                            format!(
                                "truncated: the header says {} points but the data ends after {}",
                                h.count,
                                self.next + got
                            ),
                        ));
                    }
                    *used = 0;
                }
                let take = n.min(slab.raw_bytes().len() / rl - *used);
                chunk
                    .raw
                    .extend_from_slice(&slab.raw_bytes()[*used * rl..(*used + take) * rl]);
                *used += take;
                n = take;
                None
            }
            Body::PointWise(d) => {
                chunk.raw.resize(n * rl, 0);
                let (path, next, raw) = (&self.path, self.next, &mut chunk.raw);
                // `laz` panics on some contradictions of its VLR and the records (a fuzzed item
                // size of 19 for a 20-byte item): a format error like the chunked path's.
                crate::interrupt::guarded(path, "decompressing it", || {
                    d.decompress_many(raw).map_err(|e| {
                        let e = laz::LasZipError::IoError(e);
                        Error::format(path, laz_message(&format!("point {next} onwards: "), &e))
                    })
                })?;
                None
            }
        };
        let ret =
            ret.unwrap_or_else(|| decode(h, &chunk.raw, &mut chunk.positions, &mut chunk.classes));
        self.max_return = self.max_return.max(ret);
        self.next += n as u64;
        Ok(n)
    }
}

/// Appends the world coordinates and classes of `records` to `positions` and `classes`;
/// returns the largest return number among them.
fn decode(
    h: &LasHeader,
    records: &[u8],
    positions: &mut Vec<Vect<3>>,
    classes: &mut Vec<u8>,
) -> u8 {
    let class_at = h.class_at();
    let five_bits = h.format < 6;
    let mut max_return = 0;
    for rec in records.chunks_exact(h.record_len as usize) {
        let c = |at: usize| i32::from_le_bytes(rec[at..at + 4].try_into().expect("4 bytes"));
        positions.push(Vect::<3>::new(
            c(0) as f64 * h.scale[0] + h.offset[0],
            c(4) as f64 * h.scale[1] + h.offset[1],
            c(8) as f64 * h.scale[2] + h.offset[2],
        ));
        let class = rec[class_at];
        classes.push(if five_bits { class & 0x1f } else { class });
        max_return = max_return.max(return_number(rec, five_bits));
    }
    max_return
}

/// A record's return number: 3 bits in formats 0–5 (`five_bits`: 5-bit classes), 4 bits after.
fn return_number(record: &[u8], five_bits: bool) -> u8 {
    record[14] & if five_bits { 0x07 } else { 0x0f }
}

/// The output's scale and offset: the input's, unless `bounds` (of the moved samples, known
/// after an overflow) do not fit them.
fn output_frame(
    header: &LasHeader,
    bounds: Option<Bounds>,
    notes: &mut Vec<String>,
) -> ([f64; 3], [f64; 3]) {
    match bounds {
        None => (header.scale, header.offset),
        Some(bounds) => reframe((header.scale, header.offset), bounds, notes),
    }
}

/// `frame`, with the offset of each axis on which `lo`–`hi` (the moved coordinates' bounds)
/// do not fit 32-bit record integers moved to their center (on the old grid, so unmoved bits
/// stay exact) and the scale doubled only as far as their range needs; a note per changed axis.
fn reframe(
    (mut scale, mut offset): Frame,
    (lo, hi): Bounds,
    notes: &mut Vec<String>,
) -> ([f64; 3], [f64; 3]) {
    let fits = |s: f64, o: f64, v: f64| {
        let r = ((v - o) / s).round();
        r >= i32::MIN as f64 && r <= i32::MAX as f64
    };
    for a in 0..3 {
        if fits(scale[a], offset[a], lo[a]) && fits(scale[a], offset[a], hi[a]) {
            continue;
        }
        let old = (scale[a], offset[a]);
        while (hi[a] - lo[a]) / scale[a] > 4.0e9 {
            scale[a] *= 2.0;
        }
        // The center, on the old grid of representable values, so unmoved bits stay exact.
        let center = 0.5 * (lo[a] + hi[a]);
        offset[a] = old.1 + ((center - old.1) / old.0).round() * old.0;
        notes.push(format!(
            "axis {}: moved coordinates overflow the input's encoding; offset {} -> {}{}",
            ["x", "y", "z"][a],
            old.1,
            offset[a],
            if scale[a] != old.0 {
                format!(", scale {} -> {}", old.0, scale[a])
            } else {
                String::new()
            }
        ));
    }
    (scale, offset)
}

/// A scale and an offset per axis.
pub(crate) type Frame = ([f64; 3], [f64; 3]);

/// Writes the moved coordinates into the first 12 bytes of each record of `raw`, tracking
/// the bounds of the encoded values; [`Accepted::Overflow`] (the records half written) when
/// one does not fit `frame`.
pub(crate) fn encode(
    raw: &mut [u8],
    record_len: usize,
    moved: &[Vect<3>],
    (scale, offset): &Frame,
    (lo, hi): (&mut [f64; 3], &mut [f64; 3]),
) -> Accepted {
    for (rec, p) in raw.chunks_exact_mut(record_len).zip(moved) {
        for a in 0..3 {
            let Some(v) = round_to_i32((p[a] - offset[a]) / scale[a]) else {
                return Accepted::Overflow;
            };
            rec[4 * a..4 * a + 4].copy_from_slice(&v.to_le_bytes());
            let x = v as f64 * scale[a] + offset[a];
            lo[a] = lo[a].min(x);
            hi[a] = hi[a].max(x);
        }
    }
    Accepted::Yes
}

/// `r` rounded half away from zero (as `f64::round`), if it fits an `i32`. `f64::round` is a
/// libm call on baseline x86-64, three per record; truncation is one instruction, and `r − t`
/// is exact for `|r| < 2^52`, so the comparisons decide the rounding exactly.
#[inline(always)]
fn round_to_i32(r: f64) -> Option<i32> {
    if !(r > i32::MIN as f64 - 0.5 && r < i32::MAX as f64 + 0.5) {
        return None;
    }
    let t = r as i64;
    let frac = r - t as f64;
    // Branch-free: the fraction of a moved coordinate is random, and a branch on it missed
    // half the time (a fifth of pass 2 before).
    let v = t + i64::from(frac >= 0.5) - i64::from(frac <= -0.5);
    i32::try_from(v).ok()
}

/// Why `scale` and `offset` cannot frame LAS coordinates, if they cannot: scales are positive
/// (the record's integers times the scale, plus the offset, are the coordinates), from 1e-15
/// to 1e100, and offsets finite, within ±1e100. A scale of 5e-324 or −1, or an offset of
/// −1.8e308, left no frame that could hold the moved coordinates (exit 1 after the whole
/// solve); the upper bounds are far past what the writers make of any spec's motions (a 1e15
/// translation gave a scale of 2.3e9 and an offset past 1e18), so every output reads back.
pub fn frame_error(scale: &[f64; 3], offset: &[f64; 3]) -> Option<String> {
    let ok = scale.iter().all(|s| (1e-15..=1e100).contains(s))
        && offset.iter().all(|o| o.is_finite() && o.abs() <= 1e100);
    (!ok).then(|| {
        format!(
            "scale {scale:?} / offset {offset:?} are out of range (scales positive, 1e-15 to \
             1e100; offsets finite, within ±1e100)"
        )
    })
}

/// The coordinates of LAS record integers `X Y Z` (any integer type that holds them) in the
/// frame `scale`, `offset`: `X · scale + offset` per axis, as every LAS reader here decodes
/// them. A frame that [`frame_error`] refuses is an [`Error::Param`].
pub fn decode_coordinates(
    records: &[[i64; 3]],
    scale: [f64; 3],
    offset: [f64; 3],
) -> Result<Vec<Vect<3>>> {
    if let Some(why) = frame_error(&scale, &offset) {
        return Err(Error::Param(why));
    }
    Ok(records
        .iter()
        .map(|r| {
            Vect::<3>::new(
                r[0] as f64 * scale[0] + offset[0],
                r[1] as f64 * scale[1] + offset[1],
                r[2] as f64 * scale[2] + offset[2],
            )
        })
        .collect())
}

/// Coordinates encoded as LAS record integers by [`encode_coordinates`].
#[derive(Debug, Clone, PartialEq)]
pub struct Encoded {
    /// `X Y Z` of each sample: `(coordinate − offset) / scale` rounded to the nearest integer,
    /// halves away from zero.
    pub records: Vec<[i32; 3]>,
    /// The scale the records are in: the one asked for unless re-framing doubled it.
    pub scale: [f64; 3],
    /// The offset the records are in: the one asked for unless re-framing moved it.
    pub offset: [f64; 3],
    /// One line per re-framed axis (the old and new offset and scale).
    pub notes: Vec<String>,
}

/// `moved` as LAS record integers in the frame `scale`, `offset`, rounded to the nearest step
/// exactly as the LAS and LAZ writers here write them. When a coordinate does not fit a 32-bit
/// record integer, `reframe` moves that axis' offset (and doubles its scale if the range needs
/// it) as `rigidcells deform` does for its output, with a note; without `reframe` that is an
/// [`Error::Param`] naming the axis, its moved range and the range the frame holds. A frame
/// that [`frame_error`] refuses is an [`Error::Param`] too.
pub fn encode_coordinates(
    moved: &[Vect<3>],
    scale: [f64; 3],
    offset: [f64; 3],
    reframe: bool,
) -> Result<Encoded> {
    if let Some(why) = frame_error(&scale, &offset) {
        return Err(Error::Param(why));
    }
    let records = |(scale, offset): Frame| -> Option<Vec<[i32; 3]>> {
        moved
            .iter()
            .map(|p| {
                Some([
                    round_to_i32((p[0] - offset[0]) / scale[0])?,
                    round_to_i32((p[1] - offset[1]) / scale[1])?,
                    round_to_i32((p[2] - offset[2]) / scale[2])?,
                ])
            })
            .collect()
    };
    if let Some(records) = records((scale, offset)) {
        return Ok(Encoded {
            records,
            scale,
            offset,
            notes: Vec::new(),
        });
    }
    let mut bounds = (
        Vect::<3>::repeat(f64::INFINITY),
        Vect::<3>::repeat(f64::NEG_INFINITY),
    );
    for p in moved {
        bounds.0 = bounds.0.inf(p);
        bounds.1 = bounds.1.sup(p);
    }
    if !moved.iter().all(|p| p.iter().all(|v| v.is_finite())) {
        return Err(Error::Param("a moved coordinate is not finite".into()));
    }
    if !reframe {
        let a = (0..3)
            .find(|&a| {
                [bounds.0[a], bounds.1[a]]
                    .iter()
                    .any(|v| round_to_i32((v - offset[a]) / scale[a]).is_none())
            })
            .expect("a finite coordinate that does not fit lies on the bounds");
        let step = |i: i32| i as f64 * scale[a] + offset[a];
        return Err(Error::Param(format!(
            "axis {}: the moved coordinates span {} to {}, but 32-bit record integers with \
             scale {} and offset {} hold {} to {}",
            ["x", "y", "z"][a],
            bounds.0[a],
            bounds.1[a],
            scale[a],
            offset[a],
            step(i32::MIN),
            step(i32::MAX),
        )));
    }
    let mut notes = Vec::new();
    let (scale, offset) = self::reframe((scale, offset), bounds, &mut notes);
    let records = records((scale, offset)).ok_or_else(|| {
        Error::Param(format!(
            "the moved coordinates span {:?} to {:?}, more than 32-bit record integers can hold",
            <[f64; 3]>::from(bounds.0),
            <[f64; 3]>::from(bounds.1)
        ))
    })?;
    Ok(Encoded {
        records,
        scale,
        offset,
        notes,
    })
}

/// LAS → LAS without the `las` crate: header, VLRs and trailing bytes copied verbatim.
struct RawSink {
    tmp: TempFile,
    out: std::io::BufWriter<File>,
    input: Arc<Mmap>,
    header: LasHeader,
    scale: [f64; 3],
    offset: [f64; 3],
    lo: [f64; 3],
    hi: [f64; 3],
    buf: Vec<u8>,
    notes: Vec<String>,
}

impl RawSink {
    fn new(
        output: &Path,
        input: Arc<Mmap>,
        header: LasHeader,
        scale: [f64; 3],
        offset: [f64; 3],
        notes: Vec<String>,
    ) -> Result<Self> {
        let (tmp, mut out) = TempFile::create(output)?;
        let mut prefix = input[..header.point_offset as usize].to_vec();
        prefix[58..90].copy_from_slice(&text_field::<32>(SOFTWARE));
        out.write_all(&prefix)
            .map_err(|e| Error::write(output, e))?;
        Ok(Self {
            tmp,
            out,
            input,
            header,
            scale,
            offset,
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
            buf: Vec::new(),
            notes,
        })
    }
}

impl Sink for RawSink {
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
        let frame = (self.scale, self.offset);
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

    fn finish(self: Box<Self>) -> Result<Vec<String>> {
        let Self {
            tmp,
            mut out,
            input,
            header,
            scale,
            offset,
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
        let mut patch = Vec::with_capacity(96);
        for v in scale.iter().chain(&offset) {
            patch.extend_from_slice(&v.to_le_bytes());
        }
        for a in 0..3 {
            patch.extend_from_slice(&hi[a].to_le_bytes());
            patch.extend_from_slice(&lo[a].to_le_bytes());
        }
        file.seek(SeekFrom::Start(131))
            .and_then(|_| file.write_all(&patch))
            .and_then(|_| file.flush())
            .map_err(io)?;
        drop(file);
        tmp.commit()?;
        Ok(notes)
    }
}

/// LAZ in or out, through the `las` crate's raw slab path.
struct CrateSink {
    tmp: Option<TempFile>,
    writer: Option<las::Writer<std::io::BufWriter<File>>>,
    /// Records waiting to be written, [`LAZ_BATCH`] at a time.
    pending: Vec<u8>,
    record_len: usize,
    /// The records of one batch, in the writer's format and transforms; reused.
    slab: PointData,
    scale: [f64; 3],
    offset: [f64; 3],
    global_encoding: u16,
    /// The header is LAS 1.0–1.3, whose return counts stop at 5: a record with return 6 or 7
    /// makes the writer fail at the end ([`Accepted::Restart`] at once instead).
    legacy_returns: bool,
    notes: Vec<String>,
}

impl CrateSink {
    fn new(
        source: &LasSource,
        output: &Path,
        out_laz: bool,
        (scale, offset): Frame,
        mut notes: Vec<String>,
    ) -> Result<Self> {
        let (input, header, max_return) = (&source.path, &source.header, source.max_return);
        let mut b = Builder::from(source.las_header()?);
        b.point_format.is_compressed = out_laz;
        b.generating_software = SOFTWARE.to_string();
        if max_return > 5 && header.version.1 < 4 {
            // The `las` writer cannot count returns 6 and 7 in a legacy header (CRATES.md).
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
        // The writer computes its header bounds itself.
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let accepted = encode(
            &mut self.pending[start..],
            chunk.record_len,
            moved,
            &(self.scale, self.offset),
            (&mut lo, &mut hi),
        );
        if accepted == Accepted::Yes && self.pending.len() >= LAZ_BATCH * chunk.record_len {
            self.flush()?;
        }
        Ok(accepted)
    }

    fn finish(mut self: Box<Self>) -> Result<Vec<String>> {
        self.flush()?;
        let target = self.target();
        let mut writer = self.writer.take().expect("writer open until finish");
        if let Err(e) = writer.close() {
            std::mem::forget(writer);
            return Err(Error::format(&target, format!("{e}")));
        }
        drop(writer);
        // Restore the global encoding word (waveform bits) that the crate reduces.
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .open(self.tmp.as_ref().expect("open until finish").path())
            .map_err(|e| Error::write(&target, e))?;
        file.seek(SeekFrom::Start(6))
            .and_then(|_| file.write_all(&self.global_encoding.to_le_bytes()))
            .map_err(|e| Error::write(&target, e))?;
        drop(file);
        self.tmp.take().expect("open until finish").commit()?;
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

/// Checks that a LAS 1.4 file's extended VLRs lie within it before `las` reads them: it sizes
/// each one's buffer from its 8-byte length (a damaged length asked for 35 TB and aborted).
fn check_evlrs(path: &Path, header: &LasHeader) -> Result<()> {
    use std::io::Read;
    if header.evlr_count == 0 {
        return Ok(());
    }
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut start = [0u8; 8];
    file.seek(SeekFrom::Start(235))
        .and_then(|_| file.read_exact(&mut start))
        .map_err(|e| Error::io(path, e))?;
    let mut at = u64::from_le_bytes(start);
    if at == 0 {
        return Ok(()); // `las` reads none
    }
    let bad = |m: String| Err(Error::format(path, m));
    const HEADER: u64 = 60;
    if at < u64::from(header.point_offset)
        || u64::from(header.evlr_count).saturating_mul(HEADER) > len.saturating_sub(at)
    {
        return bad(format!(
            "the header's {} extended VLRs from byte {at} cannot fit the file ({len} bytes)",
            header.evlr_count
        ));
    }
    for k in 0..header.evlr_count {
        let mut head = [0u8; HEADER as usize];
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(&mut head))
            .map_err(|e| Error::io(path, e))?;
        let data = le_u64(&head, 20);
        match at.checked_add(HEADER).and_then(|a| a.checked_add(data)) {
            Some(end) if end <= len => at = end,
            _ => {
                return bad(format!(
                    "extended VLR {} of {} claims {data} bytes past the end of the file",
                    k + 1,
                    header.evlr_count
                ));
            }
        }
    }
    Ok(())
}

/// Checks that a LAZ file's records are as long as its LASzip items say: `laz` sizes its
/// buffers by the header's record length (32,768 bytes for 110,000 points asked for 3.6 GB and
/// aborted) and panicked where the two disagree.
fn check_items(path: &Path, header: &LasHeader, vlr: &laz::LazVlr) -> Result<()> {
    let items = vlr.items_size();
    if items != u64::from(header.record_len) {
        return Err(Error::format(
            path,
            format!(
                "LAZ: records of {} bytes in the header, {items} in the LASzip items",
                header.record_len
            ),
        ));
    }
    Ok(())
}

/// Checks a LAZ file's chunk table before `laz` sizes allocations from it: where the table's
/// offset (the 8 bytes where the points begin; −1: none written) lies in the file, its chunk
/// count must not pass the point count (a chunk holds at least one point). A damaged count
/// asked `laz` for 34 GB and aborted; an offset outside the file the decoder reports itself.
/// Returns where each chunk begins and its bytes, `None` where there is no table to check.
fn check_chunk_table(
    path: &Path,
    header: &LasHeader,
    vlr: &laz::LazVlr,
    file: &mut File,
    len: u64,
) -> Result<Option<Vec<(u64, u64)>>> {
    use std::io::Read;
    let mut at = [0u8; 8];
    file.seek(SeekFrom::Start(u64::from(header.point_offset)))
        .and_then(|_| file.read_exact(&mut at))
        .map_err(|_| Error::format(path, "LAZ: the file ends before its points"))?;
    let table = i64::from_le_bytes(at);
    if table == -1 {
        return Ok(None);
    }
    let start = u64::from(header.point_offset) + 8;
    if table < start as i64 || table as u64 + 8 > len {
        // Outside the file: the decoder says so itself (after naming what else is wrong with
        // the file, as a bad compressor), without sizing anything from it.
        return Ok(None);
    }
    let mut head = [0u8; 8];
    file.seek(SeekFrom::Start(table as u64))
        .and_then(|_| file.read_exact(&mut head))
        .map_err(|e| Error::io(path, e))?;
    let chunks = u32::from_le_bytes(head[4..8].try_into().expect("4 bytes"));
    // A chunk holds at least one point and begins with it stored raw (at least 8 bytes here,
    // to be safe): a damaged point count of 3.4e9 let a damaged chunk count through, and the
    // table's entries asked for 3.7 GB.
    let room = (table as u64 - start) / 8;
    if u64::from(chunks) > header.count.max(1) || u64::from(chunks) > room.max(1) {
        return Err(Error::format(
            path,
            format!(
                "LAZ: the chunk table lists {chunks} chunks for {} points in {} bytes",
                header.count,
                table as u64 - start
            ),
        ));
    }
    // The entries size `laz`'s buffers: its largest chunk's point count (a fuzzed fixed chunk
    // size of 3.85e9 for 1,000 points asked for 3.85 GB and aborted) and each chunk's bytes.
    file.seek(SeekFrom::Start(u64::from(header.point_offset)))
        .map_err(|e| Error::io(path, e))?;
    let table = crate::interrupt::guarded(path, "reading its chunk table", || {
        laz::laszip::ChunkTable::read_from(&mut *file, vlr)
            .map_err(|e| Error::format(path, format!("LAZ: the chunk table: {e}")))
    })?;
    let most = header.count.max(1 << 24);
    let mut chunks = Vec::with_capacity(table.as_ref().len());
    let mut at = start;
    for (k, entry) in table.as_ref().iter().enumerate() {
        chunks.push((at, entry.byte_count));
        at = at.saturating_add(entry.byte_count);
        if entry.point_count > most || entry.byte_count > len {
            return Err(Error::format(
                path,
                format!(
                    "LAZ: chunk {} of the chunk table claims {} points in {} bytes, for {} points \
                     in a file of {len} bytes",
                    k + 1,
                    entry.point_count,
                    entry.byte_count,
                    header.count
                ),
            ));
        }
    }
    Ok(Some(chunks))
}

/// Why LASzip data that no LAZ version defines cannot be read.
const NEWER_OR_DAMAGED: &str = "the file is damaged or was written by a newer tool";

/// A `laz` error in words: what the file holds and why it cannot be read, after `context`
/// (where in the file, or empty). What `laz` finds in the LASzip VLR (an item type, an item
/// version, a compressor that no LAZ version defines) and a body that ends early are said
/// plainly; any other error keeps `laz`'s own words, after `LAZ: `.
fn laz_message(context: &str, e: &laz::LasZipError) -> String {
    use laz::LasZipError as E;
    let words = match e {
        E::UnknownLazItem(t) => format!(
            "its LAZ compression uses item type {t}, which no LAZ version defines: \
             {NEWER_OR_DAMAGED}"
        ),
        E::UnsupportedLazItemVersion(item, version) => version_words(*item, *version),
        E::UnknownCompressorType(c) => format!(
            "its LAZ compression names compressor {c}, which no LAZ version defines (LASzip's \
             are 0 to 3): {NEWER_OR_DAMAGED}"
        ),
        E::UnsupportedCompressorType(laz::laszip::CompressorType::None) => {
            "its LASzip VLR names compressor 0 (no compression) although the header marks the \
             points compressed: the file is damaged"
                .to_string()
        }
        E::MissingChunkTable => {
            "its LAZ chunk table, which reading its chunks needs, is missing: the file is \
             damaged or was cut short"
                .to_string()
        }
        E::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            "its compressed points end early: the file is truncated".to_string()
        }
        other => return format!("LAZ: {context}{other}"),
    };
    format!("{context}{words}")
}

/// A `las` error of reading a LAZ file: its `laz` errors in [`laz_message`]'s words.
fn las_message(context: &str, e: &las::Error) -> String {
    match e {
        las::Error::LasZipError(e) => laz_message(context, e),
        other => format!("LAZ: {context}{other}"),
    }
}

/// Words for an item of a LASzip VLR.
fn item_words(item: laz::LazItemType) -> String {
    use laz::LazItemType as T;
    match item {
        T::Byte(n) => format!("its {n} extra bytes"),
        T::Point10 => "its point fields (formats 0-5)".into(),
        T::GpsTime => "its GPS times".into(),
        T::RGB12 => "its RGB colors".into(),
        T::WavePacket13 => "its wave packets".into(),
        T::Point14 => "its point fields (formats 6-10)".into(),
        T::RGB14 => "its RGB colors (formats 7-10)".into(),
        T::RGBNIR14 => "its RGB and NIR colors".into(),
        T::WavePacket14 => "its wave packets (formats 9-10)".into(),
        T::Byte14(n) => format!("its {n} extra bytes (formats 6-10)"),
    }
}

/// An item of a LASzip VLR in a version of its encoding that LASzip does not define for it.
fn version_words(item: laz::LazItemType, version: u16) -> String {
    format!(
        "its LAZ compression stores {} in version {version} of their encoding, which no LAZ \
         version defines for them: {NEWER_OR_DAMAGED}",
        item_words(item)
    )
}

/// Whether `laz` decodes `item` in its version: 1 and 2 for the items of point formats 0–5,
/// 3 and 4 for those of formats 6–10 (LASzip defines no others).
fn known_version(item: &laz::LazItem) -> bool {
    use laz::LazItemType as T;
    match item.item_type() {
        T::Byte(_) | T::Point10 | T::GpsTime | T::RGB12 | T::WavePacket13 => {
            matches!(item.version(), 1 | 2)
        }
        _ => matches!(item.version(), 3 | 4),
    }
}

/// The LASzip VLR of a LAZ file's header, with its coder and item versions checked: `laz`
/// reads the coder without checking it (LASzip's only coder is 0, arithmetic coding), and finds
/// an item version it does not decode only when it starts decoding.
fn laszip_vlr(path: &Path, header: &LasHeader) -> Result<laz::LazVlr> {
    let data = header.laszip_vlr.as_deref().unwrap_or_default();
    let vlr =
        laz::LazVlr::from_buffer(data).map_err(|e| Error::format(path, laz_message("", &e)))?;
    // A VLR that parsed holds its compressor and coder (2 bytes each) and more.
    let coder = u16::from_le_bytes([data[2], data[3]]);
    if coder != 0 {
        return Err(Error::format(
            path,
            format!(
                "its LAZ compression uses coder {coder}, which no LAZ version defines (LASzip's \
                 only coder is 0, arithmetic coding): {NEWER_OR_DAMAGED}"
            ),
        ));
    }
    if let Some(item) = vlr.items().iter().find(|i| !known_version(i)) {
        return Err(Error::format(
            path,
            version_words(item.item_type(), item.version()),
        ));
    }
    Ok(vlr)
}

/// Everything of a LAZ file that `laz` sizes buffers by, checked before it reads any
/// ([`check_items`], [`check_chunk_table`], [`check_layers`]; a point-wise body is one chunk);
/// returns the parsed LASzip VLR.
fn check_laz(path: &Path, header: &LasHeader) -> Result<laz::LazVlr> {
    let vlr = laszip_vlr(path, header)?;
    check_items(path, header, &vlr)?;
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let start = u64::from(header.point_offset);
    let chunks = if header.laz_compressor == Some(1) {
        vec![(start, len.saturating_sub(start))]
    } else {
        match check_chunk_table(path, header, &vlr, &mut file, len)? {
            Some(chunks) => chunks,
            None => return Ok(vlr),
        }
    };
    check_layers(path, header, &vlr, &mut file, &chunks)?;
    Ok(vlr)
}

/// The layers of a LASzip item in a layered chunk, `None` for an item that is not layered.
fn layers(item: &laz::LazItem) -> Option<u64> {
    use laz::LazItemType as T;
    match item.item_type() {
        T::Point14 => Some(9),
        T::RGB14 | T::WavePacket14 => Some(1),
        T::RGBNIR14 => Some(2),
        T::Byte14(n) => Some(u64::from(n)),
        _ => None,
    }
}

/// Checks the layer sizes at the head of each layered chunk (`chunks`: where each begins, and
/// its bytes) against the chunk's bytes: `laz` resizes a buffer to each size it reads there
/// before reading it (damaged sizes asked for 3.6 and 4.1 GB and aborted). A layered chunk is
/// its first point raw, a point count, then one u32 size per layer of each item.
fn check_layers(
    path: &Path,
    header: &LasHeader,
    vlr: &laz::LazVlr,
    file: &mut File,
    chunks: &[(u64, u64)],
) -> Result<()> {
    use std::io::Read;
    let Some(count) = vlr
        .items()
        .iter()
        .map(layers)
        .sum::<Option<u64>>()
        .filter(|&n| n > 0)
    else {
        return Ok(());
    };
    let sizes_at = u64::from(header.record_len) + 4;
    // No item has more layers than bytes ([`check_items`] matched their bytes to the record
    // length), so this buffer is at most five records long.
    let head = sizes_at + 4 * count;
    let mut bytes = vec![0u8; head as usize];
    for (k, &(at, len)) in chunks.iter().enumerate() {
        if len == 0 {
            continue;
        }
        let bad = |what: String| {
            Error::format(
                path,
                format!("LAZ: chunk {} of {}: {what}", k + 1, chunks.len()),
            )
        };
        if len < head {
            return Err(bad(format!(
                "{len} bytes cannot hold its first point and {count} layer sizes"
            )));
        }
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(&mut bytes))
            .map_err(|_| bad("the file ends within it".into()))?;
        let layers: u64 = (0..count as usize)
            .map(|i| u64::from(le_u32(&bytes, sizes_at as usize + 4 * i)))
            .sum();
        if layers > len - head {
            return Err(bad(format!(
                "its layers claim {layers} bytes, past its {len} bytes"
            )));
        }
    }
    Ok(())
}

/// An error of the `las` crate's writer on `output`: its I/O errors are errors writing the
/// output (exit 1), the others the crate refusing what it was given.
/// What outputs name in the header's generating-software field (the system identifier is the
/// input's): `rigidcells` and its version.
pub const SOFTWARE: &str = concat!("rigidcells ", env!("CARGO_PKG_VERSION"));

/// `text` as a LAS text field of `N` bytes: cut to `N`, zero-padded.
pub(crate) fn text_field<const N: usize>(text: &str) -> [u8; N] {
    let mut field = [0u8; N];
    let n = text.len().min(N);
    field[..n].copy_from_slice(&text.as_bytes()[..n]);
    field
}

fn write_error(output: &Path, e: las::Error) -> Error {
    match e {
        las::Error::Io(e) => Error::write(output, e),
        other => Error::format(output, other.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::{decode_coordinates, encode_coordinates, round_to_i32};
    use crate::rigid::Vect;

    #[test]
    fn coordinates_round_to_the_nearest_step_and_decode_back() {
        let moved = [
            Vect::<3>::new(1000.006, -1000.006, 0.004),
            Vect::<3>::new(999.994, -999.994, -0.005),
        ];
        let e = encode_coordinates(&moved, [0.01; 3], [1000.0, 0.0, 0.0], false).unwrap();
        assert_eq!(e.records, vec![[1, -100001, 0], [-1, -99999, -1]]);
        assert_eq!((e.scale, e.offset), ([0.01; 3], [1000.0, 0.0, 0.0]));
        assert!(e.notes.is_empty());
        let back = decode_coordinates(&[[1, -100001, 0], [-1, -99999, -1]], e.scale, e.offset);
        assert_eq!(
            back.unwrap(),
            vec![
                Vect::<3>::new(1000.01, -1000.01, 0.0),
                Vect::<3>::new(999.99, -999.99, -0.01)
            ]
        );
    }

    #[test]
    fn an_overflow_is_reframed_as_the_writer_does_or_refused() {
        let moved = [
            Vect::<3>::new(0.0, 0.0, 3.0e7),
            Vect::<3>::new(1.0, 0.0, 3.0e7 + 100.0),
        ];
        let e = encode_coordinates(&moved, [0.01; 3], [0.0; 3], true).unwrap();
        assert_eq!(e.scale, [0.01; 3]);
        assert_eq!(e.offset, [0.0, 0.0, 30000050.0]);
        assert_eq!(e.records, vec![[0, 0, -5000], [100, 0, 5000]]);
        assert_eq!(
            e.notes,
            ["axis z: moved coordinates overflow the input's encoding; offset 0 -> 30000050"]
        );
        let refused = encode_coordinates(&moved, [0.01; 3], [0.0; 3], false).unwrap_err();
        let text = refused.to_string();
        assert!(
            text.contains("axis z") && text.contains("30000100"),
            "{text}"
        );
        assert!(encode_coordinates(&moved, [0.0, 0.01, 0.01], [0.0; 3], true).is_err());
        assert!(decode_coordinates(&[[0; 3]], [0.01; 3], [f64::NAN, 0.0, 0.0]).is_err());
    }

    #[test]
    fn rounding_matches_f64_round() {
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            0.49999999999999994,
            -0.49999999999999994,
            4503599627370495.5,
            i32::MAX as f64,
            i32::MAX as f64 + 0.49,
            i32::MAX as f64 + 0.5,
            i32::MIN as f64,
            i32::MIN as f64 - 0.49,
            i32::MIN as f64 - 0.5,
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
        ];
        let mut x = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let unit = (x >> 11) as f64 / (1u64 << 53) as f64;
            values.push((unit - 0.5) * 5e9);
            values.push((unit - 0.5) * 20.0);
        }
        for r in values {
            let reference = r.round();
            let expected = (reference >= i32::MIN as f64 && reference <= i32::MAX as f64)
                .then_some(reference as i32);
            assert_eq!(round_to_i32(r), expected, "{r}");
        }
    }
}
