//! NumPy archives (`.npz`, what `np.savez` and `np.savez_compressed` write) as
//! sequences: a ZIP of `.npy` arrays.
//!
//! Which arrays are points: an array named `points` (or `xyz`) alone when there is
//! one; otherwise every float array of shape `(N, ≥3)` or `(T, N, ≥3)` in natural
//! name order (`arr_0`, `arr_1`, … from `np.savez(f, *frames)`), except ones named
//! as normals or colours. An integer array named `labels`, `label`, `part` or
//! `parts` whose shape matches the points (`(N,)` or `(T, N)`) gives the ground-truth
//! part ids. Other arrays are skipped.
//!
//! The ZIP reader takes what NumPy writes: stored or deflated entries, ZIP64 fields
//! (NumPy forces them), no encryption. It is this short because that is all it needs;
//! the `zip` crate would bring a random-number backend and half a dozen crates into
//! the page for it.

use glam::Vec3;

use super::npy::{frames_of, read_array, read_labels, Array};
use super::sequence::natural_cmp;
use crate::error::{Error, Result};

/// Signature at the start of every ZIP (a local file header).
pub const MAGIC: &[u8] = b"PK\x03\x04";

/// An inflated entry may be at most this large (a corrupt size cannot exhaust memory).
const MAX_ENTRY_BYTES: usize = 1 << 31;

/// Frames (and their labels when the archive has them) of a `.npz` archive.
#[derive(Debug, Clone, PartialEq)]
pub struct NpzFrames {
    pub frames: Vec<Vec<Vec3>>,
    pub labels: Option<Vec<Vec<u32>>>,
}

fn input(file: &str, problem: impl Into<String>) -> Error {
    Error::input(file, problem)
}

/// Reads a `.npz` archive's point frames (see the module doc).
pub fn read_npz(bytes: &[u8], file: &str) -> Result<NpzFrames> {
    let mut arrays: Vec<(String, Array<'static>)> = Vec::new();
    for entry in central_directory(bytes, file)? {
        let name = entry.name.trim_end_matches(".npy").to_string();
        let shown = format!("{file}/{}", entry.name);
        let data = entry_data(bytes, &entry, file)?;
        arrays.push((name, read_array(data, &shown)?));
    }
    arrays.sort_by(|a, b| natural_cmp(&a.0, &b.0));
    let named = |names: &[&str]| {
        arrays
            .iter()
            .position(|(n, _)| names.iter().any(|m| n.eq_ignore_ascii_case(m)))
    };
    let point_ids: Vec<usize> = match named(&["points", "xyz"]) {
        Some(i) => vec![i],
        None => {
            const SKIPPED: [&str; 8] = [
                "normals", "normal", "colors", "colours", "color", "colour", "rgb", "features",
            ];
            (0..arrays.len())
                .filter(|&i| {
                    let (n, a) = &arrays[i];
                    !a.integer()
                        && matches!(a.shape.len(), 2 | 3)
                        && a.shape[a.shape.len() - 1] >= 3
                        && !SKIPPED.iter().any(|s| n.eq_ignore_ascii_case(s))
                })
                .collect()
        }
    };
    if point_ids.is_empty() {
        let found: Vec<String> = arrays
            .iter()
            .map(|(n, a)| format!("{n} {:?}", a.shape))
            .collect();
        return Err(input(
            file,
            format!(
                "no array of points in the archive (found: {}); name it 'points', of shape (N, 3) or (T, N, 3)",
                if found.is_empty() { "nothing".to_string() } else { found.join(", ") }
            ),
        ));
    }
    let mut frames = Vec::new();
    for &i in &point_ids {
        let (n, a) = &arrays[i];
        frames.extend(frames_of(a, &format!("{file}/{n}.npy"))?);
    }
    // Labels go with a single points array (their shapes must match it).
    let labels = match (named(&["labels", "label", "part", "parts"]), &point_ids[..]) {
        (Some(l), &[p]) => read_labels(
            &arrays[l].1,
            &arrays[p].1,
            &format!("{file}/{}.npy", arrays[l].0),
        )?,
        _ => None,
    };
    Ok(NpzFrames { frames, labels })
}

/// One central-directory record, the fields this reader needs.
#[derive(Debug, Clone)]
struct Entry {
    name: String,
    method: u16,
    flags: u16,
    crc: u32,
    compressed: u64,
    size: u64,
    local_offset: u64,
}

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(
        b.get(at..at.checked_add(2)?)?.try_into().ok()?,
    ))
}
fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(
        b.get(at..at.checked_add(4)?)?.try_into().ok()?,
    ))
}
fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(
        b.get(at..at.checked_add(8)?)?.try_into().ok()?,
    ))
}

/// The entries of the archive's central directory, ZIP64 included.
fn central_directory(b: &[u8], file: &str) -> Result<Vec<Entry>> {
    let corrupt = |what: &str| input(file, format!("not a readable .npz (ZIP) archive: {what}"));
    // The end-of-central-directory record: 22 bytes plus a comment of at most 65535.
    let lo = b.len().saturating_sub(22 + 65535);
    let eocd = (lo..b.len().saturating_sub(21))
        .rev()
        .find(|&i| b[i..i + 4] == [0x50, 0x4b, 0x05, 0x06])
        .ok_or_else(|| corrupt("no end of central directory (truncated?)"))?;
    let mut count = u16_at(b, eocd + 10).unwrap_or(0) as u64;
    let mut cd_size = u32_at(b, eocd + 12).unwrap_or(0) as u64;
    let mut cd_offset = u32_at(b, eocd + 16).unwrap_or(0) as u64;
    if count == 0xffff || cd_size == 0xffff_ffff || cd_offset == 0xffff_ffff {
        // ZIP64: a locator just before the record points at the ZIP64 record.
        let loc = eocd
            .checked_sub(20)
            .filter(|&l| u32_at(b, l) == Some(0x0706_4b50));
        let rec = loc
            .and_then(|l| u64_at(b, l + 8))
            .and_then(|r| usize::try_from(r).ok())
            .filter(|&r| u32_at(b, r) == Some(0x0606_4b50))
            .ok_or_else(|| corrupt("a ZIP64 archive without its ZIP64 directory record"))?;
        count = u64_at(b, rec + 32).ok_or_else(|| corrupt("truncated ZIP64 record"))?;
        cd_size = u64_at(b, rec + 40).ok_or_else(|| corrupt("truncated ZIP64 record"))?;
        cd_offset = u64_at(b, rec + 48).ok_or_else(|| corrupt("truncated ZIP64 record"))?;
    }
    let start = usize::try_from(cd_offset).map_err(|_| corrupt("bad directory offset"))?;
    let end = start
        .checked_add(usize::try_from(cd_size).map_err(|_| corrupt("bad directory size"))?)
        .filter(|&e| e <= b.len())
        .ok_or_else(|| corrupt("the directory lies beyond the end of the file (truncated?)"))?;
    let mut entries = Vec::new();
    let mut at = start;
    while at < end && entries.len() < count as usize {
        if u32_at(b, at) != Some(0x0201_4b50) {
            return Err(corrupt("a damaged directory record"));
        }
        let field =
            |off: usize| u16_at(b, at + off).ok_or_else(|| corrupt("a truncated directory record"));
        let (flags, method) = (field(8)?, field(10)?);
        let (n, e, c) = (
            field(28)? as usize,
            field(30)? as usize,
            field(32)? as usize,
        );
        let crc = u32_at(b, at + 16).unwrap_or(0);
        let mut compressed = u32_at(b, at + 20).unwrap_or(0) as u64;
        let mut size = u32_at(b, at + 24).unwrap_or(0) as u64;
        let mut local_offset = u32_at(b, at + 42).unwrap_or(0) as u64;
        let name_bytes = b
            .get(at + 46..at + 46 + n)
            .ok_or_else(|| corrupt("a truncated directory record"))?;
        let name = String::from_utf8_lossy(name_bytes).into_owned();
        let extra = b
            .get(at + 46 + n..at + 46 + n + e)
            .ok_or_else(|| corrupt("a truncated directory record"))?;
        // The ZIP64 extra field holds, in order, the fields saturated above.
        let mut x = 0;
        while x + 4 <= extra.len() {
            let id = u16_at(extra, x).unwrap_or(0);
            let len = u16_at(extra, x + 2).unwrap_or(0) as usize;
            if id == 1 {
                let mut p = x + 4;
                for v in [&mut size, &mut compressed, &mut local_offset] {
                    if *v == 0xffff_ffff {
                        *v = u64_at(extra, p).ok_or_else(|| corrupt("a truncated ZIP64 field"))?;
                        p += 8;
                    }
                }
            }
            x += 4 + len;
        }
        at += 46 + n + e + c;
        if name.ends_with('/') {
            continue;
        }
        entries.push(Entry {
            name,
            method,
            flags,
            crc,
            compressed,
            size,
            local_offset,
        });
    }
    Ok(entries)
}

/// An entry's bytes, inflated when deflated.
fn entry_data(b: &[u8], e: &Entry, file: &str) -> Result<Vec<u8>> {
    let bad = |what: &str| input(file, format!("{}: {what}", e.name));
    if e.flags & 1 != 0 {
        return Err(bad("encrypted entries cannot be read"));
    }
    let local = usize::try_from(e.local_offset).map_err(|_| bad("bad offset"))?;
    if u32_at(b, local) != Some(0x0403_4b50) {
        return Err(bad("its local header is missing (a damaged archive)"));
    }
    let n = u16_at(b, local + 26).unwrap_or(0) as usize;
    let x = u16_at(b, local + 28).unwrap_or(0) as usize;
    let start = local + 30 + n + x;
    let len = usize::try_from(e.compressed).map_err(|_| bad("too large"))?;
    let data = start
        .checked_add(len)
        .and_then(|end| b.get(start..end))
        .ok_or_else(|| bad("truncated"))?;
    let size = usize::try_from(e.size)
        .ok()
        .filter(|&s| s <= MAX_ENTRY_BYTES)
        .ok_or_else(|| bad("too large"))?;
    let out = match e.method {
        0 => data.to_vec(),
        8 => miniz_oxide::inflate::decompress_to_vec_with_limit(data, size)
            .map_err(|err| bad(&format!("its compressed data is damaged ({err})")))?,
        m => {
            return Err(bad(&format!(
                "compression method {m} is not supported (stored and deflate are)"
            )))
        }
    };
    if out.len() != size {
        return Err(bad(
            "its size does not match the directory (a damaged archive)",
        ));
    }
    if crc32(&out) != e.crc {
        return Err(bad("its checksum does not match (a damaged archive)"));
    }
    Ok(out)
}

/// A ZIP of `(name, bytes)` entries, stored (`deflate = false`) or deflated, with the
/// ZIP64 local fields NumPy writes: an `.npz` as `np.savez` makes it, for tests.
pub fn write_npz(entries: &[(&str, Vec<u8>)], deflate: bool) -> Vec<u8> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    for (name, data) in entries {
        let name = format!("{name}.npy");
        let packed = if deflate {
            miniz_oxide::deflate::compress_to_vec(data, 6)
        } else {
            data.clone()
        };
        let crc = crc32(data);
        let offset = out.len() as u32;
        let method: u16 = if deflate { 8 } else { 0 };
        // Local header: sizes saturated, the real ones in a ZIP64 extra field.
        out.extend_from_slice(&0x0403_4b50u32.to_le_bytes());
        out.extend_from_slice(&[45, 0, 0, 0]);
        out.extend_from_slice(&method.to_le_bytes());
        out.extend_from_slice(&[0, 0, 0x21, 0]);
        out.extend_from_slice(&crc.to_le_bytes());
        out.extend_from_slice(&u32::MAX.to_le_bytes());
        out.extend_from_slice(&u32::MAX.to_le_bytes());
        out.extend_from_slice(&(name.len() as u16).to_le_bytes());
        out.extend_from_slice(&20u16.to_le_bytes());
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(&1u16.to_le_bytes());
        out.extend_from_slice(&16u16.to_le_bytes());
        out.extend_from_slice(&(data.len() as u64).to_le_bytes());
        out.extend_from_slice(&(packed.len() as u64).to_le_bytes());
        out.extend_from_slice(&packed);
        central.extend_from_slice(&0x0201_4b50u32.to_le_bytes());
        central.extend_from_slice(&[45, 3, 45, 0, 0, 0]);
        central.extend_from_slice(&method.to_le_bytes());
        central.extend_from_slice(&[0, 0, 0x21, 0]);
        central.extend_from_slice(&crc.to_le_bytes());
        central.extend_from_slice(&(packed.len() as u32).to_le_bytes());
        central.extend_from_slice(&(data.len() as u32).to_le_bytes());
        central.extend_from_slice(&(name.len() as u16).to_le_bytes());
        central.extend_from_slice(&[0; 12]);
        central.extend_from_slice(&offset.to_le_bytes());
        central.extend_from_slice(name.as_bytes());
    }
    let cd_offset = out.len() as u32;
    out.extend_from_slice(&central);
    out.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    out.extend_from_slice(&[0; 4]);
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    out.extend_from_slice(&(central.len() as u32).to_le_bytes());
    out.extend_from_slice(&cd_offset.to_le_bytes());
    out.extend_from_slice(&[0, 0]);
    out
}

/// CRC-32 (IEEE) lookup table, one entry per byte value.
const CRC_TABLE: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xedb8_8320
            } else {
                c >> 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

/// CRC-32 (IEEE), the checksum every ZIP entry carries.
fn crc32(data: &[u8]) -> u32 {
    !data.iter().fold(!0u32, |c, &b| {
        CRC_TABLE[((c ^ b as u32) & 0xff) as usize] ^ (c >> 8)
    })
}

#[cfg(test)]
mod tests {
    use super::super::npy::write_npy;
    use super::*;

    fn pts(v: &[f32]) -> Vec<u8> {
        write_npy(
            "<f4",
            &[v.len() / 3, 3],
            &v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<_>>(),
        )
    }

    #[test]
    fn savez_frames_in_natural_order_stored_and_deflated() {
        for deflate in [false, true] {
            let z = write_npz(
                &[
                    ("arr_10", pts(&[10., 0., 0.])),
                    ("arr_2", pts(&[2., 0., 0.])),
                    ("normals", pts(&[0., 0., 1.])),
                ],
                deflate,
            );
            let r = read_npz(&z, "s.npz").unwrap();
            assert_eq!(
                r.frames,
                vec![vec![Vec3::new(2., 0., 0.)], vec![Vec3::new(10., 0., 0.)]]
            );
            assert_eq!(r.labels, None);
        }
    }

    #[test]
    fn a_points_array_with_labels() {
        let p = write_npy(
            "<f8",
            &[2, 2, 3],
            &[0., 0., 0., 1., 1., 1., 2., 2., 2., 3., 3., 3.]
                .iter()
                .flat_map(|x: &f64| x.to_le_bytes())
                .collect::<Vec<_>>(),
        );
        let l = write_npy(
            "<i8",
            &[2, 2],
            &[0i64, 1, 1, 0]
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect::<Vec<_>>(),
        );
        let z = write_npz(
            &[("labels", l), ("points", p), ("other", pts(&[9., 9., 9.]))],
            true,
        );
        let r = read_npz(&z, "s.npz").unwrap();
        assert_eq!(r.frames.len(), 2);
        assert_eq!(r.frames[1][1], Vec3::new(3., 3., 3.));
        assert_eq!(r.labels, Some(vec![vec![0, 1], vec![1, 0]]));
    }

    #[test]
    fn damaged_archives_are_named() {
        let z = write_npz(&[("arr_0", pts(&[1., 2., 3.]))], true);
        let e = read_npz(&z[..z.len() - 30], "d.npz")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("d.npz: not a readable .npz"), "{e}");
        let mut bad = z.clone();
        bad[70] ^= 0xff; // inside the deflated data
        let e = read_npz(&bad, "d.npz").unwrap_err().to_string();
        assert!(e.starts_with("d.npz: arr_0.npy: its"), "{e}");
        // Stored data with a flipped byte: only the checksum can tell.
        let mut bad = write_npz(&[("arr_0", pts(&[1., 2., 3.]))], false);
        let last_data = bad.len() - 22 - 46 - 9 - 1;
        bad[last_data] ^= 0x01;
        let e = read_npz(&bad, "d.npz").unwrap_err().to_string();
        assert!(e.contains("checksum"), "{e}");
        assert_eq!(crc32(b"123456789"), 0xcbf4_3926);
        let z = write_npz(&[("times", write_npy("<f4", &[2], &[0; 8]))], false);
        let e = read_npz(&z, "t.npz").unwrap_err().to_string();
        assert!(
            e.contains("no array of points") && e.contains("times [2]"),
            "{e}"
        );
    }
}
