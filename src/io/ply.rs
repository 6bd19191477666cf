//! PLY reading (ascii, binary little/big endian, any vertex layout, meshes sampled by
//! area) and writing (segmented output with a `part` property).
//!
//! The reader is platform-free: [`read_ply`] works on bytes (what the browser hands
//! over) and [`read_ply_from`] streams from any `std::io::Read` (what the CLI uses for
//! large files), so a frame of a million points never has to exist as text or as a
//! whole file in memory. Binary records without lists are decoded in chunks.
//!
//! Every failure is an [`Error::Input`] naming the file and the problem; no input,
//! however malformed, can make the reader panic (see the property tests).

use std::io::{BufRead, BufReader, Read, Write};

use glam::Vec3;
use nalgebra::{Matrix3, SymmetricEigen};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::error::{Error, Result};

/// The fewest points a frame may have to be worth fitting.
pub const MIN_POINTS: usize = 16;

/// Longest header accepted; a real header is a few hundred bytes, and the cap keeps
/// a binary file without a newline from being buffered whole while looking for one.
const MAX_HEADER_BYTES: usize = 1 << 20;

/// Bytes looked at to recognise the file type.
const SNIFF_BYTES: usize = 512;

/// Records decoded per chunk on the binary fast path.
const CHUNK_BYTES: usize = 1 << 16;

/// What a PLY file holds, after structural validation.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PlyCloud {
    /// Vertex positions (`x y z` converted to f32), in file order.
    pub points: Vec<Vec3>,
    /// Ground-truth part id per vertex, from an int property `part` (or `label`).
    pub labels: Option<Vec<u32>>,
    /// Triangles (polygons fan-triangulated) when the file has a `face` element with a
    /// `vertex_indices`/`vertex_index` list; indices are checked to be in range.
    pub faces: Option<Vec<[u32; 3]>>,
}

impl PlyCloud {
    /// True when the file is a mesh whose surface must be sampled to get a point cloud.
    pub fn is_mesh(&self) -> bool {
        self.faces.as_ref().is_some_and(|f| !f.is_empty())
    }
}

// ---------------------------------------------------------------- header model

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes one value; `b` holds exactly `self.size()` bytes.
    fn decode(self, b: &[u8], big: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                (if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => num!(i16, 2),
            Scalar::U16 => num!(u16, 2),
            Scalar::I32 => num!(i32, 4),
            Scalar::U32 => num!(u32, 4),
            Scalar::F32 => num!(f32, 4),
            Scalar::F64 => num!(f64, 8),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

impl Element {
    /// Record size when every property is a scalar (the chunked fast path).
    fn fixed_size(&self) -> Option<usize> {
        self.props.iter().try_fold(0usize, |acc, p| match p.kind {
            Kind::Scalar(s) => Some(acc + s.size()),
            Kind::List { .. } => None,
        })
    }

    fn find(&self, name: &str) -> Option<(usize, &Property)> {
        self.props.iter().enumerate().find(|(_, p)| p.name == name)
    }
}

#[derive(Debug)]
struct Header {
    format: Format,
    elements: Vec<Element>,
}

// ---------------------------------------------------------------- helpers

fn input(file: &str, problem: impl Into<String>) -> Error {
    Error::input(file, problem)
}

fn plural(n: u64, one: &str, many: &str) -> String {
    if n == 1 {
        format!("{n} {one}")
    } else {
        format!("{n} {many}")
    }
}

/// Names the format when the bytes are clearly something other than a PLY file.
fn sniff_other_format(start: &[u8]) -> Option<&'static str> {
    if start.starts_with(b"PK\x03\x04") || start.starts_with(b"PK\x05\x06") {
        return Some("this looks like a ZIP archive, not a PLY file (unzip it and load the frames inside; a NumPy archive loads named .npz)");
    }
    if start.starts_with(super::npy::MAGIC) {
        return Some(
            "this looks like a NumPy array, not a PLY file (name it .npy to load it as one)",
        );
    }
    if super::pcd::looks_like_pcd(start) {
        return Some("this looks like a PCD file, not a PLY file (name it .pcd to load it as one)");
    }
    if start.starts_with(&[0x1f, 0x8b]) {
        return Some(
            "this looks like a gzip-compressed file, not a PLY file (decompress it first)",
        );
    }
    let text = String::from_utf8_lossy(&start[..start.len().min(512)]);
    let first = text
        .lines()
        .map(str::trim_start)
        .find(|l| !l.is_empty())
        .unwrap_or("");
    let obj_prefixes = [
        "v ", "vn ", "vt ", "f ", "o ", "g ", "mtllib ", "usemtl ", "#",
    ];
    if obj_prefixes.iter().any(|p| first.starts_with(p)) {
        return Some(
            "this looks like a Wavefront OBJ file, not a PLY file (name it .obj to load it as one)",
        );
    }
    if first.starts_with("solid") {
        return Some("this looks like an STL file, not a PLY file (convert it to PLY)");
    }
    if first.starts_with('{') || first.starts_with('[') {
        return Some("this looks like a JSON file, not a PLY file");
    }
    None
}

/// Reads bytes until `buf` is full or the reader ends; returns how many were read.
fn read_full<R: Read>(r: &mut R, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match r.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

// ---------------------------------------------------------------- header parsing

/// Checks the first bytes of the file (as many as [`SNIFF_BYTES`], fewer only when the
/// file is shorter) so that a ZIP/OBJ/... gets a message naming what it is.
fn check_magic(start: &[u8], file: &str) -> Result<()> {
    if start.is_empty() {
        return Err(input(file, "the file is empty, not a PLY file"));
    }
    if start.starts_with(b"ply\n") || start.starts_with(b"ply\r") {
        return Ok(());
    }
    if let Some(what) = sniff_other_format(start) {
        return Err(input(file, what));
    }
    if b"ply".starts_with(start) {
        return Err(input(
            file,
            "malformed header: the file ends before the 'end_header' line",
        ));
    }
    Err(input(
        file,
        "not a PLY file: it does not start with the line 'ply'",
    ))
}

fn read_header<R: BufRead>(r: &mut R, file: &str) -> Result<Header> {
    let io_err = |e: std::io::Error| Error::io(file, e);
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut line = Vec::with_capacity(128);
    let mut total = 0usize;
    let mut lineno = 0usize;
    loop {
        line.clear();
        let n = r
            .by_ref()
            .take((MAX_HEADER_BYTES - total) as u64 + 1)
            .read_until(b'\n', &mut line)
            .map_err(io_err)?;
        total += n;
        lineno += 1;
        if n == 0 {
            return Err(input(
                file,
                "malformed header: the file ends before the 'end_header' line",
            ));
        }
        if total > MAX_HEADER_BYTES {
            return Err(input(
                file,
                "malformed header: no 'end_header' line in the first 1 MiB",
            ));
        }
        if !line.ends_with(b"\n") {
            return Err(input(
                file,
                "malformed header: the file ends before the 'end_header' line",
            ));
        }
        let text = match std::str::from_utf8(&line) {
            Ok(t) => t.trim(),
            Err(_) => {
                return Err(input(
                    file,
                    format!("malformed header: line {lineno} is not text"),
                ))
            }
        };
        if lineno == 1 {
            if text != "ply" {
                return Err(input(
                    file,
                    "not a PLY file: it does not start with the line 'ply'",
                ));
            }
            continue;
        }
        let mut words = text.split_ascii_whitespace();
        let keyword = words.next().unwrap_or("");
        let bad = |what: String| input(file, format!("malformed header, line {lineno}: {what}"));
        match keyword {
            "" | "comment" | "obj_info" => {}
            "format" => {
                if format.is_some() {
                    return Err(bad("a second 'format' line".into()));
                }
                let f = match words.next() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::BinaryLe,
                    Some("binary_big_endian") => Format::BinaryBe,
                    Some(other) => {
                        return Err(input(
                            file,
                            format!(
                                "unknown PLY format '{other}' (expected ascii, binary_little_endian or binary_big_endian)"
                            ),
                        ))
                    }
                    None => return Err(bad("'format' without a format name".into())),
                };
                match words.next() {
                    Some(v) if v.starts_with('1') => {}
                    Some(v) => {
                        return Err(input(
                            file,
                            format!("unsupported PLY version '{v}' (only 1.0 is supported)"),
                        ))
                    }
                    None => return Err(bad("'format' without a version".into())),
                }
                format = Some(f);
            }
            "element" => {
                let name = words
                    .next()
                    .ok_or_else(|| bad("'element' without a name".into()))?;
                let count = words
                    .next()
                    .ok_or_else(|| bad(format!("element '{name}' without a count")))?;
                let count: u64 = count
                    .parse()
                    .map_err(|_| bad(format!("element '{name}' has an invalid count '{count}'")))?;
                if elements.iter().any(|e| e.name == name) {
                    return Err(bad(format!("element '{name}' declared twice")));
                }
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            "property" => {
                let Some(el) = elements.last_mut() else {
                    return Err(bad("a 'property' line before any 'element' line".into()));
                };
                let ty = words
                    .next()
                    .ok_or_else(|| bad("'property' without a type".into()))?;
                let scalar = |s: Option<&str>| -> Result<Scalar> {
                    let s = s.ok_or_else(|| bad("incomplete 'property' line".into()))?;
                    Scalar::parse(s).ok_or_else(|| {
                        input(
                            file,
                            format!("unknown property type '{s}' on header line {lineno}"),
                        )
                    })
                };
                let kind = if ty == "list" {
                    let count = scalar(words.next())?;
                    if !count.is_integer() {
                        return Err(bad("a list's count type must be an integer type".into()));
                    }
                    let item = scalar(words.next())?;
                    Kind::List { count, item }
                } else {
                    Kind::Scalar(scalar(Some(ty))?)
                };
                let name = words
                    .next()
                    .ok_or_else(|| bad("'property' without a name".into()))?;
                el.props.push(Property {
                    name: name.to_string(),
                    kind,
                });
            }
            "end_header" => break,
            other => return Err(bad(format!("unknown keyword '{other}'"))),
        }
    }
    let format = format.ok_or_else(|| input(file, "malformed header: no 'format' line"))?;
    Ok(Header { format, elements })
}

// ---------------------------------------------------------------- body

/// Where the interesting vertex properties sit in a record.
struct VertexLayout {
    xyz: [usize; 3],
    label: Option<usize>,
}

/// Sink for the values of one element; the vertex and face elements collect, others skip.
enum Target<'a> {
    Skip,
    Vertex(&'a VertexLayout),
    Face(usize),
}

struct Body {
    points: Vec<Vec3>,
    labels: Option<Vec<u32>>,
    faces: Vec<[u32; 3]>,
    has_face_list: bool,
}

impl Body {
    fn push_vertex(&mut self, file: &str, idx: u64, v: [f64; 3], label: Option<f64>) -> Result<()> {
        let p = Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
        if !p.is_finite() {
            return Err(input(
                file,
                format!(
                    "non-finite coordinates at vertex {idx}: ({}, {}, {})",
                    v[0], v[1], v[2]
                ),
            ));
        }
        self.points.push(p);
        if let (Some(labels), Some(l)) = (self.labels.as_mut(), label) {
            if l < 0.0 {
                return Err(input(
                    file,
                    format!("negative part label {l} at vertex {idx}"),
                ));
            }
            let l = part_label(l).ok_or_else(|| {
                input(
                    file,
                    format!("part label {l} at vertex {idx} is not a non-negative integer"),
                )
            })?;
            labels.push(l);
        }
        Ok(())
    }

    fn push_polygon(&mut self, file: &str, idx: u64, poly: &[f64]) -> Result<()> {
        for &i in poly {
            if i < 0.0 || i.fract() != 0.0 || i > u32::MAX as f64 {
                return Err(input(
                    file,
                    format!("face {idx} has an invalid vertex index {i}"),
                ));
            }
        }
        // Fan triangulation: polygons are convex in practice, and the area sampler only
        // needs a covering of the surface.
        for k in 2..poly.len() {
            self.faces
                .push([poly[0] as u32, poly[k - 1] as u32, poly[k] as u32]);
        }
        Ok(())
    }
}

fn truncated(file: &str, el: &Element, read: u64) -> Error {
    let what = if el.name == "vertex" {
        format!(
            "truncated body: the header declares {} but only {} could be read",
            plural(el.count, "vertex", "vertices"),
            read
        )
    } else {
        format!(
            "truncated body: element '{}' declares {} records but only {} could be read",
            el.name, el.count, read
        )
    };
    input(file, what)
}

fn read_binary_element<R: BufRead>(
    r: &mut R,
    file: &str,
    el: &Element,
    big: bool,
    target: Target,
    body: &mut Body,
) -> Result<()> {
    let io_err = |e: std::io::Error| Error::io(file, e);
    if el.props.is_empty() || el.count == 0 {
        return Ok(());
    }
    if let Some(size) = el.fixed_size() {
        // Fast path: whole records in chunks.
        let per_chunk = (CHUNK_BYTES / size).max(1);
        let mut buf = vec![0u8; per_chunk * size];
        let offsets: Vec<usize> = el
            .props
            .iter()
            .scan(0usize, |off, p| {
                let o = *off;
                if let Kind::Scalar(s) = p.kind {
                    *off += s.size();
                }
                Some(o)
            })
            .collect();
        let scalar_of = |i: usize| match el.props[i].kind {
            Kind::Scalar(s) => s,
            Kind::List { count, .. } => count,
        };
        let mut done: u64 = 0;
        while done < el.count {
            let n = (el.count - done).min(per_chunk as u64) as usize;
            let want = n * size;
            let got = read_full(r, &mut buf[..want]).map_err(io_err)?;
            let whole = got / size;
            if let Target::Vertex(layout) = target {
                for rec in buf[..whole * size].chunks_exact(size) {
                    let get = |i: usize| {
                        let o = offsets[i];
                        let s = scalar_of(i);
                        s.decode(&rec[o..o + s.size()], big)
                    };
                    let xyz = [get(layout.xyz[0]), get(layout.xyz[1]), get(layout.xyz[2])];
                    let label = layout.label.map(get);
                    body.push_vertex(file, done, xyz, label)?;
                    done += 1;
                }
            } else {
                done += whole as u64;
            }
            if got < want {
                return Err(truncated(file, el, done));
            }
        }
        return Ok(());
    }

    // Records with lists: field by field (the BufRead keeps this cheap).
    let mut scratch = [0u8; 8];
    let mut values: Vec<f64> = Vec::with_capacity(el.props.len());
    let mut poly: Vec<f64> = Vec::new();
    let mut read_scalar = |r: &mut R, s: Scalar| -> std::io::Result<Option<f64>> {
        let b = &mut scratch[..s.size()];
        let got = read_full(r, b)?;
        Ok((got == b.len()).then(|| s.decode(b, big)))
    };
    for idx in 0..el.count {
        values.clear();
        for (pi, p) in el.props.iter().enumerate() {
            match p.kind {
                Kind::Scalar(s) => {
                    let v = read_scalar(r, s).map_err(io_err)?;
                    values.push(v.ok_or_else(|| truncated(file, el, idx))?);
                }
                Kind::List { count, item } => {
                    let n = read_scalar(r, count)
                        .map_err(io_err)?
                        .ok_or_else(|| truncated(file, el, idx))?;
                    if n < 0.0 {
                        return Err(input(
                            file,
                            format!(
                                "element '{}' record {idx} has a negative list length {n}",
                                el.name
                            ),
                        ));
                    }
                    values.push(n);
                    let collect = matches!(target, Target::Face(fi) if fi == pi);
                    poly.clear();
                    for _ in 0..n as u64 {
                        let v = read_scalar(r, item)
                            .map_err(io_err)?
                            .ok_or_else(|| truncated(file, el, idx))?;
                        if collect {
                            poly.push(v);
                        }
                    }
                    if collect {
                        body.push_polygon(file, idx, &poly)?;
                    }
                }
            }
        }
        if let Target::Vertex(layout) = target {
            let xyz = [
                values[layout.xyz[0]],
                values[layout.xyz[1]],
                values[layout.xyz[2]],
            ];
            body.push_vertex(file, idx, xyz, layout.label.map(|i| values[i]))?;
        }
    }
    Ok(())
}

fn read_ascii_element<R: BufRead>(
    r: &mut R,
    file: &str,
    el: &Element,
    target: Target,
    body: &mut Body,
    line: &mut Vec<u8>,
) -> Result<()> {
    let io_err = |e: std::io::Error| Error::io(file, e);
    if el.props.is_empty() || el.count == 0 {
        return Ok(());
    }
    let mut values: Vec<f64> = Vec::with_capacity(el.props.len());
    let mut poly: Vec<f64> = Vec::new();
    let mut idx: u64 = 0;
    while idx < el.count {
        line.clear();
        let n = r.read_until(b'\n', line).map_err(io_err)?;
        if n == 0 {
            return Err(truncated(file, el, idx));
        }
        let text = std::str::from_utf8(line).map_err(|_| {
            input(
                file,
                format!(
                    "element '{}' record {idx} is not text (is the header's format right?)",
                    el.name
                ),
            )
        })?;
        let at_eof = !line.ends_with(b"\n");
        let mut tokens = text.split_ascii_whitespace();
        let Some(first) = tokens.next() else {
            continue; // blank line
        };
        let mut tokens = std::iter::once(first).chain(tokens);
        let mismatch = |detail: &str| {
            input(
                file,
                format!(
                    "header/body mismatch: element '{}' record {idx} {detail} (the header declares {} properties: {})",
                    el.name,
                    el.props.len(),
                    el.props.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join(" ")
                ),
            )
        };
        let next = |tokens: &mut dyn Iterator<Item = &str>| -> Result<f64> {
            let t = tokens.next().ok_or_else(|| {
                // A short last line without its newline is a cut-off file.
                if at_eof {
                    truncated(file, el, idx)
                } else {
                    mismatch("has too few values")
                }
            })?;
            t.parse::<f64>()
                .map_err(|_| mismatch(&format!("has a value '{t}' that is not a number")))
        };
        values.clear();
        for (pi, p) in el.props.iter().enumerate() {
            match p.kind {
                Kind::Scalar(_) => {
                    let v = next(&mut tokens)?;
                    values.push(v);
                }
                Kind::List { .. } => {
                    let n = next(&mut tokens)?;
                    if n < 0.0 || n.fract() != 0.0 {
                        return Err(mismatch(&format!("has an invalid list length {n}")));
                    }
                    values.push(n);
                    let collect = matches!(target, Target::Face(fi) if fi == pi);
                    poly.clear();
                    for _ in 0..n as u64 {
                        let v = next(&mut tokens)?;
                        if collect {
                            poly.push(v);
                        }
                    }
                    if collect {
                        body.push_polygon(file, idx, &poly)?;
                    }
                }
            }
        }
        if tokens.next().is_some() {
            return Err(mismatch("has more values than declared"));
        }
        if let Target::Vertex(layout) = target {
            let xyz = [
                values[layout.xyz[0]],
                values[layout.xyz[1]],
                values[layout.xyz[2]],
            ];
            body.push_vertex(file, idx, xyz, layout.label.map(|i| values[i]))?;
        }
        idx += 1;
    }
    Ok(())
}

fn vertex_layout(file: &str, el: &Element) -> Result<VertexLayout> {
    let mut xyz = [0usize; 3];
    for (k, name) in ["x", "y", "z"].iter().enumerate() {
        match el.find(name) {
            Some((i, p)) if matches!(p.kind, Kind::Scalar(_)) => xyz[k] = i,
            Some(_) => {
                return Err(input(
                    file,
                    format!("the vertex property '{name}' is a list, expected a number"),
                ))
            }
            None => {
                let names: Vec<&str> = el.props.iter().map(|p| p.name.as_str()).collect();
                return Err(input(
                    file,
                    format!(
                        "the vertex element has no '{name}' property (it has: {})",
                        if names.is_empty() {
                            "none".to_string()
                        } else {
                            names.join(", ")
                        }
                    ),
                ));
            }
        }
    }
    let label = ["part", "label"].iter().find_map(|n| {
        el.find(n)
            .filter(|(_, p)| matches!(p.kind, Kind::Scalar(_)))
            .map(|(i, _)| i)
    });
    Ok(VertexLayout { xyz, label })
}

/// Reads a PLY file held in memory. `file` names it in error messages.
///
/// Checks the structure (magic, header, body length, coordinates, labels); whether
/// the cloud is usable as a frame is [`validate_points`]'s job (a mesh may have few
/// vertices).
pub fn read_ply(bytes: &[u8], file: &str) -> Result<PlyCloud> {
    read_ply_from(bytes, file)
}

/// Streams a PLY file from any reader (wrap files in nothing: this buffers itself).
pub fn read_ply_from<R: Read>(reader: R, file: &str) -> Result<PlyCloud> {
    // Read the start whole (whatever sizes the reader hands out) to recognise other
    // formats, then continue over it and the rest of the stream.
    let mut reader = reader;
    let mut start = vec![0u8; SNIFF_BYTES];
    let got = read_full(&mut reader, &mut start).map_err(|e| Error::io(file, e))?;
    start.truncate(got);
    check_magic(&start, file)?;
    let mut r = BufReader::with_capacity(CHUNK_BYTES, std::io::Cursor::new(start).chain(reader));
    let header = read_header(&mut r, file)?;

    let vi = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| {
            input(
                file,
                "no 'vertex' element in the header: the file has no points",
            )
        })?;
    let vertex = &header.elements[vi];
    if vertex.count == 0 {
        return Err(input(file, "the file has 0 vertices"));
    }
    let layout = vertex_layout(file, vertex)?;

    // The face element, if any, with its index list.
    let face = header
        .elements
        .iter()
        .position(|e| e.name == "face")
        .and_then(|fi| {
            let el = &header.elements[fi];
            ["vertex_indices", "vertex_index"].iter().find_map(|n| {
                el.find(n)
                    .filter(|(_, p)| matches!(p.kind, Kind::List { .. }))
                    .map(|(pi, _)| (fi, pi))
            })
        });

    // Reserve for what the header promises, bounded so a lying header cannot make us
    // allocate gigabytes before the body proves it.
    let reserve = vertex.count.min(1 << 20) as usize;
    let mut body = Body {
        points: Vec::with_capacity(reserve),
        labels: layout.label.map(|_| Vec::with_capacity(reserve)),
        faces: Vec::new(),
        has_face_list: face.is_some(),
    };
    let mut line = Vec::new();
    for (ei, el) in header.elements.iter().enumerate() {
        let target = if ei == vi {
            Target::Vertex(&layout)
        } else if let Some((_, pi)) = face.filter(|(fi, _)| *fi == ei) {
            Target::Face(pi)
        } else {
            Target::Skip
        };
        match header.format {
            Format::Ascii => read_ascii_element(&mut r, file, el, target, &mut body, &mut line)?,
            Format::BinaryLe => read_binary_element(&mut r, file, el, false, target, &mut body)?,
            Format::BinaryBe => read_binary_element(&mut r, file, el, true, target, &mut body)?,
        }
    }

    // Anything after the last declared element means the header does not describe the body.
    let io_err = |e: std::io::Error| Error::io(file, e);
    match header.format {
        Format::Ascii => loop {
            line.clear();
            if r.read_until(b'\n', &mut line).map_err(io_err)? == 0 {
                break;
            }
            if !line.iter().all(u8::is_ascii_whitespace) {
                return Err(input(
                    file,
                    format!(
                        "header/body mismatch: there is more data after the {} declared in the header",
                        describe_counts(&header)
                    ),
                ));
            }
        },
        _ => {
            let extra = std::io::copy(&mut r, &mut std::io::sink()).map_err(io_err)?;
            if extra > 0 {
                return Err(input(
                    file,
                    format!(
                        "header/body mismatch: {} left over after the {} declared in the header",
                        plural(extra, "byte", "bytes"),
                        describe_counts(&header)
                    ),
                ));
            }
        }
    }

    let n = body.points.len() as u64;
    let faces = if body.has_face_list && !body.faces.is_empty() {
        if let Some(bad) = body.faces.iter().flatten().find(|&&i| i as u64 >= n) {
            return Err(input(
                file,
                format!("a face refers to vertex {bad}, but the file has only {n} vertices"),
            ));
        }
        Some(body.faces)
    } else {
        None
    };
    Ok(PlyCloud {
        points: body.points,
        labels: body.labels,
        faces,
    })
}

fn describe_counts(h: &Header) -> String {
    h.elements
        .iter()
        .map(|e| format!("{} '{}' records", e.count, e.name))
        .collect::<Vec<_>>()
        .join(", ")
}

// ---------------------------------------------------------------- validation

/// A ground-truth part id read as a number (every frame format's labels): a
/// non-negative integer that fits u32, else `None`.
pub(crate) fn part_label(v: f64) -> Option<u32> {
    ((0.0..=u32::MAX as f64).contains(&v) && v.fract() == 0.0).then_some(v as u32)
}

/// Checks that a point cloud is usable as a frame: at least [`MIN_POINTS`] points,
/// all finite, not all identical, not all in one plane (or on one line).
pub fn validate_points(points: &[Vec3], file: &str) -> Result<()> {
    if points.len() < MIN_POINTS {
        return Err(input(
            file,
            format!(
                "too few points: {} (a frame needs at least {MIN_POINTS})",
                points.len()
            ),
        ));
    }
    if let Some(i) = points.iter().position(|p| !p.is_finite()) {
        return Err(input(file, format!("non-finite coordinates at vertex {i}")));
    }
    // PCA of the cloud in f64 (f32 sums over a million points would lose the thin axis).
    let n = points.len() as f64;
    let mut mean = [0.0f64; 3];
    for p in points {
        mean[0] += p.x as f64;
        mean[1] += p.y as f64;
        mean[2] += p.z as f64;
    }
    mean.iter_mut().for_each(|m| *m /= n);
    let mut c = [[0.0f64; 3]; 3];
    let mut max_abs = 0.0f64;
    for p in points {
        let d = [
            p.x as f64 - mean[0],
            p.y as f64 - mean[1],
            p.z as f64 - mean[2],
        ];
        for i in 0..3 {
            for j in i..3 {
                c[i][j] += d[i] * d[j];
            }
        }
        max_abs = max_abs.max(p.abs().max_element() as f64);
    }
    let cov = Matrix3::new(
        c[0][0], c[0][1], c[0][2], c[0][1], c[1][1], c[1][2], c[0][2], c[1][2], c[2][2],
    ) / n;
    let eig = SymmetricEigen::new(cov).eigenvalues;
    let largest = eig.max().max(0.0);
    let smallest = eig.min().max(0.0);
    // f32 coordinates carry ~1e-7 relative noise, so a spread below ~1e-6 of the
    // magnitude of the coordinates is no spread at all.
    let noise = (max_abs * 1e-6).powi(2);
    if largest <= noise {
        return Err(input(
            file,
            format!(
                "degenerate cloud: all {} points are identical",
                points.len()
            ),
        ));
    }
    // Thickness ratio below 1e-5 (eigenvalue ratio 1e-10) is a plane or a line.
    if smallest <= largest * 1e-10 || smallest <= noise {
        return Err(input(
            file,
            format!(
                "degenerate cloud: all {} points lie in one plane (or on one line), no 3D shape to fit",
                points.len()
            ),
        ));
    }
    Ok(())
}

// ---------------------------------------------------------------- mesh sampling

/// Samples `n` points uniformly by area on a triangle mesh, seeded. A sampled point
/// takes the label of its triangle's first vertex when labels exist.
///
/// Errors (named after `file`) when the mesh has no triangles, a face index is out
/// of range, or the total area is zero.
pub fn sample_mesh(
    points: &[Vec3],
    faces: &[[u32; 3]],
    labels: Option<&[u32]>,
    n: usize,
    seed: u64,
    file: &str,
) -> Result<(Vec<Vec3>, Option<Vec<u32>>)> {
    if faces.is_empty() {
        return Err(input(file, "the mesh has no faces to sample"));
    }
    let nv = points.len();
    if labels.is_some_and(|l| l.len() != nv) {
        return Err(input(file, "labels and vertices differ in number"));
    }
    let mut cum = Vec::with_capacity(faces.len());
    let mut total = 0.0f64;
    for f in faces {
        if f.iter().any(|&i| i as usize >= nv) {
            return Err(input(
                file,
                format!("a face refers to a vertex beyond the {nv} vertices"),
            ));
        }
        let [a, b, c] = f.map(|i| points[i as usize].as_dvec3());
        total += 0.5 * (b - a).cross(c - a).length();
        cum.push(total);
    }
    if !(total > 0.0 && total.is_finite()) {
        return Err(input(
            file,
            "degenerate mesh: its triangles have zero total area",
        ));
    }
    let mut rng = StdRng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n);
    let mut out_labels = labels.map(|_| Vec::with_capacity(n));
    for _ in 0..n {
        let u = rng.random::<f64>() * total;
        // First triangle whose cumulative area exceeds u (zero-area ones are never hit).
        let t = cum.partition_point(|&c| c <= u).min(faces.len() - 1);
        let f = faces[t];
        let [a, b, c] = f.map(|i| points[i as usize].as_dvec3());
        let (r1, r2): (f64, f64) = (rng.random(), rng.random());
        let s = r1.sqrt();
        let p = a * (1.0 - s) + b * (s * (1.0 - r2)) + c * (s * r2);
        out.push(p.as_vec3());
        if let (Some(ol), Some(l)) = (out_labels.as_mut(), labels) {
            ol.push(l[f[0] as usize]);
        }
    }
    Ok((out, out_labels))
}

// ---------------------------------------------------------------- writing

/// Writes a point cloud in the benchmark layout: `float x y z` and, with labels,
/// `int part`; binary little endian (16-byte records) unless `ascii`.
pub fn write_ply(
    w: &mut impl Write,
    points: &[Vec3],
    labels: Option<&[u32]>,
    ascii: bool,
) -> std::io::Result<()> {
    use std::io::{Error as IoError, ErrorKind};
    if let Some(l) = labels {
        if l.len() != points.len() {
            return Err(IoError::new(
                ErrorKind::InvalidInput,
                format!("{} labels for {} points", l.len(), points.len()),
            ));
        }
        if l.iter().any(|&v| v > i32::MAX as u32) {
            return Err(IoError::new(
                ErrorKind::InvalidInput,
                "a label does not fit the PLY 'int part' property",
            ));
        }
    }
    let mut head = String::new();
    head.push_str("ply\n");
    head.push_str(if ascii {
        "format ascii 1.0\n"
    } else {
        "format binary_little_endian 1.0\n"
    });
    head.push_str("comment written by gsart\n");
    head.push_str(&format!("element vertex {}\n", points.len()));
    head.push_str("property float x\nproperty float y\nproperty float z\n");
    if labels.is_some() {
        head.push_str("property int part\n");
    }
    head.push_str("end_header\n");
    w.write_all(head.as_bytes())?;

    let mut buf: Vec<u8> = Vec::with_capacity(CHUNK_BYTES + 64);
    for (i, p) in points.iter().enumerate() {
        if ascii {
            // `{}` prints the shortest text that reads back to the same f32.
            match labels {
                Some(l) => writeln!(buf, "{} {} {} {}", p.x, p.y, p.z, l[i])?,
                None => writeln!(buf, "{} {} {}", p.x, p.y, p.z)?,
            }
        } else {
            buf.extend_from_slice(&p.x.to_le_bytes());
            buf.extend_from_slice(&p.y.to_le_bytes());
            buf.extend_from_slice(&p.z.to_le_bytes());
            if let Some(l) = labels {
                buf.extend_from_slice(&(l[i] as i32).to_le_bytes());
            }
        }
        if buf.len() >= CHUNK_BYTES {
            w.write_all(&buf)?;
            buf.clear();
        }
    }
    w.write_all(&buf)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Libm;

    fn cube(n: usize) -> Vec<Vec3> {
        (0..n)
            .map(|i| {
                let f = i as f32;
                Vec3::new(
                    (f * 0.37).lsin(),
                    (f * 0.71).lcos(),
                    (f * 1.13).lsin() * 0.5,
                )
            })
            .collect()
    }

    #[test]
    fn binary_round_trip_with_labels() {
        let pts = cube(40);
        let labels: Vec<u32> = (0..40).map(|i| i % 3).collect();
        let mut bytes = Vec::new();
        write_ply(&mut bytes, &pts, Some(&labels), false).unwrap();
        let c = read_ply(&bytes, "t.ply").unwrap();
        assert_eq!(c.points, pts);
        assert_eq!(c.labels.as_deref(), Some(&labels[..]));
        assert!(c.faces.is_none());
    }

    #[test]
    fn ascii_round_trip_exact() {
        let pts = cube(33);
        let mut bytes = Vec::new();
        write_ply(&mut bytes, &pts, None, true).unwrap();
        let c = read_ply(&bytes, "t.ply").unwrap();
        assert_eq!(c.points, pts);
        assert!(c.labels.is_none());
    }

    #[test]
    fn scalar_decoding_both_endians() {
        assert_eq!(Scalar::I16.decode(&[0xff, 0xfe], false), -257.0);
        assert_eq!(Scalar::I16.decode(&[0xfe, 0xff], true), -257.0);
        assert_eq!(Scalar::U8.decode(&[200], false), 200.0);
        assert_eq!(Scalar::I8.decode(&[200], false), -56.0);
        assert_eq!(Scalar::F64.decode(&1.5f64.to_be_bytes(), true), 1.5);
    }

    #[test]
    fn validate_rejects_plane_and_identical() {
        let plane: Vec<Vec3> = (0..50)
            .map(|i| Vec3::new(i as f32 * 0.1, (i * i % 7) as f32, 2.0))
            .collect();
        let e = validate_points(&plane, "p.ply").unwrap_err().to_string();
        assert!(e.contains("p.ply") && e.contains("plane"), "{e}");
        let same = vec![Vec3::splat(3.0); 20];
        let e = validate_points(&same, "s.ply").unwrap_err().to_string();
        assert!(e.contains("identical"), "{e}");
        validate_points(&cube(20), "ok.ply").unwrap();
    }
}
