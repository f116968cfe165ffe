//! PLY's raw layer: ASCII, binary little- and big-endian; every scalar and list type; any
//! element order. The sources of [`super::ply_stream`] are built on it.
//!
//! The header is parsed by `ply-rs-bw` (with the tolerance [`parse_header`] describes) and kept
//! verbatim. The body is walked record by record ([`walk_element`]) to find where the vertices'
//! `x y z` live (byte offsets in binary, token spans in ASCII) and to decode faces
//! (`vertex_indices`/`vertex_index` lists, fan-triangulated) and triangle strips (`tristrips`,
//! `-1` restarts). Writers copy the input and replace only those coordinates, so faces, other
//! elements, every other property and the header's comments and obj_info come out byte for
//! byte.

use std::io::Cursor;
use std::path::Path;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{DefaultElement, ElementDef, Encoding, Header, PropertyType, ScalarType};

use super::text::{Numbers, Precision, Span};
use crate::error::{Error, Result};
use crate::rigid::Vect;

/// How numbers are written in a body of `encoding` (text: with `precision`).
pub(super) fn numbers(encoding: Encoding, precision: Precision) -> Numbers {
    match encoding {
        Encoding::Ascii => Numbers::Text(precision),
        Encoding::BinaryLittleEndian => Numbers::Binary { big: false },
        Encoding::BinaryBigEndian => Numbers::Binary { big: true },
    }
}

/// Fails when a triangle refers to a vertex past the `n` there are.
pub(super) fn check_triangles(path: &Path, triangles: &[[u32; 3]], n: usize) -> Result<()> {
    match triangles
        .iter()
        .find(|t| t.iter().any(|&v| v as usize >= n))
    {
        Some(t) => Err(Error::format(
            path,
            format!(
                "a face refers to vertex {} but there are {n} vertices",
                t.iter().max().unwrap_or(&0)
            ),
        )),
        None => Ok(()),
    }
}

/// Whether the vertex element's `x y z` are doubles (else floats), and the same for `nx ny nz`
/// when all three are there as floating-point scalars.
pub(super) fn vertex_layout(
    header: &Header,
) -> std::result::Result<([bool; 3], Option<[bool; 3]>), String> {
    let vertex = header.elements.get("vertex").ok_or("no `vertex` element")?;
    let mut doubles = [false; 3];
    for (k, name) in ["x", "y", "z"].iter().enumerate() {
        match vertex.properties.get(*name).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(ScalarType::Float)) => {}
            Some(PropertyType::Scalar(ScalarType::Double)) => doubles[k] = true,
            Some(t) => {
                return Err(format!(
                    "vertex property `{name}` is {t:?}; rigidcells moves float or double coordinates"
                ));
            }
            None => return Err(format!("vertex element has no `{name}` property")),
        }
    }
    let mut normal_doubles = Some([false; 3]);
    for (k, name) in ["nx", "ny", "nz"].iter().enumerate() {
        match vertex.properties.get(*name).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(ScalarType::Float)) => {}
            Some(PropertyType::Scalar(ScalarType::Double)) => {
                if let Some(d) = normal_doubles.as_mut() {
                    d[k] = true
                }
            }
            _ => normal_doubles = None,
        }
    }
    Ok((doubles, normal_doubles))
}

/// Parses the header; returns it and the offset of the body. Exporters (Blender 2.4) write
/// comments that run over several lines: a header line of free text (its first word is not a
/// lowercase identifier) is read as a comment, its bytes kept as they are. A line that starts
/// with an unknown lowercase word is a misspelled keyword and an error. Two elements, or two
/// properties of one element, of the same name are an error: the records' values are found
/// by name, so one of the two would be read in place of the other and the records misread.
pub(super) fn parse_header(bytes: &[u8]) -> std::result::Result<(Header, usize), String> {
    let end = bytes
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or("no `end_header` line (truncated or not a PLY header)")?;
    let mut body = end + 10;
    if bytes.get(body) == Some(&b'\r') {
        body += 1;
    }
    if bytes.get(body) == Some(&b'\n') {
        body += 1;
    }
    const KEYWORDS: [&str; 7] = [
        "ply",
        "format",
        "comment",
        "obj_info",
        "element",
        "property",
        "end_header",
    ];
    let mut text = String::new();
    // The first name declared twice, and the names declared so far: elements, and the
    // properties of the current element.
    let mut twice: Option<String> = None;
    let (mut elements, mut properties) = (Vec::<String>::new(), Vec::<String>::new());
    for line in String::from_utf8_lossy(&bytes[..end]).lines() {
        let first = line.split_whitespace().next().unwrap_or("");
        if line.trim().is_empty() {
            continue;
        }
        let name = line.split_whitespace().nth(1).unwrap_or("").to_string();
        if first == "element" {
            if elements.contains(&name) {
                twice.get_or_insert(format!("two elements are named `{name}`"));
            }
            elements.push(name);
            properties.clear();
        } else if first == "property" {
            let name = line.split_whitespace().last().unwrap_or("").to_string();
            if properties.contains(&name) {
                let element = elements.last().map_or("", String::as_str);
                twice.get_or_insert(format!(
                    "element `{element}` has two properties named `{name}`"
                ));
            }
            properties.push(name);
        }
        if !KEYWORDS.contains(&first) {
            if first.chars().all(|c| c.is_ascii_lowercase() || c == '_') {
                return Err(format!("unknown header keyword `{first}`"));
            }
            text.push_str("comment ");
        }
        text.push_str(line.trim_end());
        text.push('\n');
    }
    text.push_str("end_header\n");
    let mut reader = Reader::new(Cursor::new(text.as_bytes()));
    let header = Parser::<DefaultElement>::new()
        .read_header(&mut reader)
        .map_err(|e| format!("bad header: {e}"))?;
    if let Some(what) = twice {
        return Err(format!(
            "{what}: a record's values are found by their names, so its records cannot be \
             read unambiguously"
        ));
    }
    check_counts(&header, bytes.len().saturating_sub(body))?;
    Ok((header, body))
}

/// Refuses element counts the body cannot hold, before any is used to size a buffer (a fuzzed
/// `element vertex 4294967295` in a 650 kB file had 206 GB reserved and aborted). A record
/// takes at least its scalars' bytes and one count per list in binary, and two characters
/// (a digit and a separator) per property in ASCII.
fn check_counts(header: &Header, body: usize) -> std::result::Result<(), String> {
    let mut least = 0u128;
    for (name, element) in header.elements.iter() {
        let record: usize = element
            .properties
            .values()
            .map(|p| match (&header.encoding, &p.data_type) {
                (Encoding::Ascii, _) => 2,
                (_, PropertyType::Scalar(t) | PropertyType::List(t, _)) => scalar_size(t),
            })
            .sum::<usize>()
            // An element without properties would take no bytes and be walked record by
            // record: counted as one byte each, so its count cannot stall the reader.
            .max(1);
        least += element.count as u128 * record as u128;
        // ASCII may omit the last newline.
        if least > body as u128 + 1 {
            return Err(format!(
                "the header's {} {name} records cannot fit the {body} bytes of the body \
                 (truncated file, or a count that is too large)",
                element.count
            ));
        }
    }
    Ok(())
}

/// What [`walk_element`] shows its visitor.
pub(super) enum Visit<'a> {
    /// A scalar property of the current record: name, value, where it lies.
    Scalar(&'a str, f64, Span),
    /// The end of record `.0`.
    End(usize),
}

/// The `x y z` and `nx ny nz` of the vertex record being walked, gathered from [`Visit`]s.
#[derive(Debug, Default)]
pub(super) struct VertexFields {
    spans: [Span; 3],
    xyz: [f64; 3],
    nspans: [Span; 3],
    nxyz: [f64; 3],
}

impl VertexFields {
    /// Takes one visit; at the end of a record returns its index.
    pub(super) fn take(&mut self, visit: Visit) -> Option<usize> {
        match visit {
            Visit::Scalar(pname, value, span) => {
                if let Some(k) = ["x", "y", "z"].iter().position(|n| *n == pname) {
                    self.spans[k] = span;
                    self.xyz[k] = value;
                } else if let Some(k) = ["nx", "ny", "nz"].iter().position(|n| *n == pname) {
                    self.nspans[k] = span;
                    self.nxyz[k] = value;
                }
                None
            }
            Visit::End(record) => Some(record),
        }
    }

    /// The record's coordinate spans and position, normal spans and normal; an error naming
    /// vertex `record` when a coordinate is not finite.
    pub(super) fn checked(
        &self,
        path: &Path,
        record: usize,
    ) -> Result<([Span; 3], Vect<3>, [Span; 3], Vect<3>)> {
        if !self.xyz.iter().all(|v| v.is_finite()) {
            return Err(Error::format(
                path,
                format!(
                    "vertex {record} has a coordinate that is not finite: {:?}",
                    self.xyz
                ),
            ));
        }
        Ok((
            self.spans,
            Vect::<3>::from(self.xyz),
            self.nspans,
            Vect::<3>::from(self.nxyz),
        ))
    }
}

/// Walks `records` of `element` (named `name`), collecting the triangles of faces and strips
/// and showing `visit` every scalar and the end of every record. Errors name the element,
/// record and property.
pub(super) fn walk_element(
    walker: &mut Walker,
    name: &str,
    element: &ElementDef,
    records: std::ops::Range<usize>,
    triangles: &mut Vec<[u32; 3]>,
    mut visit: impl FnMut(Visit) -> Result<()>,
) -> Result<()> {
    let props: Vec<(&str, &PropertyType)> = element
        .properties
        .iter()
        .map(|(n, p)| (n.as_str(), &p.data_type))
        .collect();
    let keep_lists = matches!(name, "face" | "tristrips");
    let mut list = Vec::new();
    for record in records {
        for &(pname, ptype) in &props {
            let at = |e: Error| match e {
                Error::Format { path, message } => Error::Format {
                    path,
                    message: format!(
                        "{name} {record} of {}, property `{pname}`: {message}",
                        element.count
                    ),
                },
                other => other,
            };
            match ptype {
                PropertyType::Scalar(t) => {
                    let (value, span) = walker.scalar(t).map_err(at)?;
                    visit(Visit::Scalar(pname, value, span))?;
                }
                PropertyType::List(count_type, item_type) => {
                    let (count, _) = walker.scalar(count_type).map_err(at)?;
                    if !(count >= 0.0 && count.fract() == 0.0) {
                        return Err(at(Error::format(
                            walker.path,
                            format!("list length {count} is not a count"),
                        )));
                    }
                    let keep = keep_lists && matches!(pname, "vertex_indices" | "vertex_index");
                    list.clear();
                    for _ in 0..count as usize {
                        let (v, _) = walker.scalar(item_type).map_err(at)?;
                        if keep {
                            list.push(v);
                        }
                    }
                    if keep {
                        collect_triangles(name, &list, triangles);
                    }
                }
            }
        }
        visit(Visit::End(record))?;
    }
    Ok(())
}

fn collect_triangles(element: &str, list: &[f64], out: &mut Vec<[u32; 3]>) {
    let idx = |v: f64| v as u32;
    if element == "tristrips" {
        let mut strip: Vec<u32> = Vec::new();
        for &v in list.iter().chain(std::iter::once(&-1.0)) {
            if v < 0.0 {
                for k in 2..strip.len() {
                    let t = if k % 2 == 0 {
                        [strip[k - 2], strip[k - 1], strip[k]]
                    } else {
                        [strip[k - 1], strip[k - 2], strip[k]]
                    };
                    if t[0] != t[1] && t[1] != t[2] && t[0] != t[2] {
                        out.push(t);
                    }
                }
                strip.clear();
            } else {
                strip.push(idx(v));
            }
        }
    } else if list.iter().all(|&v| v >= 0.0) {
        for k in 2..list.len() {
            out.push([idx(list[0]), idx(list[k - 1]), idx(list[k])]);
        }
    }
}

/// Walks scalars of the body in either encoding.
pub(super) struct Walker<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) pos: usize,
    pub(super) encoding: Encoding,
    pub(super) path: &'a Path,
}

impl<'a> Walker<'a> {
    /// A walker over `bytes` from `pos`.
    pub(super) fn new(bytes: &'a [u8], pos: usize, encoding: Encoding, path: &'a Path) -> Self {
        Self {
            bytes,
            pos,
            encoding,
            path,
        }
    }

    pub(super) fn scalar(&mut self, t: &ScalarType) -> Result<(f64, Span)> {
        match self.encoding {
            Encoding::Ascii => self.ascii(t),
            Encoding::BinaryLittleEndian => self.binary(t, false),
            Encoding::BinaryBigEndian => self.binary(t, true),
        }
    }

    fn binary(&mut self, t: &ScalarType, big: bool) -> Result<(f64, Span)> {
        let size = scalar_size(t);
        let start = self.pos;
        let end = start + size;
        let Some(b) = self.bytes.get(start..end) else {
            return Err(Error::format(
                self.path,
                "the body ends early (truncated file, or a header count that is too large)",
            ));
        };
        macro_rules! num {
            ($ty:ty) => {{
                let a = b.try_into().expect("size checked");
                (if big {
                    <$ty>::from_be_bytes(a)
                } else {
                    <$ty>::from_le_bytes(a)
                }) as f64
            }};
        }
        let v = match t {
            ScalarType::Char => num!(i8),
            ScalarType::UChar => num!(u8),
            ScalarType::Short => num!(i16),
            ScalarType::UShort => num!(u16),
            ScalarType::Int => num!(i32),
            ScalarType::UInt => num!(u32),
            ScalarType::Float => num!(f32),
            ScalarType::Double => num!(f64),
        };
        self.pos = end;
        Ok((v, Span { start, end }))
    }

    fn ascii(&mut self, t: &ScalarType) -> Result<(f64, Span)> {
        let b = self.bytes;
        let mut start = self.pos;
        while start < b.len() && b[start].is_ascii_whitespace() {
            start += 1;
        }
        let mut end = start;
        while end < b.len() && !b[end].is_ascii_whitespace() {
            end += 1;
        }
        if start == end {
            return Err(Error::format(
                self.path,
                "the body ends early (truncated file, or a header count that is too large)",
            ));
        }
        let text = std::str::from_utf8(&b[start..end]).unwrap_or("");
        let v = match t {
            ScalarType::Float | ScalarType::Double => text.parse::<f64>().ok(),
            _ => text.parse::<i64>().ok().map(|v| v as f64),
        }
        .ok_or_else(|| Error::format(self.path, format!("`{text}` is not a {t:?}")))?;
        self.pos = end;
        Ok((v, Span { start, end }))
    }
}

/// Bytes of a binary scalar.
pub(super) fn scalar_size(t: &ScalarType) -> usize {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// Colors a PLY file gives its geometry, for pictures.
#[derive(Debug, Clone, PartialEq)]
pub enum Colors {
    /// One per vertex.
    Vertices(Vec<[u8; 3]>),
    /// One per triangle (a face's color repeated over its fan's triangles).
    Triangles(Vec<[u8; 3]>),
}

/// The colors of the PLY file `path`: `red`, `green`, `blue` on its vertices, else on its
/// faces (8-bit, 16-bit scaled down, or floats in 0..1); `None` when neither has them. For
/// pictures: the whole file is parsed once more.
pub fn colors(path: &Path) -> Result<Option<Colors>> {
    use ply_rs_bw::ply::Property;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (header, _) = parse_header(&bytes).map_err(|m| Error::format(path, m))?;
    let has = |element: &str| {
        header.elements.get(element).is_some_and(|e| {
            ["red", "green", "blue"]
                .iter()
                .all(|c| e.properties.contains_key(*c))
        })
    };
    let (vertex, face) = (has("vertex"), has("face"));
    if !vertex && !face {
        return Ok(None);
    }
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut Cursor::new(&bytes))
        .map_err(|e| Error::format(path, format!("{e}")))?;
    let channel = |p: Option<&Property>| -> u8 {
        match p {
            Some(Property::UChar(v)) => *v,
            Some(Property::Char(v)) => (*v).max(0) as u8,
            Some(Property::UShort(v)) => (*v / 257) as u8,
            Some(Property::Float(v)) => (v.clamp(0.0, 1.0) * 255.0).round() as u8,
            Some(Property::Double(v)) => (v.clamp(0.0, 1.0) * 255.0).round() as u8,
            _ => 200,
        }
    };
    let rgb = |e: &DefaultElement| [e.get("red"), e.get("green"), e.get("blue")].map(channel);
    if vertex {
        return Ok(ply
            .payload
            .get("vertex")
            .map(|v| Colors::Vertices(v.iter().map(rgb).collect())));
    }
    // A face of n corners is n − 2 triangles of the fan.
    let corners = |e: &DefaultElement| -> usize {
        match e.get("vertex_indices").or_else(|| e.get("vertex_index")) {
            Some(Property::ListInt(l)) => l.len(),
            Some(Property::ListUInt(l)) => l.len(),
            Some(Property::ListShort(l)) => l.len(),
            Some(Property::ListUShort(l)) => l.len(),
            Some(Property::ListChar(l)) => l.len(),
            Some(Property::ListUChar(l)) => l.len(),
            _ => 3,
        }
    };
    Ok(ply.payload.get("face").map(|faces| {
        Colors::Triangles(
            faces
                .iter()
                .flat_map(|f| std::iter::repeat_n(rgb(f), corners(f).saturating_sub(2)))
                .collect(),
        )
    }))
}
