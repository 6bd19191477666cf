//! Point Cloud Library files (`.pcd`, versions 0.6–0.7), as PCL and ROS tools save
//! them.
//!
//! `DATA ascii`, `binary` and `binary_compressed` (LZF); fields of any type, size and
//! count, of which `x y z` are read and an integer `label` (PCL's `PointXYZL`) or
//! `part` is the ground-truth part id. Points with a NaN coordinate are no points (an
//! organised cloud's missing pixels) and are dropped; an infinite one is an error.

use glam::Vec3;

use super::ply::{part_label, PlyCloud};
use crate::error::{Error, Result};

fn input(file: &str, problem: impl Into<String>) -> Error {
    Error::input(file, problem)
}

#[derive(Debug, Clone)]
struct Field {
    name: String,
    size: usize,
    kind: u8,
    count: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Data {
    Ascii,
    Binary,
    Compressed,
}

/// True when `bytes` start like a PCD header (a comment line or a header keyword).
pub fn looks_like_pcd(bytes: &[u8]) -> bool {
    let head = &bytes[..bytes.len().min(64)];
    head.starts_with(b"# .PCD") || head.starts_with(b"VERSION") || head.starts_with(b"FIELDS")
}

/// Reads a `.pcd` file's points (and labels).
pub fn read_pcd(bytes: &[u8], file: &str) -> Result<PlyCloud> {
    let mut fields: Vec<Field> = Vec::new();
    let (mut sizes, mut types, mut counts) = (Vec::new(), Vec::new(), Vec::new());
    let (mut width, mut height, mut points) = (None::<usize>, 1usize, None::<usize>);
    let mut at = 0;
    let data = loop {
        let Some(nl) = bytes[at..].iter().position(|&c| c == b'\n') else {
            return Err(input(
                file,
                "not a PCD file, or its header has no DATA line",
            ));
        };
        let line = String::from_utf8_lossy(&bytes[at..at + nl])
            .trim()
            .to_string();
        at += nl + 1;
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut words = line.split_whitespace();
        let key = words.next().unwrap_or("").to_ascii_uppercase();
        let rest: Vec<&str> = words.collect();
        let num = |w: &str| -> Result<usize> {
            w.parse().map_err(|_| {
                input(
                    file,
                    format!("bad number '{w}' in the header line '{line}'"),
                )
            })
        };
        match key.as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => {
                fields = rest
                    .iter()
                    .map(|n| Field {
                        name: n.to_ascii_lowercase(),
                        size: 4,
                        kind: b'F',
                        count: 1,
                    })
                    .collect()
            }
            "SIZE" => sizes = rest.iter().map(|w| num(w)).collect::<Result<_>>()?,
            "TYPE" => {
                types = rest
                    .iter()
                    .map(|w| {
                        w.as_bytes()
                            .first()
                            .copied()
                            .unwrap_or(0)
                            .to_ascii_uppercase()
                    })
                    .collect()
            }
            "COUNT" => counts = rest.iter().map(|w| num(w)).collect::<Result<_>>()?,
            "WIDTH" => width = Some(num(rest.first().unwrap_or(&""))?),
            "HEIGHT" => height = num(rest.first().unwrap_or(&""))?,
            "POINTS" => points = Some(num(rest.first().unwrap_or(&""))?),
            "DATA" => {
                break match rest.first().map(|s| s.to_ascii_lowercase()).as_deref() {
                    Some("ascii") => Data::Ascii,
                    Some("binary") => Data::Binary,
                    Some("binary_compressed") => Data::Compressed,
                    other => {
                        return Err(input(
                            file,
                            format!(
                            "DATA {} is not a PCD data format (ascii, binary, binary_compressed)",
                            other.unwrap_or("")
                        ),
                        ))
                    }
                };
            }
            _ => {
                return Err(input(
                    file,
                    format!("not a PCD file: unknown header line '{line}'"),
                ))
            }
        }
    };
    if fields.is_empty() {
        return Err(input(file, "the PCD header has no FIELDS line"));
    }
    let nf = fields.len();
    for (list, what) in [
        (sizes.len(), "SIZE"),
        (types.len(), "TYPE"),
        (counts.len(), "COUNT"),
    ] {
        if list != 0 && list != nf {
            return Err(input(
                file,
                format!("the header's {what} line has {list} entries for {nf} fields"),
            ));
        }
    }
    for (i, f) in fields.iter_mut().enumerate() {
        f.size = sizes.get(i).copied().unwrap_or(4);
        f.kind = types.get(i).copied().unwrap_or(b'F');
        f.count = counts.get(i).copied().unwrap_or(1);
        let ok = match f.kind {
            b'F' => matches!(f.size, 4 | 8),
            b'I' | b'U' => matches!(f.size, 1 | 2 | 4 | 8),
            _ => false,
        };
        if !ok {
            return Err(input(
                file,
                format!(
                    "field '{}' has an unknown type {}{}",
                    f.name, f.kind as char, f.size
                ),
            ));
        }
    }
    let n = match (points, width) {
        (Some(p), _) => p,
        (None, Some(w)) => w
            .checked_mul(height)
            .ok_or_else(|| input(file, "WIDTH × HEIGHT is too large"))?,
        (None, None) => return Err(input(file, "the PCD header gives neither POINTS nor WIDTH")),
    };
    let find = |names: &[&str]| fields.iter().position(|f| names.contains(&f.name.as_str()));
    let (Some(ix), Some(iy), Some(iz)) = (find(&["x"]), find(&["y"]), find(&["z"])) else {
        let names: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
        return Err(input(
            file,
            format!("the PCD has no x y z fields (it has {})", names.join(" ")),
        ));
    };
    let il = find(&["label", "part"]).filter(|&i| fields[i].kind != b'F');
    // Offset of each field's first value inside a record (counts included).
    let mut offsets = Vec::with_capacity(nf);
    let mut record = 0usize;
    for f in &fields {
        if f.count == 0 {
            return Err(input(file, format!("field '{}' has COUNT 0", f.name)));
        }
        offsets.push(record);
        record = f
            .size
            .checked_mul(f.count)
            .and_then(|b| b.checked_add(record))
            .ok_or_else(|| input(file, format!("field '{}' has too large a COUNT", f.name)))?;
    }
    let body = &bytes[at..];
    // The most points the body can hold (an ascii point takes at least 2 bytes, LZF
    // unpacks at most 88-fold), checked before anything is allocated for them.
    let room = match data {
        Data::Ascii => body.len() / 2 + 1,
        Data::Binary => body.len() / record.max(1),
        Data::Compressed => body.len().saturating_mul(88) / record.max(1),
    };
    if n > room {
        return Err(input(
            file,
            format!(
                "truncated: the header announces {n} points, the body ({} bytes) cannot hold them",
                body.len()
            ),
        ));
    }
    let mut xyz = vec![[0f64; 3]; n];
    let mut labels = il.map(|_| vec![0f64; n]);
    match data {
        Data::Ascii => {
            let text = String::from_utf8_lossy(body);
            let mut lines = text.lines().filter(|l| !l.trim().is_empty());
            let words_per_point: usize = fields.iter().map(|f| f.count).sum();
            let word_index = |i: usize| fields[..i].iter().map(|f| f.count).sum::<usize>();
            let (wx, wy, wz) = (word_index(ix), word_index(iy), word_index(iz));
            let wl = il.map(word_index);
            for (p, out) in xyz.iter_mut().enumerate() {
                let line = lines.next().ok_or_else(|| {
                    input(
                        file,
                        format!("truncated: the header announces {n} points, the body has {p}"),
                    )
                })?;
                let words: Vec<&str> = line.split_whitespace().collect();
                if words.len() < words_per_point {
                    return Err(input(
                        file,
                        format!(
                            "point {p} has {} values, the fields need {words_per_point}",
                            words.len()
                        ),
                    ));
                }
                let val = |w: usize| -> Result<f64> {
                    let s = words[w];
                    s.parse::<f64>()
                        .or_else(|_| match s.to_ascii_lowercase().as_str() {
                            "nan" | "-nan" => Ok(f64::NAN),
                            _ => Err(input(file, format!("point {p}: '{s}' is not a number"))),
                        })
                };
                *out = [val(wx)?, val(wy)?, val(wz)?];
                if let (Some(l), Some(w)) = (labels.as_mut(), wl) {
                    l[p] = val(w)?;
                }
            }
        }
        Data::Binary => {
            let need = n
                .checked_mul(record)
                .ok_or_else(|| input(file, "too many points"))?;
            if body.len() < need {
                return Err(input(file, format!("truncated: {n} points of {record} bytes need {need} bytes, the body has {}", body.len())));
            }
            for (p, out) in xyz.iter_mut().enumerate() {
                let r = &body[p * record..];
                *out = [ix, iy, iz].map(|i| value(&fields[i], &r[offsets[i]..]));
                if let (Some(l), Some(i)) = (labels.as_mut(), il) {
                    l[p] = value(&fields[i], &r[offsets[i]..]);
                }
            }
        }
        Data::Compressed => {
            let word = |k: usize| {
                body.get(k..k + 4)
                    .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]) as usize)
            };
            let (Some(packed), Some(size)) = (word(0), word(4)) else {
                return Err(input(file, "truncated: the compressed body has no sizes"));
            };
            let need = n
                .checked_mul(record)
                .ok_or_else(|| input(file, "too many points"))?;
            if size != need {
                return Err(input(file, format!("the compressed body unpacks to {size} bytes, {n} points of {record} bytes need {need}")));
            }
            let src = body
                .get(8..8 + packed)
                .ok_or_else(|| input(file, "truncated compressed body"))?;
            let raw = lzf_decompress(src, size)
                .ok_or_else(|| input(file, "the compressed body is damaged (LZF)"))?;
            // Field by field: every point's values of field 0, then of field 1, …
            let mut start = 0;
            let mut field_start = Vec::with_capacity(nf);
            for f in &fields {
                field_start.push(start);
                start += f.size * f.count * n;
            }
            let at_point =
                |i: usize, p: usize| &raw[field_start[i] + p * fields[i].size * fields[i].count..];
            for (p, out) in xyz.iter_mut().enumerate() {
                *out = [ix, iy, iz].map(|i| value(&fields[i], at_point(i, p)));
                if let (Some(l), Some(i)) = (labels.as_mut(), il) {
                    l[p] = value(&fields[i], at_point(i, p));
                }
            }
        }
    }
    let mut cloud = PlyCloud {
        points: Vec::with_capacity(n),
        labels: labels.as_ref().map(|_| Vec::with_capacity(n)),
        faces: None,
    };
    for (p, c) in xyz.iter().enumerate() {
        if c.iter().any(|v| v.is_nan()) {
            continue;
        }
        if c.iter().any(|v| v.is_infinite()) {
            return Err(input(file, format!("infinite coordinate at point {p}")));
        }
        cloud
            .points
            .push(Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32));
        if let (Some(out), Some(l)) = (cloud.labels.as_mut(), labels.as_ref()) {
            let v = l[p];
            out.push(part_label(v).ok_or_else(|| {
                input(
                    file,
                    format!("point {p}: part label {v} is not a non-negative integer"),
                )
            })?);
        }
    }
    Ok(cloud)
}

/// The first value of field `f` at the start of `b` (little-endian, as PCL writes).
fn value(f: &Field, b: &[u8]) -> f64 {
    let mut w = [0u8; 8];
    w[..f.size].copy_from_slice(&b[..f.size]);
    match (f.kind, f.size) {
        (b'F', 4) => f32::from_le_bytes([w[0], w[1], w[2], w[3]]) as f64,
        (b'F', _) => f64::from_le_bytes(w),
        (b'I', 1) => w[0] as i8 as f64,
        (b'I', 2) => i16::from_le_bytes([w[0], w[1]]) as f64,
        (b'I', 4) => i32::from_le_bytes([w[0], w[1], w[2], w[3]]) as f64,
        (b'I', _) => i64::from_le_bytes(w) as f64,
        _ => u64::from_le_bytes(w) as f64,
    }
}

/// LZF decompression (liblzf's format, which PCL's `binary_compressed` uses); `None`
/// when the data is damaged or does not unpack to exactly `size` bytes.
fn lzf_decompress(src: &[u8], size: usize) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(size);
    let mut i = 0;
    while i < src.len() {
        let ctrl = src[i] as usize;
        i += 1;
        if ctrl < 32 {
            // A literal run of ctrl + 1 bytes.
            let run = src.get(i..i + ctrl + 1)?;
            out.extend_from_slice(run);
            i += ctrl + 1;
        } else {
            // A back reference: length (3 bits, extended by a byte at 7), offset 13 bits.
            let mut len = ctrl >> 5;
            if len == 7 {
                len += *src.get(i)? as usize;
                i += 1;
            }
            let back = ((ctrl & 0x1f) << 8) + *src.get(i)? as usize + 1;
            i += 1;
            let from = out.len().checked_sub(back)?;
            for k in 0..len + 2 {
                let b = out[from + k];
                out.push(b);
            }
        }
        if out.len() > size {
            return None;
        }
    }
    (out.len() == size).then_some(out)
}

/// LZF compression (greedy, 3-byte hash): the inverse of [`lzf_decompress`], for tests
/// and for users' tools writing `binary_compressed` PCDs.
pub fn lzf_compress(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut lit: Vec<u8> = Vec::new();
    let mut table = vec![usize::MAX; 1 << 14];
    let flush = |out: &mut Vec<u8>, lit: &mut Vec<u8>| {
        for chunk in lit.chunks(32) {
            out.push((chunk.len() - 1) as u8);
            out.extend_from_slice(chunk);
        }
        lit.clear();
    };
    let mut i = 0;
    while i < data.len() {
        if i + 2 < data.len() {
            let h = ((data[i] as usize) << 8 ^ (data[i + 1] as usize) << 4 ^ data[i + 2] as usize)
                & ((1 << 14) - 1);
            let cand = table[h];
            table[h] = i;
            if cand != usize::MAX && i - cand <= 8192 && data[cand..cand + 3] == data[i..i + 3] {
                let mut len = 3;
                while i + len < data.len() && len < 264 && data[cand + len] == data[i + len] {
                    len += 1;
                }
                flush(&mut out, &mut lit);
                let back = i - cand - 1;
                let l = len - 2;
                if l < 7 {
                    out.push(((l << 5) | (back >> 8)) as u8);
                } else {
                    out.push(((7 << 5) | (back >> 8)) as u8);
                    out.push((l - 7) as u8);
                }
                out.push((back & 0xff) as u8);
                i += len;
                continue;
            }
        }
        lit.push(data[i]);
        i += 1;
    }
    flush(&mut out, &mut lit);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z label\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\n";

    fn expected() -> PlyCloud {
        PlyCloud {
            points: vec![Vec3::new(0., 1., 2.), Vec3::new(3., 4., 5.)],
            labels: Some(vec![7, 8]),
            faces: None,
        }
    }

    #[test]
    fn ascii_binary_and_compressed_agree() {
        let ascii = format!("{HEAD}DATA ascii\n0 1 2 7\nnan nan nan 0\n3 4 5 8\n");
        assert_eq!(read_pcd(ascii.as_bytes(), "a.pcd").unwrap(), expected());
        let rows: [([f32; 3], u32); 3] = [([0., 1., 2.], 7), ([f32::NAN; 3], 0), ([3., 4., 5.], 8)];
        let mut bin = format!("{HEAD}DATA binary\n").into_bytes();
        for (p, l) in rows {
            p.iter()
                .for_each(|v| bin.extend_from_slice(&v.to_le_bytes()));
            bin.extend_from_slice(&l.to_le_bytes());
        }
        assert_eq!(read_pcd(&bin, "b.pcd").unwrap(), expected());
        // Field by field, LZF-packed.
        let mut soa = Vec::new();
        for f in 0..4 {
            for (p, l) in rows {
                let v = if f < 3 {
                    p[f].to_le_bytes()
                } else {
                    l.to_le_bytes()
                };
                soa.extend_from_slice(&v);
            }
        }
        let packed = lzf_compress(&soa);
        let mut comp = format!("{HEAD}DATA binary_compressed\n").into_bytes();
        comp.extend_from_slice(&(packed.len() as u32).to_le_bytes());
        comp.extend_from_slice(&(soa.len() as u32).to_le_bytes());
        comp.extend_from_slice(&packed);
        assert_eq!(read_pcd(&comp, "c.pcd").unwrap(), expected());
    }

    #[test]
    fn lzf_round_trips() {
        let data: Vec<u8> = (0..5000u32)
            .flat_map(|i| ((i / 7) as f32).to_le_bytes())
            .collect();
        let packed = lzf_compress(&data);
        assert!(packed.len() < data.len() / 2);
        assert_eq!(lzf_decompress(&packed, data.len()).unwrap(), data);
        assert_eq!(lzf_decompress(&packed, data.len() + 1), None);
        assert_eq!(lzf_decompress(&[0x20, 0x05], 4), None); // a reference before the start
    }

    #[test]
    fn bad_files_are_named() {
        let e = |b: &str| read_pcd(b.as_bytes(), "p.pcd").unwrap_err().to_string();
        assert!(e("hello\n").contains("not a PCD file"));
        assert!(e("FIELDS a b c\nPOINTS 1\nDATA ascii\n1 2 3\n").contains("no x y z"));
        assert!(e("FIELDS x y z\nPOINTS 2\nDATA ascii\n1 2 3\n").contains("truncated"));
        assert!(e("FIELDS x y z\nPOINTS 1\nDATA ascii\n1 2 inf\n").contains("infinite"));
        assert!(e("FIELDS x y z\nPOINTS 1\nDATA binary\n123").contains("truncated"));
        assert!(
            e("FIELDS x y z\nSIZE 4 4\nPOINTS 1\nDATA ascii\n1 2 3\n").contains("SIZE line has 2")
        );
        assert!(e("FIELDS x y z\nPOINTS 1\nDATA lzma\n").contains("not a PCD data format"));
    }
}
