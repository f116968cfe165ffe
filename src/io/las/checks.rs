//! Checks of a LAS/LAZ file before the `las` and `laz` crates read it, and their errors in
//! words.
//!
//! Both crates size buffers from numbers in the file (EVLR lengths, the LASzip items, the chunk
//! table, the layer sizes of layered chunks) and some panic on contradictions; every such number
//! is checked here against the file first, so a damaged file is a format error that names what
//! is wrong, never an allocation of gigabytes or a panic.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use super::header::LasHeader;
use super::raw::{EVLR_HEADER, HEADER_1_4, RawHeader, RawVlrHeader, le_u32};
use crate::error::{Error, Result};

/// Checks that a LAS 1.4 file's extended VLRs lie within it before `las` reads them: it sizes
/// each one's buffer from its 8-byte length (a damaged length asked for 35 TB and aborted).
pub(super) fn check_evlrs(path: &Path, header: &LasHeader) -> Result<()> {
    if header.evlr_count == 0 {
        return Ok(());
    }
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    // Only LAS 1.4 has EVLRs, and the parsed header checked that its 375 bytes are all there.
    let mut bytes = [0u8; HEADER_1_4];
    file.read_exact(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    let mut at = RawHeader::from_bytes(&bytes)
        .expect("a whole header")
        .evlr_start;
    if at == 0 {
        return Ok(()); // `las` reads none
    }
    let bad = |m: String| Err(Error::format(path, m));
    const HEADER: u64 = EVLR_HEADER as u64;
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
        let data = RawVlrHeader::from_bytes(&head, true).len;
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
pub(super) fn laz_message(context: &str, e: &laz::LasZipError) -> String {
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
pub(super) fn las_message(context: &str, e: &las::Error) -> String {
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
pub(super) fn laszip_vlr(path: &Path, header: &LasHeader) -> Result<laz::LazVlr> {
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
pub(super) fn check_laz(path: &Path, header: &LasHeader) -> Result<laz::LazVlr> {
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
