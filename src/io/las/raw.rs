//! The LAS public header block and VLR headers as bytes: every field where the LAS
//! specification puts it, read and written without judging it ([`super::header`] validates).
//!
//! Keeping the byte layout here, in one place, lets every writer make or patch a header by
//! setting fields, and a header read and written back is the same bytes (`f64` fields keep their
//! bits, text fields their padding).

/// Size of the public header block of LAS 1.0–1.2.
pub(super) const HEADER_1_0: usize = 227;
/// Size of the public header block of LAS 1.3 (adds the waveform data start).
pub(super) const HEADER_1_3: usize = 235;
/// Size of the public header block of LAS 1.4 (adds EVLRs and 64-bit point counts).
pub(super) const HEADER_1_4: usize = 375;
/// Size of a VLR's header.
pub(super) const VLR_HEADER: usize = 54;
/// Size of an extended VLR's header.
pub(super) const EVLR_HEADER: usize = 60;

/// Offset of the field "offset to point data", which says how far the header and VLRs reach.
const POINT_OFFSET_AT: usize = 96;

/// The public header block, field by field (LAS 1.0–1.4); fields a version lacks are zero.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct RawHeader {
    /// `LASF` in a LAS file.
    pub file_signature: [u8; 4],
    /// File source ID.
    pub file_source_id: u16,
    /// Global encoding bits (GPS time type, waveform location, WKT).
    pub global_encoding: u16,
    /// Project ID (GUID).
    pub guid: [u8; 16],
    /// Major and minor version.
    pub version: (u8, u8),
    /// System identifier, NUL-padded.
    pub system_identifier: [u8; 32],
    /// Generating software, NUL-padded.
    pub generating_software: [u8; 32],
    /// File creation day of the year.
    pub creation_day: u16,
    /// File creation year.
    pub creation_year: u16,
    /// Header size in bytes.
    pub header_size: u16,
    /// Offset of the first point record.
    pub point_offset: u32,
    /// Number of VLRs.
    pub vlr_count: u32,
    /// Point data record format; bits 6 and 7 mark LAZ compression.
    pub point_format: u8,
    /// Bytes per point record.
    pub record_len: u16,
    /// Number of points (32-bit, legacy in LAS 1.4).
    pub legacy_count: u32,
    /// Points by return 1–5 (32-bit, legacy in LAS 1.4).
    pub legacy_by_return: [u32; 5],
    /// Scale per axis.
    pub scale: [f64; 3],
    /// Offset per axis.
    pub offset: [f64; 3],
    /// Maximum per axis.
    pub max: [f64; 3],
    /// Minimum per axis.
    pub min: [f64; 3],
    /// Start of the waveform data packet record (LAS 1.3+).
    pub waveform_start: u64,
    /// Start of the first EVLR (LAS 1.4).
    pub evlr_start: u64,
    /// Number of EVLRs (LAS 1.4).
    pub evlr_count: u32,
    /// Number of points (LAS 1.4).
    pub count: u64,
    /// Points by return 1–15 (LAS 1.4).
    pub by_return: [u64; 15],
}

/// A little-endian `u16` at `at`.
pub(super) fn le_u16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}
/// A little-endian `u32` at `at`.
pub(super) fn le_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}
/// A little-endian `u64` at `at`.
pub(super) fn le_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}
fn le_f64(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

/// A NUL-terminated text field as text (bytes after the first NUL are padding).
pub(super) fn text(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).trim().to_string()
}

/// `text` as a LAS text field of `N` bytes: cut to `N`, zero-padded.
pub(super) fn text_field<const N: usize>(text: &str) -> [u8; N] {
    let mut field = [0u8; N];
    let n = text.len().min(N);
    field[..n].copy_from_slice(&text.as_bytes()[..n]);
    field
}

/// The size of the public header block that LAS 1.`minor` defines.
pub(super) fn header_size_for(minor: u8) -> usize {
    match minor {
        0..=2 => HEADER_1_0,
        3 => HEADER_1_3,
        _ => HEADER_1_4,
    }
}

/// The offset to the point data of a file starting with `prefix`, when `prefix` is long enough
/// to hold it and starts with `LASF`.
pub(super) fn point_offset_of(prefix: &[u8]) -> Option<u32> {
    (prefix.len() >= POINT_OFFSET_AT + 4 && prefix.starts_with(b"LASF"))
        .then(|| le_u32(prefix, POINT_OFFSET_AT))
}

impl RawHeader {
    /// The header at the start of `b`, which holds at least [`HEADER_1_0`] bytes (`None` when it
    /// holds fewer). The LAS 1.3 and 1.4 fields are read when the version has them and `b`
    /// holds them, and are zero otherwise.
    pub(super) fn from_bytes(b: &[u8]) -> Option<Self> {
        if b.len() < HEADER_1_0 {
            return None;
        }
        let f3 = |at: usize| [le_f64(b, at), le_f64(b, at + 8), le_f64(b, at + 16)];
        let version = (b[24], b[25]);
        let mut h = Self {
            file_signature: b[0..4].try_into().expect("4 bytes"),
            file_source_id: le_u16(b, 4),
            global_encoding: le_u16(b, 6),
            guid: b[8..24].try_into().expect("16 bytes"),
            version,
            system_identifier: b[26..58].try_into().expect("32 bytes"),
            generating_software: b[58..90].try_into().expect("32 bytes"),
            creation_day: le_u16(b, 90),
            creation_year: le_u16(b, 92),
            header_size: le_u16(b, 94),
            point_offset: le_u32(b, POINT_OFFSET_AT),
            vlr_count: le_u32(b, 100),
            point_format: b[104],
            record_len: le_u16(b, 105),
            legacy_count: le_u32(b, 107),
            legacy_by_return: std::array::from_fn(|i| le_u32(b, 111 + 4 * i)),
            scale: f3(131),
            offset: f3(155),
            max: [le_f64(b, 179), le_f64(b, 195), le_f64(b, 211)],
            min: [le_f64(b, 187), le_f64(b, 203), le_f64(b, 219)],
            waveform_start: 0,
            evlr_start: 0,
            evlr_count: 0,
            count: 0,
            by_return: [0; 15],
        };
        if version.1 >= 3 && b.len() >= HEADER_1_3 {
            h.waveform_start = le_u64(b, 227);
        }
        if version.1 >= 4 && b.len() >= HEADER_1_4 {
            h.evlr_start = le_u64(b, 235);
            h.evlr_count = le_u32(b, 243);
            h.count = le_u64(b, 247);
            h.by_return = std::array::from_fn(|i| le_u64(b, 255 + 8 * i));
        }
        Some(h)
    }

    /// The header as the bytes of its version's public header block ([`header_size_for`]; the
    /// header size field is written as it is, so a larger block keeps its tail elsewhere).
    pub(super) fn to_bytes(&self) -> Vec<u8> {
        let minor = self.version.1;
        let mut b = Vec::with_capacity(HEADER_1_4);
        b.extend_from_slice(&self.file_signature);
        b.extend_from_slice(&self.file_source_id.to_le_bytes());
        b.extend_from_slice(&self.global_encoding.to_le_bytes());
        b.extend_from_slice(&self.guid);
        b.extend_from_slice(&[self.version.0, self.version.1]);
        b.extend_from_slice(&self.system_identifier);
        b.extend_from_slice(&self.generating_software);
        b.extend_from_slice(&self.creation_day.to_le_bytes());
        b.extend_from_slice(&self.creation_year.to_le_bytes());
        b.extend_from_slice(&self.header_size.to_le_bytes());
        b.extend_from_slice(&self.point_offset.to_le_bytes());
        b.extend_from_slice(&self.vlr_count.to_le_bytes());
        b.push(self.point_format);
        b.extend_from_slice(&self.record_len.to_le_bytes());
        b.extend_from_slice(&self.legacy_count.to_le_bytes());
        for n in self.legacy_by_return {
            b.extend_from_slice(&n.to_le_bytes());
        }
        for v in self.scale.iter().chain(&self.offset) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for a in 0..3 {
            b.extend_from_slice(&self.max[a].to_le_bytes());
            b.extend_from_slice(&self.min[a].to_le_bytes());
        }
        debug_assert_eq!(b.len(), HEADER_1_0);
        if minor >= 3 {
            b.extend_from_slice(&self.waveform_start.to_le_bytes());
        }
        if minor >= 4 {
            b.extend_from_slice(&self.evlr_start.to_le_bytes());
            b.extend_from_slice(&self.evlr_count.to_le_bytes());
            b.extend_from_slice(&self.count.to_le_bytes());
            for n in self.by_return {
                b.extend_from_slice(&n.to_le_bytes());
            }
        }
        debug_assert_eq!(b.len(), header_size_for(minor));
        b
    }
}

/// The header of a VLR (54 bytes) or an extended VLR (60 bytes, with a 64-bit length).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct RawVlrHeader {
    /// Reserved.
    pub reserved: u16,
    /// User id, NUL-padded.
    pub user_id: [u8; 16],
    /// Record id.
    pub record_id: u16,
    /// Payload length in bytes.
    pub len: u64,
    /// Description, NUL-padded.
    pub description: [u8; 32],
}

impl RawVlrHeader {
    /// The header at the start of `b`, which holds at least [`VLR_HEADER`] bytes, or
    /// [`EVLR_HEADER`] with `extended`.
    pub(super) fn from_bytes(b: &[u8], extended: bool) -> Self {
        let (len, description_at) = if extended {
            (le_u64(b, 20), 28)
        } else {
            (u64::from(le_u16(b, 20)), 22)
        };
        Self {
            reserved: le_u16(b, 0),
            user_id: b[2..18].try_into().expect("16 bytes"),
            record_id: le_u16(b, 18),
            len,
            description: b[description_at..description_at + 32]
                .try_into()
                .expect("32 bytes"),
        }
    }

    /// The header as bytes; a VLR's length is cut to its 16 bits' largest value.
    pub(super) fn to_bytes(&self, extended: bool) -> Vec<u8> {
        let mut h = Vec::with_capacity(EVLR_HEADER);
        h.extend_from_slice(&self.reserved.to_le_bytes());
        h.extend_from_slice(&self.user_id);
        h.extend_from_slice(&self.record_id.to_le_bytes());
        if extended {
            h.extend_from_slice(&self.len.to_le_bytes());
        } else {
            h.extend_from_slice(&(self.len.min(u64::from(u16::MAX)) as u16).to_le_bytes());
        }
        h.extend_from_slice(&self.description);
        h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bytes from a seeded xorshift: every field gets values a writer would not choose (NaN
    /// and subnormal bits in the `f64` fields, text without a terminating NUL).
    fn noise(n: usize, seed: u64) -> Vec<u8> {
        let mut x = seed.max(1);
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                (x >> 24) as u8
            })
            .collect()
    }

    /// A public header block of every version, and VLR and EVLR headers, read and written
    /// back are the same bytes, whatever the fields hold.
    #[test]
    fn headers_write_back_as_read() {
        for seed in 1..=50u64 {
            for minor in 0..=4u8 {
                let mut bytes = noise(header_size_for(minor), seed * 7 + u64::from(minor));
                bytes[..4].copy_from_slice(b"LASF");
                (bytes[24], bytes[25]) = (1, minor);
                let h = RawHeader::from_bytes(&bytes).unwrap();
                assert_eq!(h.to_bytes(), bytes, "LAS 1.{minor}, seed {seed}");
            }
            for (extended, size) in [(false, VLR_HEADER), (true, EVLR_HEADER)] {
                let bytes = noise(size, seed);
                let v = RawVlrHeader::from_bytes(&bytes, extended);
                assert_eq!(v.to_bytes(extended), bytes, "seed {seed}");
            }
        }
    }
}
