//! Which reader a point-cloud file goes to, and how a file of several frames names
//! them.
//!
//! A file's format is its extension's ([`FRAME_EXTENSIONS`]); a file with another
//! extension (or none) is recognised by its first bytes (PLY, NumPy, ZIP, PCD) and
//! otherwise read as a PLY, whose errors name what the file looks like instead. A
//! PLY, PCD, OBJ or text table is one frame; a `.npy` or `.npz` may hold several,
//! named `walk.npy[0]`, `walk.npy[1]`, … in time order.

use std::path::Path;

use super::npy::{read_npy, MAGIC as NPY_MAGIC};
use super::npz::{read_npz, MAGIC as ZIP_MAGIC};
use super::obj::read_obj;
use super::pcd::{looks_like_pcd, read_pcd};
use super::ply::{read_ply, PlyCloud};
use super::text_cloud::read_text_cloud;
use crate::error::Result;

/// The extensions read as frames, in the order a folder's formats are preferred: a
/// folder's frames are its files of the first of these it has (so a `notes.txt`
/// beside PLY frames is not a frame). The page's `www/js/files.js` holds the same
/// list: it sorts a drop before a worker has the wasm.
pub const FRAME_EXTENSIONS: [&str; 9] = [
    "ply", "pcd", "npy", "npz", "obj", "xyz", "pts", "csv", "txt",
];

/// The file formats frames are read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CloudFormat {
    Ply,
    Pcd,
    Npy,
    Npz,
    Obj,
    /// `.xyz`, `.pts`, `.csv`, `.txt`: one point a line.
    Text,
}

impl CloudFormat {
    /// The format of an extension (any case), when it is one of [`FRAME_EXTENSIONS`].
    pub fn of_extension(ext: &str) -> Option<CloudFormat> {
        Some(match ext.to_ascii_lowercase().as_str() {
            "ply" => CloudFormat::Ply,
            "pcd" => CloudFormat::Pcd,
            "npy" => CloudFormat::Npy,
            "npz" => CloudFormat::Npz,
            "obj" => CloudFormat::Obj,
            "xyz" | "pts" | "csv" | "txt" => CloudFormat::Text,
            _ => return None,
        })
    }

    /// The format of a file named `name` holding `bytes`.
    pub fn of_file(name: &str, bytes: &[u8]) -> CloudFormat {
        if let Some(f) = Path::new(name)
            .extension()
            .and_then(|e| e.to_str())
            .and_then(CloudFormat::of_extension)
        {
            return f;
        }
        if bytes.starts_with(NPY_MAGIC) {
            CloudFormat::Npy
        } else if bytes.starts_with(ZIP_MAGIC)
            && bytes.len() > 64
            && contains(&bytes[..bytes.len().min(4096)], b".npy")
        {
            CloudFormat::Npz
        } else if looks_like_pcd(bytes) {
            CloudFormat::Pcd
        } else {
            CloudFormat::Ply
        }
    }
}

fn contains(hay: &[u8], needle: &[u8]) -> bool {
    hay.windows(needle.len()).any(|w| w == needle)
}

/// The frames of one file (a PLY, PCD, OBJ or text table is one; a NumPy file may be
/// several), not yet sampled (a mesh keeps its faces) nor validated.
pub fn read_clouds(name: &str, bytes: &[u8]) -> Result<Vec<PlyCloud>> {
    let cloud = |points| PlyCloud {
        points,
        labels: None,
        faces: None,
    };
    Ok(match CloudFormat::of_file(name, bytes) {
        CloudFormat::Ply => vec![read_ply(bytes, name)?],
        CloudFormat::Pcd => vec![read_pcd(bytes, name)?],
        CloudFormat::Obj => vec![read_obj(bytes, name)?],
        CloudFormat::Text => vec![read_text_cloud(bytes, name)?],
        CloudFormat::Npy => read_npy(bytes, name)?.into_iter().map(cloud).collect(),
        CloudFormat::Npz => {
            let z = read_npz(bytes, name)?;
            let mut labels = z.labels.map(|l| l.into_iter());
            z.frames
                .into_iter()
                .map(|points| PlyCloud {
                    points,
                    labels: labels.as_mut().and_then(|l| l.next()),
                    faces: None,
                })
                .collect()
        }
    })
}

/// The name of frame `k` of the `count` a file named `file` holds.
pub fn frame_name(file: &str, k: usize, count: usize) -> String {
    if count == 1 {
        file.to_string()
    } else {
        format!("{file}[{k}]")
    }
}

/// A frame's name made a file stem for its outputs (`f1.ply` → `f1`, `walk.npy[3]` →
/// `walk_3`), as `--ply-out` and the page's segmented PLY export name them.
pub fn frame_stem(name: &str) -> String {
    let (base, index) = match name
        .strip_suffix(']')
        .and_then(|s| s.rsplit_once('['))
        .filter(|(_, i)| !i.is_empty() && i.bytes().all(|c| c.is_ascii_digit()))
    {
        Some((b, i)) => (b, Some(i)),
        None => (name, None),
    };
    let stem = Path::new(base)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "frame".to_string());
    match index {
        Some(i) => format!("{stem}_{i}"),
        None => stem,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_by_extension_then_by_content() {
        assert_eq!(CloudFormat::of_file("a.PCD", b""), CloudFormat::Pcd);
        assert_eq!(CloudFormat::of_file("a.csv", b""), CloudFormat::Text);
        assert_eq!(
            CloudFormat::of_file("a.bin", b"\x93NUMPY\x01\x00"),
            CloudFormat::Npy
        );
        assert_eq!(
            CloudFormat::of_file("frame", b"# .PCD v0.7\n"),
            CloudFormat::Pcd
        );
        assert_eq!(
            CloudFormat::of_file("frame", b"PK\x03\x04"),
            CloudFormat::Ply
        );
        assert_eq!(CloudFormat::of_file("frame", b"ply\n"), CloudFormat::Ply);
    }

    #[test]
    fn stems_of_frame_names() {
        assert_eq!(frame_stem("f1.ply"), "f1");
        assert_eq!(frame_stem("walk.npy[3]"), "walk_3");
        assert_eq!(frame_stem("a.b.pcd"), "a.b");
        assert_eq!(frame_stem("odd[x]"), "odd[x]");
        assert_eq!(frame_name("walk.npy", 3, 10), "walk.npy[3]");
        assert_eq!(frame_name("one.npy", 0, 1), "one.npy");
    }
}
