//! The validated LAS header: the fields the rest of the code reads, from a header and VLRs that
//! [`LasHeader::parse`] has checked against the file (counts that lie, VLRs that overrun the
//! point data, truncated bodies, LAS 1.5 give precise errors before any point is read).

use std::fs::File;
use std::io::Read;
use std::path::Path;

use super::coords::frame_error;
use super::raw::{
    HEADER_1_0, HEADER_1_4, RawHeader, RawVlrHeader, VLR_HEADER, header_size_for, le_u16,
    point_offset_of, text,
};
use crate::error::{Error, Result};

/// What outputs name in the header's generating-software field (the system identifier is the
/// input's): `rigidcells` and its version.
pub const SOFTWARE: &str = concat!("rigidcells ", env!("CARGO_PKG_VERSION"));

/// Minimum record length of each point data record format.
const RECORD_LEN: [u16; 11] = [20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67];

/// The standard length of point format `format`'s records (0–10), without extra bytes.
pub(super) fn standard_record_len(format: u8) -> usize {
    usize::from(RECORD_LEN[format as usize])
}

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

/// The CRS the `LASF_Projection` records among `records` declare ([`crate::crs::of_projection`]).
pub fn crs_of(records: &[VlrRecord]) -> Option<crate::crs::Crs> {
    crate::crs::of_projection(|id| {
        records
            .iter()
            .find(|r| r.is("LASF_Projection", id))
            .map(|r| r.data.as_slice())
    })
}

impl VlrRecord {
    /// Whether it is the record `user_id`/`record_id`.
    pub fn is(&self, user_id: &str, record_id: u16) -> bool {
        self.user_id == user_id && self.record_id == record_id
    }

    /// Every VLR, then every EVLR, of the `las` crate's header `h`, with its payload. A VLR too
    /// long for a VLR's 16-bit length is marked extended.
    pub(super) fn all_of(h: &las::Header) -> Vec<Self> {
        let record = |v: &las::Vlr, extended: bool| Self {
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
        let Some(raw) = RawHeader::from_bytes(prefix) else {
            return Err(err(format!(
                "the header is truncated ({} bytes; a LAS header has at least {HEADER_1_0})",
                prefix.len()
            )));
        };
        let version = raw.version;
        if version.0 != 1 || version.1 > 4 {
            return Err(err(format!(
                "LAS {}.{} is not supported (rigidcells reads LAS 1.0 to 1.4)",
                version.0, version.1
            )));
        }
        let header_size = raw.header_size;
        let needed = header_size_for(version.1);
        if (header_size as usize) < needed || (header_size as usize) > prefix.len() {
            return Err(err(format!(
                "header size {header_size} is wrong for LAS {}.{} (at least {needed}) or the header is truncated",
                version.0, version.1
            )));
        }
        let point_offset = raw.point_offset;
        if point_offset < header_size as u32 || point_offset as u64 > file_len {
            return Err(err(format!(
                "the offset to the point data ({point_offset}) lies outside the file ({file_len} bytes) or inside the header"
            )));
        }
        if (point_offset as usize) > prefix.len() {
            return Err(err("the VLRs are truncated".into()));
        }
        let vlr_count = raw.vlr_count;
        let mut vlrs = Vec::new();
        let mut laz_compressor = None;
        let mut laszip_vlr = None;
        let mut at = header_size as usize;
        for k in 0..vlr_count {
            if at + VLR_HEADER > point_offset as usize {
                return Err(err(format!(
                    "VLR {} of {vlr_count} would start past the point data at byte {point_offset}: the header's VLR count or a VLR length is wrong",
                    k + 1
                )));
            }
            let vlr = RawVlrHeader::from_bytes(&prefix[at..], false);
            let (user_id, len) = (text(&vlr.user_id), vlr.len);
            let data = at + VLR_HEADER;
            if user_id == "laszip encoded"
                && vlr.record_id == 22204
                && len >= 2
                && data + 2 <= point_offset as usize
            {
                laz_compressor = Some(le_u16(prefix, data));
                laszip_vlr =
                    Some(prefix[data..(data + len as usize).min(point_offset as usize)].to_vec());
            }
            vlrs.push(VlrInfo {
                user_id,
                record_id: vlr.record_id,
                len,
                description: text(&vlr.description),
            });
            at = data + len as usize;
            if at > point_offset as usize {
                return Err(err(format!(
                    "VLR {} of {vlr_count} runs past the start of the point data (byte {point_offset})",
                    k + 1
                )));
            }
        }
        let format = raw.point_format & 0x3f;
        let compressed = raw.point_format & 0x80 != 0
            || vlrs
                .iter()
                .any(|v| v.user_id == "laszip encoded" && v.record_id == 22204);
        if format > 10 {
            return Err(err(format!(
                "point data record format {format} is not 0–10"
            )));
        }
        let record_len = raw.record_len;
        if record_len < RECORD_LEN[format as usize] {
            return Err(err(format!(
                "records of {record_len} bytes are too short for point format {format} (at least {})",
                RECORD_LEN[format as usize]
            )));
        }
        // `raw.count` is zero before LAS 1.4, where only the legacy count exists.
        let count = if raw.count != 0 {
            raw.count
        } else {
            u64::from(raw.legacy_count)
        };
        if count == 0 {
            return Err(err("the file holds no points".into()));
        }
        // A frame that could not hold the moved coordinates is refused here, before the solve.
        if let Some(why) = frame_error(&raw.scale, &raw.offset) {
            return Err(err(why));
        }
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
        Ok(Self {
            version,
            header_size,
            point_offset,
            format,
            compressed,
            record_len,
            count,
            scale: raw.scale,
            offset: raw.offset,
            min: raw.min,
            max: raw.max,
            global_encoding: raw.global_encoding,
            vlrs,
            evlr_count: raw.evlr_count,
            laz_compressor,
            laszip_vlr,
            system: text(&raw.system_identifier),
            software: text(&raw.generating_software),
            file_source_id: raw.file_source_id,
            guid: raw.guid,
            creation: (raw.creation_day, raw.creation_year),
        })
    }

    /// Reads and parses the header of `path` without reading the points.
    pub fn read(path: &Path) -> Result<Self> {
        let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        let mut prefix = vec![0u8; len.min(HEADER_1_4 as u64) as usize];
        file.read_exact(&mut prefix)
            .map_err(|e| Error::io(path, e))?;
        if let Some(offset) = point_offset_of(&prefix).map(u64::from)
            && offset > prefix.len() as u64
            && offset <= len
        {
            // The VLRs up to the point data, after the bytes already read.
            let have = prefix.len();
            prefix.resize(offset as usize, 0);
            file.read_exact(&mut prefix[have..])
                .map_err(|e| Error::io(path, e))?;
        }
        Self::parse(path, &prefix, len)
    }

    /// Byte offset of the class in a record.
    pub(super) fn class_at(&self) -> usize {
        if self.format >= 6 { 16 } else { 15 }
    }

    /// Whether the point format carries RGB (else [`LasHeader::color`] is the intensity).
    pub fn has_rgb(&self) -> bool {
        matches!(self.format, 2 | 3 | 5 | 7 | 8 | 10)
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

/// A record's return number: 3 bits in formats 0–5 (`five_bits`: 5-bit classes), 4 bits after.
pub(super) fn return_number(record: &[u8], five_bits: bool) -> u8 {
    record[14] & if five_bits { 0x07 } else { 0x0f }
}
