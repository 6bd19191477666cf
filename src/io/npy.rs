//! NumPy arrays (`.npy`) as point clouds: what 3D-vision code most often saves.
//!
//! An array of shape `(N, C)` is one frame, `(T, N, C)` is T frames, with `C ≥ 3`:
//! the first three columns are `x y z`, the others (normals, colours) are skipped.
//! Any float or integer dtype, either byte order, C or Fortran order, format versions
//! 1–3. A row with a NaN coordinate is no point (how arrays pad frames of different
//! sizes, or mark a depth camera's missing pixels) and is dropped; an infinite one is
//! an error. An integer array of shape `(N,)` or `(T, N)` can carry the points'
//! ground-truth part ids ([`read_labels`], used by `.npz` archives).

use glam::Vec3;

use crate::error::{Error, Result};

/// The magic string every `.npy` file starts with.
pub const MAGIC: &[u8] = b"\x93NUMPY";

/// Element type of an array, from its `descr`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Float,
    Int,
    Uint,
    Bool,
}

/// A parsed `.npy` header and where its data starts.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Header {
    kind: Kind,
    size: usize,
    big_endian: bool,
    fortran: bool,
    shape: Vec<usize>,
    data_start: usize,
}

/// An array: its shape and its raw elements, decoded one at a time (a stack of
/// frames is never held as f64 beside its bytes).
#[derive(Debug, Clone, PartialEq)]
pub struct Array<'a> {
    pub shape: Vec<usize>,
    header: Header,
    data: std::borrow::Cow<'a, [u8]>,
}

impl Array<'_> {
    /// True for integer (and bool) dtypes: what ground-truth labels are stored as.
    pub fn integer(&self) -> bool {
        self.header.kind != Kind::Float
    }

    /// The element at index `idx` (one entry an axis) as f64.
    fn at(&self, idx: &[usize]) -> f64 {
        // Row-major: the last axis fastest; Fortran order: the first.
        let mut pos = 0;
        let axes = idx.iter().zip(&self.shape);
        if self.header.fortran {
            for (i, n) in axes.rev() {
                pos = pos * n + i;
            }
        } else {
            for (i, n) in axes {
                pos = pos * n + i;
            }
        }
        let size = self.header.size;
        element(&self.header, &self.data[pos * size..(pos + 1) * size])
    }
}

fn input(file: &str, problem: impl Into<String>) -> Error {
    Error::input(file, problem)
}

/// Reads one `.npy` array of any numeric dtype, borrowing its bytes.
pub fn read_array<'a>(
    bytes: impl Into<std::borrow::Cow<'a, [u8]>>,
    file: &str,
) -> Result<Array<'a>> {
    let bytes = bytes.into();
    let h = parse_header(&bytes, file)?;
    let count = h
        .shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(|| input(file, "the array's shape is too large"))?;
    let need = count
        .checked_mul(h.size)
        .and_then(|b| b.checked_add(h.data_start))
        .ok_or_else(|| input(file, "the array's shape is too large"))?;
    if bytes.len() < need {
        return Err(input(
            file,
            format!(
                "truncated: the header announces shape {:?} ({} bytes of data) but the file holds {}",
                h.shape,
                count * h.size,
                bytes.len() - h.data_start
            ),
        ));
    }
    let data = match bytes {
        std::borrow::Cow::Borrowed(b) => std::borrow::Cow::Borrowed(&b[h.data_start..need]),
        std::borrow::Cow::Owned(mut b) => {
            b.truncate(need);
            b.drain(..h.data_start);
            std::borrow::Cow::Owned(b)
        }
    };
    Ok(Array {
        shape: h.shape.clone(),
        header: h,
        data,
    })
}

/// Frames of a `.npy` file: `(N, C)` → one, `(T, N, C)` → T (see the module doc).
pub fn read_npy(bytes: &[u8], file: &str) -> Result<Vec<Vec<Vec3>>> {
    frames_of(&read_array(bytes, file)?, file)
}

/// The point frames an array holds (see the module doc).
pub fn frames_of(a: &Array, file: &str) -> Result<Vec<Vec<Vec3>>> {
    let (t, n, c) = match a.shape[..] {
        [n, c] => (1, n, c),
        [t, n, c] => (t, n, c),
        _ => {
            return Err(input(
                file,
                format!(
                    "an array of shape {:?} is not points: expected (N, 3) for one frame or (T, N, 3) for T frames",
                    a.shape
                ),
            ))
        }
    };
    if c < 3 {
        return Err(input(
            file,
            format!(
                "an array of shape {:?} is not points: its last axis has {c} columns, x y z need 3",
                a.shape
            ),
        ));
    }
    let row = |k: usize, i: usize| -> [f64; 3] {
        if a.shape.len() == 2 {
            [0, 1, 2].map(|j| a.at(&[i, j]))
        } else {
            [0, 1, 2].map(|j| a.at(&[k, i, j]))
        }
    };
    let mut frames = Vec::with_capacity(t);
    for k in 0..t {
        let mut pts = Vec::with_capacity(n);
        for i in 0..n {
            let r = row(k, i);
            if r.iter().any(|v| v.is_nan()) {
                continue;
            }
            if r.iter().any(|v| v.is_infinite()) {
                let at = if t > 1 {
                    format!("[{k}, {i}]")
                } else {
                    format!("[{i}]")
                };
                return Err(input(file, format!("infinite coordinate in row {at}")));
            }
            pts.push(Vec3::new(r[0] as f32, r[1] as f32, r[2] as f32));
        }
        frames.push(pts);
    }
    Ok(frames)
}

/// Per-frame labels from an integer array of shape `(N,)` (one frame) or `(T, N)`,
/// with NaN rows of `points` (the frames' source array) dropped as the frames drop
/// them. `None` when the shapes do not correspond.
pub fn read_labels(labels: &Array, points: &Array, file: &str) -> Result<Option<Vec<Vec<u32>>>> {
    let (t, n) = match (&labels.shape[..], &points.shape[..]) {
        ([n], [pn, _]) if n == pn => (1, *n),
        ([t, n], [pt, pn, _]) if t == pt && n == pn => (*t, *n),
        _ => return Ok(None),
    };
    if !labels.integer() {
        return Err(input(file, "part labels must be an integer array"));
    }
    let stacked = points.shape.len() == 3;
    let mut out = Vec::with_capacity(t);
    for k in 0..t {
        let mut l = Vec::with_capacity(n);
        for i in 0..n {
            let nan = (0..3).any(|j| {
                let v = if stacked {
                    points.at(&[k, i, j])
                } else {
                    points.at(&[i, j])
                };
                v.is_nan()
            });
            if nan {
                continue;
            }
            let v = if stacked {
                labels.at(&[k, i])
            } else {
                labels.at(&[i])
            };
            // An integer array's values are whole numbers: only the range can fail.
            l.push(
                super::ply::part_label(v).ok_or_else(|| {
                    input(file, format!("part label {v} is negative or too large"))
                })?,
            );
        }
        out.push(l);
    }
    Ok(Some(out))
}

fn parse_header(bytes: &[u8], file: &str) -> Result<Header> {
    if !bytes.starts_with(MAGIC) {
        return Err(input(
            file,
            "not a NumPy .npy file (it does not start with \\x93NUMPY)",
        ));
    }
    if bytes.len() < 10 {
        return Err(input(file, "truncated .npy header"));
    }
    let major = bytes[6];
    let (len, start): (usize, usize) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err(input(file, "truncated .npy header"));
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            )
        }
        v => {
            return Err(input(
                file,
                format!(".npy format version {v} is not supported (1–3 are)"),
            ))
        }
    };
    let end = start
        .checked_add(len)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| input(file, "truncated .npy header"))?;
    let text = std::str::from_utf8(&bytes[start..end])
        .map_err(|_| input(file, "the .npy header is not text"))?;
    let descr =
        dict_value(text, "descr").ok_or_else(|| input(file, "the .npy header has no 'descr'"))?;
    let descr = unquote(descr).ok_or_else(|| {
        input(
            file,
            format!("dtype {descr} is not supported: points need one number per element (a plain float or integer dtype)"),
        )
    })?;
    let (kind, size, big_endian) = parse_descr(descr).ok_or_else(|| {
        input(
            file,
            format!("dtype '{descr}' is not supported: points need float or integer numbers"),
        )
    })?;
    let fortran = match dict_value(text, "fortran_order").map(str::trim) {
        Some(v) if v.starts_with("True") => true,
        Some(v) if v.starts_with("False") => false,
        _ => return Err(input(file, "the .npy header has no valid 'fortran_order'")),
    };
    let shape_text =
        dict_value(text, "shape").ok_or_else(|| input(file, "the .npy header has no 'shape'"))?;
    let shape = parse_shape(shape_text)
        .ok_or_else(|| input(file, format!("bad shape in the .npy header: {shape_text}")))?;
    Ok(Header {
        kind,
        size,
        big_endian,
        fortran,
        shape,
        data_start: end,
    })
}

/// The text after `'key':` in the header's Python dict literal.
fn dict_value<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    let at = text
        .find(&format!("'{key}'"))
        .or_else(|| text.find(&format!("\"{key}\"")))?;
    let rest = &text[at + key.len() + 2..];
    let colon = rest.find(':')?;
    Some(rest[colon + 1..].trim_start())
}

/// A quoted string at the start of `v` (`'<f4', ...` → `<f4`); `None` for a
/// structured dtype (a list).
fn unquote(v: &str) -> Option<&str> {
    let q = v.chars().next().filter(|&c| c == '\'' || c == '"')?;
    let end = v[1..].find(q)?;
    Some(&v[1..1 + end])
}

fn parse_descr(d: &str) -> Option<(Kind, usize, bool)> {
    let (order, rest) = match d.as_bytes().first()? {
        b'<' | b'=' => (false, &d[1..]),
        b'|' => (false, &d[1..]),
        b'>' => (true, &d[1..]),
        _ => (false, d),
    };
    let kind = match rest.as_bytes().first()? {
        b'f' => Kind::Float,
        b'i' => Kind::Int,
        b'u' => Kind::Uint,
        b'b' => Kind::Bool,
        _ => return None,
    };
    let size: usize = rest[1..].parse().ok()?;
    let ok = match kind {
        Kind::Float => matches!(size, 2 | 4 | 8),
        Kind::Int | Kind::Uint => matches!(size, 1 | 2 | 4 | 8),
        Kind::Bool => size == 1,
    };
    ok.then_some((kind, size, order))
}

fn parse_shape(v: &str) -> Option<Vec<usize>> {
    let v = v.strip_prefix('(')?;
    let v = &v[..v.find(')')?];
    v.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.trim_end_matches('L').parse().ok())
        .collect()
}

fn element(h: &Header, c: &[u8]) -> f64 {
    let mut b = [0u8; 8];
    b[..h.size].copy_from_slice(c);
    if h.big_endian {
        b[..h.size].reverse();
    }
    match (h.kind, h.size) {
        (Kind::Float, 2) => half_to_f64(u16::from_le_bytes([b[0], b[1]])),
        (Kind::Float, 4) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        (Kind::Float, _) => f64::from_le_bytes(b),
        (Kind::Int, 1) => b[0] as i8 as f64,
        (Kind::Int, 2) => i16::from_le_bytes([b[0], b[1]]) as f64,
        (Kind::Int, 4) => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        (Kind::Int, _) => i64::from_le_bytes(b) as f64,
        (Kind::Uint | Kind::Bool, _) => u64::from_le_bytes(b) as f64,
    }
}

/// IEEE 754 half precision to f64.
fn half_to_f64(h: u16) -> f64 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let frac = (h & 0x3ff) as f64;
    match exp {
        0 => sign * frac * 2f64.powi(-24),
        31 if frac == 0.0 => sign * f64::INFINITY,
        31 => f64::NAN,
        e => sign * (1.0 + frac / 1024.0) * 2f64.powi(e - 15),
    }
}

/// A `.npy` file of `values` (C order) with dtype `descr` (`<f4`, `<f8`, `<i4`, …):
/// what NumPy's `np.save` writes, for tests and for users' tools.
pub fn write_npy(descr: &str, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_text}, }}");
    // Padded with spaces so the data starts on a 64-byte boundary, ending in '\n'.
    let total = MAGIC.len() + 4 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut out = MAGIC.to_vec();
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `b` with the first `from` replaced by `to` (of the same length).
    fn replace(b: &[u8], from: &[u8], to: &[u8]) -> Vec<u8> {
        let at = b.windows(from.len()).position(|w| w == from).unwrap();
        let mut out = b.to_vec();
        out[at..at + to.len()].copy_from_slice(to);
        out
    }

    fn f32_bytes(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    #[test]
    fn one_frame_and_a_stack_of_frames() {
        let pts = [0.0f32, 1.0, 2.0, 3.0, 4.0, 5.0];
        let one = read_npy(&write_npy("<f4", &[2, 3], &f32_bytes(&pts)), "a.npy").unwrap();
        assert_eq!(
            one,
            vec![vec![Vec3::new(0., 1., 2.), Vec3::new(3., 4., 5.)]]
        );
        let two = read_npy(&write_npy("<f4", &[2, 1, 3], &f32_bytes(&pts)), "b.npy").unwrap();
        assert_eq!(
            two,
            vec![vec![Vec3::new(0., 1., 2.)], vec![Vec3::new(3., 4., 5.)]]
        );
        // Extra columns (normals) are skipped.
        let six = read_npy(&write_npy("<f4", &[1, 6], &f32_bytes(&pts)), "c.npy").unwrap();
        assert_eq!(six, vec![vec![Vec3::new(0., 1., 2.)]]);
    }

    #[test]
    fn dtypes_byte_orders_and_fortran_order() {
        let be: Vec<u8> = [1.5f64, -2.0, 3.25]
            .iter()
            .flat_map(|x| x.to_be_bytes())
            .collect();
        let f = read_npy(&write_npy(">f8", &[1, 3], &be), "be.npy").unwrap();
        assert_eq!(f[0][0], Vec3::new(1.5, -2.0, 3.25));
        let ints: Vec<u8> = [-1i16, 2, 300]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let f = read_npy(&write_npy("<i2", &[1, 3], &ints), "i.npy").unwrap();
        assert_eq!(f[0][0], Vec3::new(-1.0, 2.0, 300.0));
        // float16: 1.0 = 0x3c00, -2.0 = 0xc000, 0.5 = 0x3800.
        let half: Vec<u8> = [0x3c00u16, 0xc000, 0x3800]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        let f = read_npy(&write_npy("<f2", &[1, 3], &half), "h.npy").unwrap();
        assert_eq!(f[0][0], Vec3::new(1.0, -2.0, 0.5));
        // Fortran order: a (2, 3) array stored column by column.
        let b = replace(
            &write_npy("<f4", &[2, 3], &f32_bytes(&[0., 3., 1., 4., 2., 5.])),
            b"'fortran_order': False",
            b"'fortran_order': True ",
        );
        // The replacement kept the header's length, so the data did not move.
        let f = read_npy(&b, "f.npy").unwrap();
        assert_eq!(f[0], vec![Vec3::new(0., 1., 2.), Vec3::new(3., 4., 5.)]);
    }

    #[test]
    fn nan_rows_are_dropped_and_infinities_refused() {
        let b = write_npy(
            "<f4",
            &[3, 3],
            &f32_bytes(&[0., 0., 0., f32::NAN, 1., 1., 2., 2., 2.]),
        );
        assert_eq!(read_npy(&b, "n.npy").unwrap()[0].len(), 2);
        let b = write_npy("<f4", &[1, 3], &f32_bytes(&[0., f32::INFINITY, 0.]));
        let e = read_npy(&b, "inf.npy").unwrap_err().to_string();
        assert!(e.starts_with("inf.npy: infinite coordinate"), "{e}");
    }

    #[test]
    fn bad_arrays_are_named() {
        let e = |b: &[u8]| read_npy(b, "x.npy").unwrap_err().to_string();
        assert!(e(b"PK\x03\x04").contains("not a NumPy .npy file"));
        assert!(e(&write_npy("<f4", &[4], &f32_bytes(&[0.; 4]))).contains("not points"));
        assert!(e(&write_npy("<f4", &[2, 2], &f32_bytes(&[0.; 4]))).contains("2 columns"));
        assert!(e(&write_npy("<c8", &[1, 3], &[0; 24])).contains("not supported"));
        let full = write_npy("<f4", &[10, 3], &f32_bytes(&[0.; 30]));
        assert!(e(&full[..full.len() - 4]).contains("truncated"));
        // Same length as the plain dtype, so the header stays whole.
        let structured = replace(
            &write_npy("<f4", &[1, 3], &f32_bytes(&[0.; 3])),
            b"'descr': '<f4'",
            b"'descr': [(x',",
        );
        assert!(e(&structured).contains("not supported"));
    }

    #[test]
    fn labels_follow_the_frames_dropped_rows() {
        let pts = read_array(
            write_npy(
                "<f4",
                &[1, 3, 3],
                &f32_bytes(&[0., 0., 0., f32::NAN, 0., 0., 1., 1., 1.]),
            ),
            "p",
        )
        .unwrap();
        let ints: Vec<u8> = [4i32, 5, 6].iter().flat_map(|x| x.to_le_bytes()).collect();
        let lab = read_array(write_npy("<i4", &[1, 3], &ints), "l").unwrap();
        assert_eq!(
            read_labels(&lab, &pts, "l").unwrap(),
            Some(vec![vec![4, 6]])
        );
        let other = read_array(write_npy("<i4", &[3], &ints), "l").unwrap();
        assert_eq!(read_labels(&other, &pts, "l").unwrap(), None);
    }
}
