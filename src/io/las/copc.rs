//! COPC output (`-o out.copc.laz`): a cloud-optimized point cloud, built while streaming with
//! bounded memory.
//!
//! A COPC file is a LAS 1.4 LAZ file whose points are grouped into the nodes of an octree,
//! each node one LAZ chunk (variable-size chunks), with a `copc` info VLR first (the octree's
//! cube and spacing, where the hierarchy is) and a `copc` hierarchy EVLR listing every node
//! (its key, the file offset and size of its chunk, its point count). Readers fetch the nodes
//! a view needs and no others.
//!
//! **How it is built.** The sink converts each record to point format 6, 7 or 8 (formats 0–5
//! map to 6 or 7, their fields moved to the 1.4 layout; 9 and 10 lose their wave packet and
//! become 6 and 8, with a note) and appends it, with its moved coordinates, to a spill file
//! beside the output. At the end, with the bounds known, the cube is fixed and every record
//! gets the Morton code of its position in the cube (21 bits per axis); an external sort by
//! that code (sorted runs of at most `RUN_BYTES`, merged) walks the points in octree order,
//! where the points of any node, at any level, are contiguous. One pass then samples the
//! levels: a node of level `l` keeps the first point of each cell of a `2^7`-per-axis grid over
//! it (its *spacing* is the node's edge / 128) that no shallower node kept; points every level
//! down to [`MAX_LEVEL`] declined go to the deepest node. Each level's points go to a file of
//! their own, in octree order, so a node's points are contiguous there; the levels are then
//! compressed node by node into the output. Memory: one run, plus the merge's buffers.
//! Every point lands in exactly one node, inside that node's cube, and a node's ancestors all
//! hold points (the first point of a cell at level `l` lies in a cell of level `l − 1` whose
//! first point was kept there or higher).
//!
//! The input's VLRs are kept (the CRS WKT among them; LASzip's and an input COPC's own are
//! replaced), and its EVLRs after the hierarchy. Point formats 6–8 state their CRS as a WKT
//! (global encoding bit 4), which some COPC readers require: an input of formats 0–5 whose
//! CRS is only GeoTIFF keys gets the WKT of the EPSG code they name (its keys kept too); keys
//! that name no code, or a code without a known definition, are kept alone, with a note.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::coords::{Frame, encode, frame_words, on_frame};
use super::header::{LasHeader, SOFTWARE, VlrRecord, standard_record_len};
use super::raw::{EVLR_HEADER, HEADER_1_4, RawHeader, RawVlrHeader, VLR_HEADER, text_field};
use crate::error::{Error, Result};
use crate::io::stream::{Accepted, Chunk, OutFile, ResultSet, Sink, TempFile};
use crate::rigid::Vect;

/// The deepest octree level; points declined by every level down to it go to its nodes.
pub const MAX_LEVEL: u32 = 14;
/// Sampling cells per node edge at every level (`2^GRID_BITS`).
const GRID_BITS: u32 = 7;
/// Bytes of records sorted in memory at a time.
pub(crate) const RUN_BYTES: usize = 256 << 20;

/// Whether `path` names a COPC output (`*.copc.laz`).
pub fn is_copc(path: &Path) -> bool {
    path.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.to_ascii_lowercase().ends_with(".copc.laz"))
}

/// The sink of a COPC output; see the module docs.
pub(super) struct CopcSink {
    output: PathBuf,
    input: LasHeader,
    /// Output point format (6, 7 or 8) and record length (with the input's extra bytes).
    format: u8,
    record_len: usize,
    extra: usize,
    frame: Frame,
    vlrs: Vec<VlrRecord>,
    evlrs: Vec<VlrRecord>,
    spill: Option<(TempFile, BufWriter<OutFile>)>,
    count: u64,
    lo: [f64; 3],
    hi: [f64; 3],
    gps: (f64, f64),
    /// Points by return number (1–15).
    by_return: [u64; 15],
    /// Bytes of records sorted in memory at a time ([`RUN_BYTES`]).
    run_bytes: usize,
    buf: Vec<u8>,
    notes: Vec<String>,
}

impl CopcSink {
    pub(super) fn new(
        output: &Path,
        input: LasHeader,
        records: Vec<VlrRecord>,
        frame: Frame,
        mut notes: Vec<String>,
    ) -> Result<Self> {
        let format = match input.format {
            0 | 1 | 4 | 6 | 9 => 6,
            2 | 3 | 5 | 7 => 7,
            _ => 8,
        };
        if matches!(input.format, 4 | 5 | 9 | 10) {
            notes.push(format!(
                "COPC holds point formats 6-8: the wave packets of format {} are dropped, with \
                 the records that describe them",
                input.format
            ));
        } else if records.iter().any(is_waveform) {
            notes.push(
                "COPC holds point formats 6-8, without wave packets: the records that describe \
                 them are dropped"
                    .into(),
            );
        }
        if input.format < 6 {
            notes.push(format!(
                "point format {} becomes {format} (COPC holds formats 6-8): every field kept",
                input.format
            ));
        }
        let mut records = records;
        let crs = |id: u16| records.iter().any(|r| r.is("LASF_Projection", id));
        if crs(34735) && !crs(2112) {
            match geotiff_wkt(&records) {
                Ok((wkt, vertical)) => {
                    records.push(wkt);
                    notes.extend(vertical);
                }
                Err(why) => notes.push(format!(
                    "the CRS is kept as the input's GeoTIFF keys ({why}); LAS 1.4 point formats \
                     6-8 expect a WKT, which some COPC readers require"
                )),
            }
        }
        let extra = (input.record_len as usize).saturating_sub(standard_record_len(input.format));
        let keep = |r: &VlrRecord| {
            !(r.user_id == "copc" || r.is("laszip encoded", 22204) || is_waveform(r))
        };
        let (evlrs, vlrs) = records.into_iter().filter(keep).partition(|r| r.extended);
        let spill_name = output.with_file_name(format!(
            "{}.points",
            output.file_name().unwrap_or_default().to_string_lossy()
        ));
        Ok(Self {
            output: output.to_path_buf(),
            format,
            record_len: standard_record_len(format) + extra,
            extra,
            frame,
            vlrs,
            evlrs,
            spill: Some(TempFile::scratch(&spill_name)?),
            count: 0,
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
            gps: (f64::INFINITY, f64::NEG_INFINITY),
            by_return: [0; 15],
            run_bytes: RUN_BYTES,
            buf: Vec::new(),
            input,
            notes,
        })
    }

    /// The record `rec` (input format, coordinates already encoded) in the output format.
    fn convert(&mut self, rec: &[u8], out: &mut Vec<u8>) {
        let f = self.input.format;
        let start = out.len();
        out.extend_from_slice(&rec[..14]);
        let gps_at = match f {
            1 | 3 | 4 | 5 => Some(20),
            6.. => Some(22),
            _ => None,
        };
        let rgb_at = match f {
            2 => Some(20),
            3 | 5 => Some(28),
            7 | 8 | 10 => Some(30),
            _ => None,
        };
        if f >= 6 {
            out.extend_from_slice(&rec[14..22]);
        } else {
            let (b14, class) = (rec[14], rec[15]);
            out.push((b14 & 0x07) | ((b14 >> 3 & 0x07) << 4));
            // Flags: synthetic, key-point, withheld; scan direction and edge of flight line.
            out.push((class >> 5 & 0x07) | (b14 & 0xc0));
            out.push(class & 0x1f);
            out.push(rec[17]);
            let angle = ((rec[16] as i8) as f64 / 0.006).round() as i16;
            out.extend_from_slice(&angle.to_le_bytes());
            out.extend_from_slice(&rec[18..20]);
        }
        let gps = gps_at.map_or(0.0, |at| {
            f64::from_le_bytes(rec[at..at + 8].try_into().expect("8 bytes"))
        });
        out.extend_from_slice(&gps.to_le_bytes());
        if gps.is_finite() {
            self.gps = (self.gps.0.min(gps), self.gps.1.max(gps));
        }
        if self.format >= 7 {
            match rgb_at {
                Some(at) => out.extend_from_slice(&rec[at..at + 6]),
                None => out.extend_from_slice(&[0; 6]),
            }
        }
        if self.format == 8 {
            match f {
                8 | 10 => out.extend_from_slice(&rec[36..38]),
                _ => out.extend_from_slice(&[0; 2]),
            }
        }
        let tail = rec.len() - self.extra;
        out.extend_from_slice(&rec[tail..]);
        let r = out[start + 14] & 0x0f;
        if (1..=15).contains(&r) {
            self.by_return[r as usize - 1] += 1;
        }
        debug_assert_eq!(out.len() - start, self.record_len);
    }
}

impl Sink for CopcSink {
    fn written(&self, p: &Vect<3>) -> Vect<3> {
        on_frame(&self.frame, p)
    }

    fn rounding(&self) -> Option<String> {
        Some(frame_words(&self.frame))
    }

    fn write(
        &mut self,
        chunk: &Chunk,
        moved: &[Vect<3>],
        _normals: &[Vect<3>],
    ) -> Result<Accepted> {
        let rl = self.input.record_len as usize;
        let mut raw = chunk.raw[..moved.len() * rl].to_vec();
        let (mut lo, mut hi) = (self.lo, self.hi);
        let accepted = encode(&mut raw, rl, moved, &self.frame, (&mut lo, &mut hi));
        if accepted != Accepted::Yes {
            return Ok(accepted);
        }
        (self.lo, self.hi) = (lo, hi);
        let mut out = std::mem::take(&mut self.buf);
        out.clear();
        for rec in raw.chunks_exact(rl) {
            self.convert(rec, &mut out);
        }
        let (tmp, w) = self.spill.as_mut().expect("open until finish");
        w.write_all(&out).map_err(|e| Error::write(tmp.path(), e))?;
        self.count += moved.len() as u64;
        self.buf = out;
        Ok(Accepted::Yes)
    }

    fn finish(mut self: Box<Self>, set: &ResultSet) -> Result<Vec<String>> {
        let (spill, w) = self.spill.take().expect("open until finish");
        let io = |p: &Path| {
            let p = p.to_path_buf();
            move |e: std::io::Error| Error::write(&p, e)
        };
        // A scratch file: read back through the page cache, never synced.
        w.into_inner()
            .map_err(|e| io(spill.path())(e.into_error()))?;
        let (tmp, out) = TempFile::create(&self.output)?;
        write_copc(&self, spill.path(), out, tmp.path())?;
        set.stage(tmp)?;
        drop(spill);
        Ok(std::mem::take(&mut self.notes))
    }
}

/// Whether `r` describes or holds wave packets: a waveform packet descriptor (LASF_Spec 100 to
/// 354) or the waveform data packets (LASF_Spec 65535). COPC's point formats hold no wave
/// packets, so a COPC output keeps neither.
fn is_waveform(r: &VlrRecord) -> bool {
    r.user_id == "LASF_Spec" && matches!(r.record_id, 100..=354 | 65535)
}

/// The WKT VLR (LASF_Projection 2112) of the EPSG code that the GeoTIFF keys among `records`
/// name, and a note when they also name a vertical system, which the WKT leaves out (the
/// definitions known are of horizontal systems); why not, when they name no code or one
/// without a known definition.
fn geotiff_wkt(records: &[VlrRecord]) -> std::result::Result<(VlrRecord, Option<String>), String> {
    let crs = super::crs_of(records).ok_or("they could not be read")?;
    let code = crs
        .epsg
        .ok_or("they name no EPSG code of a horizontal system")?;
    let def = u16::try_from(code)
        .ok()
        .and_then(crs_definitions::from_code)
        .ok_or(format!("EPSG:{code} has no known WKT definition"))?;
    // A WKT VLR holds a null-terminated string.
    let mut data = def.wkt.as_bytes().to_vec();
    data.push(0);
    let vertical = crs.vertical_epsg.map(|v| {
        format!(
            "the CRS is written as the WKT of EPSG:{code}, which the input's GeoTIFF keys name; \
             their vertical system, EPSG:{v}, is in the keys only (kept)"
        )
    });
    let wkt = VlrRecord {
        user_id: "LASF_Projection".into(),
        record_id: 2112,
        description: format!("OGC WKT of EPSG:{code}"),
        data,
        extended: false,
    };
    Ok((wkt, vertical))
}

/// The octree's cube: its center and half edge (a little past the bounds, so that the highest
/// point falls inside).
fn cube(lo: &[f64; 3], hi: &[f64; 3]) -> ([f64; 3], f64) {
    let center = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
    let half = (0..3).map(|a| 0.5 * (hi[a] - lo[a])).fold(0.0, f64::max);
    (center, (half * (1.0 + 1e-9)).max(1e-9))
}

/// The 63-bit Morton code of a point's cell at depth 21 in the cube.
fn morton(p: [f64; 3], center: &[f64; 3], half: f64) -> u64 {
    let cells = (1u64 << 21) as f64;
    let mut code = 0u64;
    let q: [u64; 3] = std::array::from_fn(|a| {
        let t = (p[a] - (center[a] - half)) / (2.0 * half);
        ((t * cells).floor().clamp(0.0, cells - 1.0)) as u64
    });
    for bit in (0..21).rev() {
        for v in &q {
            code = (code << 1) | (v >> bit & 1);
        }
    }
    code
}

/// A sorted run being merged: its reader and its current record's key.
struct Run {
    reader: BufReader<File>,
    key: u64,
    record: Vec<u8>,
    left: u64,
}

impl Run {
    fn advance(&mut self) -> std::io::Result<bool> {
        if self.left == 0 {
            return Ok(false);
        }
        let mut k = [0u8; 8];
        self.reader.read_exact(&mut k)?;
        self.key = u64::from_le_bytes(k);
        self.reader.read_exact(&mut self.record)?;
        self.left -= 1;
        Ok(true)
    }
}

fn write_copc(
    sink: &CopcSink,
    spill: &Path,
    mut out: BufWriter<OutFile>,
    target: &Path,
) -> Result<()> {
    let rl = sink.record_len;
    let werr = |e: std::io::Error| Error::write(target, e);
    let (scale, offset) = sink.frame;
    let (lo, hi) = if sink.count > 0 {
        (sink.lo, sink.hi)
    } else {
        ([0.0; 3], [0.0; 3])
    };
    let (center, half) = cube(&lo, &hi);
    let position = |rec: &[u8]| -> [f64; 3] {
        std::array::from_fn(|a| {
            let v = i32::from_le_bytes(rec[4 * a..4 * a + 4].try_into().expect("4 bytes"));
            v as f64 * scale[a] + offset[a]
        })
    };
    // 1. Sorted runs of (Morton code, record).
    let run_len = (sink.run_bytes / (rl + 8)).max(1);
    let mut reader = BufReader::new(File::open(spill).map_err(|e| Error::io(spill, e))?);
    let mut runs = Vec::new();
    let mut left = sink.count;
    let mut block = Vec::new();
    while left > 0 {
        let n = (left as usize).min(run_len);
        block.resize(n * rl, 0);
        reader
            .read_exact(&mut block)
            .map_err(|e| Error::io(spill, e))?;
        let mut order: Vec<(u64, u32)> = block
            .chunks_exact(rl)
            .enumerate()
            .map(|(i, rec)| (morton(position(rec), &center, half), i as u32))
            .collect();
        order.sort_unstable();
        let name = sink.output.with_file_name(format!(
            "{}.run{}",
            sink.output
                .file_name()
                .unwrap_or_default()
                .to_string_lossy(),
            runs.len()
        ));
        let (tmp, mut w) = TempFile::scratch(&name)?;
        for (key, i) in &order {
            w.write_all(&key.to_le_bytes())
                .and_then(|_| w.write_all(&block[*i as usize * rl..(*i as usize + 1) * rl]))
                .map_err(|e| Error::write(tmp.path(), e))?;
        }
        w.flush().map_err(|e| Error::write(tmp.path(), e))?;
        runs.push((tmp, n as u64));
        left -= n as u64;
    }
    drop(block);
    // 2. Merge, sampling levels, into one file per level.
    let mut open = Vec::new();
    for (tmp, n) in &runs {
        let file = File::open(tmp.path()).map_err(|e| Error::io(tmp.path(), e))?;
        let mut run = Run {
            reader: BufReader::with_capacity(1 << 16, file),
            key: 0,
            record: vec![0; rl],
            left: *n,
        };
        if run.advance().map_err(|e| Error::io(tmp.path(), e))? {
            open.push(run);
        }
    }
    let mut heap: std::collections::BinaryHeap<std::cmp::Reverse<(u64, usize)>> = open
        .iter()
        .enumerate()
        .map(|(i, r)| std::cmp::Reverse((r.key, i)))
        .collect();
    let levels = MAX_LEVEL as usize + 1;
    let mut level_files: Vec<Option<(TempFile, BufWriter<OutFile>)>> =
        (0..levels).map(|_| None).collect();
    let mut level_counts = vec![0u64; levels];
    // Per level: the sampling cell of the last point seen, and whether a point took it.
    let mut cell = vec![u64::MAX; levels];
    let mut taken = vec![false; levels];
    while let Some(std::cmp::Reverse((key, i))) = heap.pop() {
        let mut level = levels - 1;
        for l in 0..levels {
            // The sampling cell at level l: the Morton prefix at depth l + GRID_BITS.
            let depth = (l as u32 + GRID_BITS).min(21);
            let c = key >> (3 * (21 - depth));
            if c != cell[l] {
                cell[l] = c;
                taken[l] = false;
            }
        }
        if let Some(l) = (0..levels).find(|&l| !taken[l]) {
            level = l;
        }
        taken[level] = true;
        let slot = &mut level_files[level];
        if slot.is_none() {
            let name = sink.output.with_file_name(format!(
                "{}.level{level}",
                sink.output
                    .file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
            ));
            *slot = Some(TempFile::scratch(&name)?);
        }
        let (tmp, w) = slot.as_mut().expect("just opened");
        let run = &mut open[i];
        w.write_all(&key.to_le_bytes())
            .and_then(|_| w.write_all(&run.record))
            .map_err(|e| Error::write(tmp.path(), e))?;
        level_counts[level] += 1;
        if run.advance().map_err(|e| Error::io(&sink.output, e))? {
            heap.push(std::cmp::Reverse((run.key, i)));
        }
    }
    drop(open);
    drop(runs);
    // 3. The output: header and VLRs, then the nodes level by level, the chunk table, the
    // hierarchy and the input's EVLRs.
    let laz_vlr = laz::LazVlrBuilder::default()
        .with_point_format(sink.format, sink.extra as u16)
        .map_err(|e| Error::solver(format!("LASzip items: {e}")))?
        .with_variable_chunk_size()
        .build();
    let mut laz_bytes = Vec::new();
    laz_vlr.write_to(&mut laz_bytes).map_err(werr)?;
    let record = |user_id: &str, record_id, description: &str, data| VlrRecord {
        user_id: user_id.into(),
        record_id,
        description: description.into(),
        data,
        extended: false,
    };
    let mut vlrs = vec![
        record("copc", 1, "COPC info", vec![0; 160]),
        record("laszip encoded", 22204, "LASzip", laz_bytes),
    ];
    vlrs.extend(sink.vlrs.iter().cloned());
    let point_offset = HEADER_1_4
        + vlrs
            .iter()
            .map(|v| VLR_HEADER + v.data.len())
            .sum::<usize>();
    // The header, written last, when its counts and offsets are known.
    out.write_all(&[0u8; HEADER_1_4]).map_err(werr)?;
    for v in &vlrs {
        write_vlr(&mut out, v, false).map_err(werr)?;
    }
    let mut compressor = laz::LasZipCompressor::new(out, laz_vlr.clone())
        .map_err(|e| Error::solver(format!("LAZ compressor: {e}")))?;
    compressor.reserve_offset_to_chunk_table().map_err(werr)?;
    // (key, offset, bytes, points) per node.
    let mut nodes: Vec<([i32; 4], u64, i32, i32)> = Vec::new();
    for (level, file) in level_files.into_iter().enumerate() {
        let Some((tmp, w)) = file else { continue };
        drop(
            w.into_inner()
                .map_err(|e| Error::write(tmp.path(), e.into_error()))?,
        );
        let mut r = BufReader::with_capacity(
            1 << 16,
            File::open(tmp.path()).map_err(|e| Error::io(tmp.path(), e))?,
        );
        let shift = 3 * (21 - level as u32);
        let mut current: Option<u64> = None;
        let mut points = 0u64;
        let mut start = compressor.get_mut().stream_position().map_err(werr)?;
        let mut record = vec![0u8; rl];
        let mut k = [0u8; 8];
        let mut finish = |node: u64,
                          points: u64,
                          start: &mut u64,
                          c: &mut laz::LasZipCompressor<BufWriter<OutFile>>|
         -> Result<()> {
            c.finish_current_chunk().map_err(werr)?;
            let end = c.get_mut().stream_position().map_err(werr)?;
            let (bytes, points) = entry_sizes(&sink.output, end - *start, points)?;
            nodes.push((node_key(level as u32, node), *start, bytes, points));
            *start = end;
            Ok(())
        };
        for _ in 0..level_counts[level] {
            r.read_exact(&mut k)
                .and_then(|_| r.read_exact(&mut record))
                .map_err(|e| Error::io(tmp.path(), e))?;
            let node = u64::from_le_bytes(k) >> shift;
            if current.is_some_and(|c| c != node) {
                finish(current.expect("some"), points, &mut start, &mut compressor)?;
                points = 0;
            }
            current = Some(node);
            compressor.compress_one(&record).map_err(werr)?;
            points += 1;
        }
        if let Some(c) = current {
            finish(c, points, &mut start, &mut compressor)?;
        }
    }
    // The chunk table, written here: `done` would close one more, empty chunk after the last
    // node's (laspy reads past it; a strict reader, ours among them, refuses it).
    let mut out = compressor.into_inner();
    let table_at = out.stream_position().map_err(werr)?;
    let mut table = laz::laszip::ChunkTable::with_capacity(nodes.len());
    for (_, _, bytes, points) in &nodes {
        table.push(laz::laszip::ChunkTableEntry {
            point_count: *points as u64,
            byte_count: *bytes as u64,
        });
    }
    table.write_to(&mut out, &laz_vlr).map_err(werr)?;
    let end = out.stream_position().map_err(werr)?;
    out.seek(SeekFrom::Start(point_offset as u64))
        .and_then(|_| out.write_all(&(table_at as i64).to_le_bytes()))
        .and_then(|_| out.seek(SeekFrom::Start(end)))
        .map_err(werr)?;
    // The hierarchy: one page with every node.
    let evlr_start = out.stream_position().map_err(werr)?;
    let mut page = Vec::with_capacity(nodes.len() * 32);
    for (key, offset, bytes, points) in &nodes {
        for v in key {
            page.extend_from_slice(&v.to_le_bytes());
        }
        page.extend_from_slice(&offset.to_le_bytes());
        page.extend_from_slice(&bytes.to_le_bytes());
        page.extend_from_slice(&points.to_le_bytes());
    }
    let page_len = page.len() as u64;
    let hierarchy = record("copc", 1000, "EPT hierarchy", page);
    write_vlr(&mut out, &hierarchy, true).map_err(werr)?;
    for v in &sink.evlrs {
        write_vlr(&mut out, v, true).map_err(werr)?;
    }
    // The COPC info, now that the hierarchy's place is known.
    let mut info = Vec::with_capacity(160);
    for v in [
        center[0],
        center[1],
        center[2],
        half,
        2.0 * half / (1u32 << GRID_BITS) as f64,
    ] {
        info.extend_from_slice(&v.to_le_bytes());
    }
    info.extend_from_slice(&(evlr_start + EVLR_HEADER as u64).to_le_bytes());
    info.extend_from_slice(&page_len.to_le_bytes());
    let gps = if sink.gps.0 <= sink.gps.1 {
        sink.gps
    } else {
        (0.0, 0.0)
    };
    info.extend_from_slice(&gps.0.to_le_bytes());
    info.extend_from_slice(&gps.1.to_le_bytes());
    info.resize(160, 0);
    // The COPC info VLR comes first, right after the header.
    out.seek(SeekFrom::Start((HEADER_1_4 + VLR_HEADER) as u64))
        .map_err(werr)?;
    out.write_all(&info).map_err(werr)?;
    let header = header(
        sink,
        point_offset as u32,
        vlrs.len() as u32,
        evlr_start,
        1 + sink.evlrs.len() as u32,
        (lo, hi),
    );
    out.seek(SeekFrom::Start(0)).map_err(werr)?;
    out.write_all(&header.to_bytes()).map_err(werr)?;
    out.flush().map_err(werr)?;
    Ok(())
}

/// A node's chunk size and point count as the hierarchy's 32-bit entries hold them; a node
/// past them (samples piled at one spot, below every level's sampling cells) is an error, not
/// a wrapped number.
fn entry_sizes(output: &Path, bytes: u64, points: u64) -> Result<(i32, i32)> {
    match (i32::try_from(bytes), i32::try_from(points)) {
        (Ok(b), Ok(p)) => Ok((b, p)),
        _ => Err(Error::param(format!(
            "{}: an octree node would hold {points} points in {bytes} bytes, past what a COPC \
             hierarchy entry records (2^31 - 1): the samples pile up at one spot (duplicates?); \
             write a plain .laz instead",
            output.display()
        ))),
    }
}

/// The key (level, x, y, z) of the node at `level` whose Morton prefix is `prefix`.
fn node_key(level: u32, prefix: u64) -> [i32; 4] {
    let mut xyz = [0i32; 3];
    for bit in 0..level {
        for a in 0..3 {
            // Bits interleave x, y, z from the most significant: x is the highest of each triple.
            let v = (prefix >> (3 * bit + (2 - a as u32))) & 1;
            xyz[a] |= (v as i32) << bit;
        }
    }
    [level as i32, xyz[0], xyz[1], xyz[2]]
}

/// Writes `v` as a VLR (54-byte header) or, with `extended`, an EVLR (60-byte header).
fn write_vlr(out: &mut impl Write, v: &VlrRecord, extended: bool) -> std::io::Result<()> {
    let header = RawVlrHeader {
        reserved: 0,
        user_id: text_field(&v.user_id),
        record_id: v.record_id,
        len: v.data.len() as u64,
        description: text_field(&v.description),
    };
    out.write_all(&header.to_bytes(extended))?;
    out.write_all(&v.data)
}

/// The LAS 1.4 header of the COPC output.
fn header(
    sink: &CopcSink,
    point_offset: u32,
    vlr_count: u32,
    evlr_start: u64,
    evlr_count: u32,
    (lo, hi): ([f64; 3], [f64; 3]),
) -> RawHeader {
    let h = &sink.input;
    // Global encoding: GPS time as the input's; the CRS is WKT (bit 4) for formats 6+.
    let wkt = sink
        .vlrs
        .iter()
        .chain(&sink.evlrs)
        .any(|v| v.is("LASF_Projection", 2112));
    let (scale, offset) = sink.frame;
    RawHeader {
        file_signature: *b"LASF",
        file_source_id: h.file_source_id,
        global_encoding: (h.global_encoding & 0x1) | if wkt { 0x10 } else { 0 },
        guid: h.guid,
        version: (1, 4),
        system_identifier: text_field(&h.system),
        generating_software: text_field(SOFTWARE),
        creation_day: h.creation.0,
        creation_year: h.creation.1,
        header_size: HEADER_1_4 as u16,
        point_offset,
        vlr_count,
        point_format: sink.format | 0x80,
        record_len: sink.record_len as u16,
        legacy_count: 0,
        legacy_by_return: [0; 5],
        scale,
        offset,
        max: hi,
        min: lo,
        waveform_start: 0,
        evlr_start,
        evlr_count,
        count: sink.count,
        by_return: sink.by_return,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{LasSource, Source};

    /// Every position of a LAS file, in centimetres, sorted.
    fn positions(path: &Path) -> Vec<[i64; 3]> {
        let mut src = LasSource::open(path).unwrap();
        let mut chunk = Chunk::default();
        let mut out = Vec::new();
        while src.read_samples(10_000, &mut chunk).unwrap() > 0 {
            out.extend(
                chunk
                    .positions
                    .iter()
                    .map(|p| [0, 1, 2].map(|a| (p[a] * 100.0).round() as i64)),
            );
        }
        out.sort_unstable();
        out
    }

    /// `n` points of LAS 1.2, record format 3, on hills 1,000 × 500 units wide, in centimetres:
    /// dense and sparse places, so that the octree has levels.
    fn write_hills(path: &Path, n: u64) {
        let mut b = las::Builder::from((1, 2));
        b.point_format = las::point::Format::new(3).unwrap();
        let t = las::Transform {
            scale: 0.01,
            offset: 0.0,
        };
        b.transforms = las::Vector { x: t, y: t, z: t };
        let header = b.into_header().unwrap();
        let mut w = las::Writer::from_path(path, header).unwrap();
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut uniform = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..n {
            // Half the points crowd the square's first tenth.
            let crowd = if uniform() < 0.5 { 0.1 } else { 1.0 };
            let (px, py) = (1000.0 * crowd * uniform(), 500.0 * crowd * uniform());
            let pz = 50.0 * (px / 90.0).sin() * (py / 70.0).cos() + uniform();
            let point = las::Point {
                x: (px * 100.0).round() / 100.0,
                y: (py * 100.0).round() / 100.0,
                z: (pz * 100.0).round() / 100.0,
                gps_time: Some(px),
                color: Some(las::Color::new(1, 2, 3)),
                ..Default::default()
            };
            w.write_point(point).unwrap();
        }
        w.close().unwrap();
    }

    #[test]
    fn a_node_past_the_hierarchys_32_bits_is_an_error() {
        let out = Path::new("o.copc.laz");
        assert_eq!(entry_sizes(out, 1000, 10).unwrap(), (1000, 10));
        let e = entry_sizes(out, 1 << 31, 10).unwrap_err().to_string();
        assert!(e.contains("o.copc.laz") && e.contains("plain .laz"), "{e}");
        assert!(entry_sizes(out, 10, 1 << 31).is_err());
    }

    /// Runs of 2,000 records: the merge of 55 runs gives the file every point once, in nodes
    /// whose points lie in their cubes.
    #[test]
    fn many_sorted_runs_merge_into_one_octree() {
        let dir = std::env::temp_dir().join(format!("rigidcells-copc-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let input = dir.join("hills.las");
        write_hills(&input, 110_000);
        let output = dir.join("runs.copc.laz");
        let mut src = LasSource::open(&input).unwrap();
        let header = src.header().clone();
        let frame = (header.scale, header.offset);
        let mut sink =
            CopcSink::new(&output, header, src.vlr_records(), frame, Vec::new()).unwrap();
        sink.run_bytes = 2_000 * (sink.record_len + 8);
        let mut chunk = Chunk::default();
        while src.read(7_000, &mut chunk).unwrap() > 0 {
            let moved = chunk.positions.clone();
            assert_eq!(sink.write(&chunk, &moved, &[]).unwrap(), Accepted::Yes);
        }
        let set = ResultSet::new();
        Box::new(sink).finish(&set).unwrap();
        set.commit().unwrap();
        assert_eq!(positions(&input), positions(&output));
        // Each node's points lie in its cube.
        let bytes = std::fs::read(&output).unwrap();
        let f = |at: usize| f64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
        let info = 375 + 54;
        let (center, half) = ([f(info), f(info + 8), f(info + 16)], f(info + 24));
        let mut src = LasSource::open(&output).unwrap();
        let mut all = Vec::new();
        while src.read_samples(100_000, &mut chunk).unwrap() > 0 {
            all.extend_from_slice(&chunk.positions);
        }
        let at = u64::from_le_bytes(bytes[info + 40..info + 48].try_into().unwrap()) as usize;
        let len = u64::from_le_bytes(bytes[info + 48..info + 56].try_into().unwrap()) as usize;
        let mut entries: Vec<(u64, [i32; 4], usize)> = bytes[at..at + len]
            .chunks_exact(32)
            .map(|e| {
                let k = |i: usize| i32::from_le_bytes(e[4 * i..4 * i + 4].try_into().unwrap());
                let offset = u64::from_le_bytes(e[16..24].try_into().unwrap());
                let n = i32::from_le_bytes(e[28..32].try_into().unwrap()) as usize;
                (offset, [k(0), k(1), k(2), k(3)], n)
            })
            .collect();
        // Chunks are in file order: the points of node k follow those of node k − 1.
        entries.sort_unstable_by_key(|e| e.0);
        let mut first = 0;
        for (_, [level, x, y, z], n) in &entries {
            let edge = 2.0 * half / (1u64 << level) as f64;
            let lo = [x, y, z].map(|v| *v as f64);
            for p in &all[first..first + n] {
                for a in 0..3 {
                    let t = (p[a] - (center[a] - half)) / edge - lo[a];
                    assert!((-1e-6..=1.0 + 1e-6).contains(&t), "level {level}: {t}");
                }
            }
            first += n;
        }
        assert_eq!(first, all.len());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
