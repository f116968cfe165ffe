//! Reading a LAS or LAZ file as a [`Source`]: an uncompressed body is memory-mapped and decoded
//! in place; a chunked LAZ body is decompressed by the `las` crate in large batches (its
//! parallel codec works per call); a point-wise LAZ body (compressor 1, no chunk table) by
//! `laz`'s sequential decompressor. Every record keeps its bytes; only `X Y Z` and the class
//! are decoded.

use std::fs::File;
use std::io::{BufReader, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use las::{Builder, LazParallelism, PointData, PointDataBuilder, ReaderOptions};
use memmap2::Mmap;

use super::Input;
use super::LAZ_BATCH;
use super::checks::{check_evlrs, check_laz, las_message, laszip_vlr, laz_message};
use super::header::{LasHeader, VlrRecord, return_number};
use super::output;
use crate::error::{Error, Result};
use crate::io::mapped;
use crate::io::stream::{Bounds, Chunk, Sink, Source};
use crate::rigid::Vect;

/// Where the records come from.
enum Body {
    /// An uncompressed body, memory-mapped.
    Mapped(Arc<Mmap>),
    /// The reader, its last batch of decoded records, and how many of them were handed out.
    Laz(Box<las::Reader>, PointData, usize),
    /// Point-wise LAZ (compressor 1): one stream without a chunk table, decoded sequentially.
    PointWise(Box<laz::LasZipDecompressor<'static, BufReader<File>>>),
}

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
        self.las_header()
            .map(|h| VlrRecord::all_of(&h))
            .unwrap_or_default()
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

    fn crs(&self) -> Option<crate::crs::Crs> {
        super::crs_of(&self.vlr_records())
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
        let map = match &self.body {
            Body::Mapped(map) => Some(map),
            _ => None,
        };
        let input = Input {
            path: &self.path,
            header: &self.header,
            map,
            max_return: self.max_return,
            las_header: &|| self.las_header(),
        };
        output::sink(&input, output, bounds)
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
