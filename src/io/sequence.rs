//! A sequence of point-cloud frames of one articulated object.
//!
//! Loading from a folder or a file list (natural filename order), from named byte
//! buffers (the browser), downsampling to the working size and validation live here.
//! File access only happens in the path-based functions; everything else works on
//! bytes and compiles (and runs) on wasm32.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use glam::Vec3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::geom::fps::farthest_point_sampling;
use crate::io::cloud_file::{frame_name, read_clouds, CloudFormat, FRAME_EXTENSIONS};
use crate::io::ply::{read_ply_from, sample_mesh, validate_points, PlyCloud};

/// One observed point cloud.
#[derive(Debug, Clone, Default)]
pub struct Frame {
    /// File name (or any label the user recognises), used in messages.
    pub name: String,
    pub points: Vec<Vec3>,
    /// Ground-truth part id per point (PLY `part`/`label` property), when present.
    pub labels: Option<Vec<u32>>,
}

/// K ≥ 2 frames in time order.
#[derive(Debug, Clone, Default)]
pub struct Sequence {
    pub frames: Vec<Frame>,
}

/// How frames larger than the working size are reduced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Downsample {
    /// Farthest-point sampling from a seeded random start: even coverage.
    #[default]
    Farthest,
    /// Seeded uniform random subset: follows the input density.
    Random,
}

/// How files become frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoadOptions {
    /// Points sampled on the surface of a PLY that is a mesh (has faces).
    pub mesh_samples: usize,
    /// Seed of the mesh sampling (mixed with the frame's index).
    pub seed: u64,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            mesh_samples: 4096,
            seed: 0,
        }
    }
}

/// A sequence reduced to the working size, with the way back to the input points.
#[derive(Debug, Clone, Default)]
pub struct Downsampled {
    /// Frames of at most the working size (frames already small enough are unchanged).
    pub sequence: Sequence,
    /// `kept[k]`: indices into input frame k of the working points, ascending.
    pub kept: Vec<Vec<usize>>,
    /// Point count of each input frame.
    pub original_sizes: Vec<usize>,
    pub working_size: usize,
    pub method: Downsample,
}

impl Downsampled {
    /// True when at least one frame lost points.
    pub fn any_downsampled(&self) -> bool {
        self.kept
            .iter()
            .zip(&self.original_sizes)
            .any(|(k, &n)| k.len() < n)
    }

    /// A sentence for the output ("say so"), or `None` when nothing was reduced.
    pub fn note(&self) -> Option<String> {
        let reduced: Vec<String> = self
            .sequence
            .frames
            .iter()
            .zip(&self.original_sizes)
            .filter(|(f, &n)| f.points.len() < n)
            .map(|(f, &n)| format!("{} {} → {}", f.name, n, f.points.len()))
            .collect();
        if reduced.is_empty() {
            return None;
        }
        let how = match self.method {
            Downsample::Farthest => "farthest-point sampling",
            Downsample::Random => "random sampling",
        };
        Some(format!(
            "{} of {} frames downsampled to the working size {} by {how}: {}",
            reduced.len(),
            self.original_sizes.len(),
            self.working_size,
            reduced.join(", ")
        ))
    }
}

/// Compares strings the way people order numbered files: runs of digits compare as
/// numbers (`f2` < `f10`), the rest character by character; ties fall back to plain
/// byte order so that the order is total.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (ab, bb) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < ab.len() && j < bb.len() {
        if ab[i].is_ascii_digit() && bb[j].is_ascii_digit() {
            let si = i;
            while i < ab.len() && ab[i].is_ascii_digit() {
                i += 1;
            }
            let sj = j;
            while j < bb.len() && bb[j].is_ascii_digit() {
                j += 1;
            }
            // Compare numerically without parsing (runs may exceed u64): strip leading
            // zeros, then longer is bigger, then lexicographic.
            let na = trim_zeros(&ab[si..i]);
            let nb = trim_zeros(&bb[sj..j]);
            let ord = na.len().cmp(&nb.len()).then_with(|| na.cmp(nb));
            if ord != Ordering::Equal {
                return ord;
            }
        } else {
            let ord = ab[i].cmp(&bb[j]);
            if ord != Ordering::Equal {
                return ord;
            }
            i += 1;
            j += 1;
        }
    }
    (ab.len() - i).cmp(&(bb.len() - j)).then_with(|| ab.cmp(bb))
}

fn trim_zeros(d: &[u8]) -> &[u8] {
    let k = d.iter().take_while(|&&c| c == b'0').count();
    &d[k..]
}

/// Seed for frame `k` derived from a job seed (splitmix64), so frames sample independently.
fn frame_seed(seed: u64, k: usize) -> u64 {
    let mut z = seed
        ^ (k as u64)
            .wrapping_add(1)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn display_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

fn sort_paths(paths: &mut [PathBuf]) {
    paths.sort_by(|a, b| {
        natural_cmp(&display_name(a), &display_name(b))
            .then_with(|| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()))
    });
}

impl Frame {
    /// Turns a parsed PLY into a frame: samples a mesh's surface, then checks that the
    /// cloud is usable (enough points, not degenerate). `file` names it in errors.
    pub fn from_cloud(
        name: &str,
        file: &str,
        cloud: PlyCloud,
        mesh_samples: usize,
        seed: u64,
    ) -> Result<Frame> {
        let (points, labels) = match &cloud.faces {
            Some(faces) if !faces.is_empty() => sample_mesh(
                &cloud.points,
                faces,
                cloud.labels.as_deref(),
                mesh_samples,
                seed,
                file,
            )?,
            _ => (cloud.points, cloud.labels),
        };
        validate_points(&points, file)?;
        Ok(Frame {
            name: name.to_string(),
            points,
            labels,
        })
    }

    /// Parses and validates one frame from bytes; a file of several frames (a NumPy
    /// stack) is an error here, see [`Frame::all_from_bytes`].
    pub fn from_bytes(name: &str, bytes: &[u8], mesh_samples: usize, seed: u64) -> Result<Frame> {
        let mut frames = Frame::all_from_bytes(name, bytes, mesh_samples, seed)?;
        if frames.len() != 1 {
            return Err(Error::input(
                name,
                format!("holds {} frames where one was expected", frames.len()),
            ));
        }
        Ok(frames.remove(0))
    }

    /// Parses and validates every frame a file holds (one for a PLY, PCD, OBJ or text
    /// table; a NumPy file may hold several, named `name[k]`), in time order. Frame k
    /// of the file samples a mesh with `seed` mixed with k.
    pub fn all_from_bytes(
        name: &str,
        bytes: &[u8],
        mesh_samples: usize,
        seed: u64,
    ) -> Result<Vec<Frame>> {
        Frame::all_from_clouds(name, name, read_clouds(name, bytes)?, mesh_samples, seed)
    }

    fn all_from_clouds(
        name: &str,
        file: &str,
        clouds: Vec<PlyCloud>,
        mesh_samples: usize,
        seed: u64,
    ) -> Result<Vec<Frame>> {
        let count = clouds.len();
        if count == 0 {
            return Err(Error::input(file, "holds no frames"));
        }
        clouds
            .into_iter()
            .enumerate()
            .map(|(k, cloud)| {
                let seed = if count == 1 {
                    seed
                } else {
                    frame_seed(seed, k)
                };
                let shown = frame_name(file, k, count);
                Frame::from_cloud(
                    &frame_name(name, k, count),
                    &shown,
                    cloud,
                    mesh_samples,
                    seed,
                )
            })
            .collect()
    }

    /// Reads and validates every frame of a file (a PLY is streamed; the others are
    /// read whole); errors name the path.
    pub fn all_from_path(path: &Path, mesh_samples: usize, seed: u64) -> Result<Vec<Frame>> {
        let shown = path.display().to_string();
        let name = display_name(path);
        let by_extension = path
            .extension()
            .and_then(|e| e.to_str())
            .and_then(CloudFormat::of_extension);
        if by_extension == Some(CloudFormat::Ply) {
            let f = std::fs::File::open(path).map_err(|e| Error::io(&shown, e))?;
            let cloud = read_ply_from(f, &shown)?;
            return Ok(vec![Frame::from_cloud(
                &name,
                &shown,
                cloud,
                mesh_samples,
                seed,
            )?]);
        }
        let bytes = std::fs::read(path).map_err(|e| Error::io(&shown, e))?;
        let clouds = read_clouds(&shown, &bytes)?;
        Frame::all_from_clouds(&name, &shown, clouds, mesh_samples, seed)
    }

    /// The working subset of this frame and the kept indices (ascending).
    pub fn downsample(
        &self,
        working_size: usize,
        method: Downsample,
        seed: u64,
    ) -> (Frame, Vec<usize>) {
        let kept = downsample_indices(&self.points, working_size, method, seed);
        if kept.len() == self.points.len() {
            return (self.clone(), kept);
        }
        let frame = Frame {
            name: self.name.clone(),
            points: kept.iter().map(|&i| self.points[i]).collect(),
            labels: self
                .labels
                .as_ref()
                .map(|l| kept.iter().map(|&i| l[i]).collect()),
        };
        (frame, kept)
    }
}

/// Indices (ascending) of at most `working_size` points of `points`, seeded.
pub fn downsample_indices(
    points: &[Vec3],
    working_size: usize,
    method: Downsample,
    seed: u64,
) -> Vec<usize> {
    let n = points.len();
    if n <= working_size {
        return (0..n).collect();
    }
    let mut rng = StdRng::seed_from_u64(seed);
    let mut kept = match method {
        Downsample::Farthest => {
            let start = rng.random_range(0..n);
            farthest_point_sampling(points, working_size, start)
        }
        Downsample::Random => rand::seq::index::sample(&mut rng, n, working_size).into_vec(),
    };
    kept.sort_unstable();
    kept
}

impl Sequence {
    /// A sequence from loaded frames (already in time order): needs at least 2.
    pub fn from_frames(frames: Vec<Frame>) -> Result<Sequence> {
        if frames.len() < 2 {
            let which = frames
                .first()
                .map(|f| format!(" ({})", f.name))
                .unwrap_or_default();
            return Err(Error::Sequence(format!(
                "a sequence needs at least 2 frames, got {}{which}",
                frames.len()
            )));
        }
        Ok(Sequence { frames })
    }

    /// Loads frame files in natural filename order (`f2.ply` before `f10.ply`; any
    /// format of [`FRAME_EXTENSIONS`], a NumPy file giving all its frames in turn),
    /// streaming PLY files; meshes are sampled with [`LoadOptions::default`].
    pub fn from_files(paths: &[PathBuf]) -> Result<Sequence> {
        Sequence::from_files_with(paths, LoadOptions::default())
    }

    /// [`Sequence::from_files`] with explicit options. Stops at the first bad file.
    pub fn from_files_with(paths: &[PathBuf], opts: LoadOptions) -> Result<Sequence> {
        let mut paths = paths.to_vec();
        sort_paths(&mut paths);
        let mut frames = Vec::new();
        for (k, p) in paths.iter().enumerate() {
            frames.extend(Frame::all_from_path(
                p,
                opts.mesh_samples,
                frame_seed(opts.seed, k),
            )?);
        }
        Sequence::from_frames(frames)
    }

    /// The frame files directly in `dir` (not `heldout/`), in natural order: the
    /// files of the first of [`FRAME_EXTENSIONS`] the folder has (PLY before the
    /// others), so one format makes the sequence and notes beside it are no frames.
    pub fn frame_files_in(dir: &Path) -> Result<Vec<PathBuf>> {
        let shown = dir.display().to_string();
        let entries = std::fs::read_dir(dir).map_err(|e| Error::io(&shown, e))?;
        let mut by_ext: Vec<Vec<PathBuf>> = vec![Vec::new(); FRAME_EXTENSIONS.len()];
        for entry in entries {
            let entry = entry.map_err(|e| Error::io(&shown, e))?;
            let path = entry.path();
            let rank = path.extension().and_then(|e| e.to_str()).and_then(|e| {
                FRAME_EXTENSIONS
                    .iter()
                    .position(|x| x.eq_ignore_ascii_case(e))
            });
            let hidden = path
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'));
            if let Some(r) = rank.filter(|_| !hidden && path.is_file()) {
                by_ext[r].push(path);
            }
        }
        let Some(mut paths) = by_ext.into_iter().find(|p| !p.is_empty()) else {
            return Err(Error::input(
                shown,
                format!(
                    "the folder contains no frame files (.{})",
                    FRAME_EXTENSIONS.join(", .")
                ),
            ));
        };
        sort_paths(&mut paths);
        Ok(paths)
    }

    /// Loads the frame files of a folder (see [`Sequence::frame_files_in`]).
    pub fn from_dir(dir: &Path) -> Result<Sequence> {
        Sequence::from_dir_with(dir, LoadOptions::default())
    }

    /// [`Sequence::from_dir`] with explicit options.
    pub fn from_dir_with(dir: &Path, opts: LoadOptions) -> Result<Sequence> {
        Sequence::from_files_with(&Sequence::frame_files_in(dir)?, opts)
    }

    /// Parses named buffers (the browser's dropped files) independently: each gets its
    /// own result so one bad file does not discard the others (a file of several
    /// frames gives one entry a frame, `walk.npy[0]`, …). Returned in natural name
    /// order; assemble the good ones with [`Sequence::from_loaded`].
    pub fn from_named_bytes(
        files: Vec<(String, Vec<u8>)>,
        opts: LoadOptions,
    ) -> Vec<(String, Result<Frame>)> {
        let mut files = files;
        files.sort_by(|a, b| natural_cmp(&a.0, &b.0));
        files
            .into_iter()
            .enumerate()
            .flat_map(|(k, (name, bytes))| {
                match Frame::all_from_bytes(
                    &name,
                    &bytes,
                    opts.mesh_samples,
                    frame_seed(opts.seed, k),
                ) {
                    Ok(frames) => frames
                        .into_iter()
                        .map(|f| (f.name.clone(), Ok(f)))
                        .collect(),
                    Err(e) => vec![(name, Err(e))],
                }
            })
            .collect()
    }

    /// The sequence of the files that loaded (errors are the caller's to show beside
    /// each file); still needs at least 2 good frames.
    pub fn from_loaded(results: Vec<(String, Result<Frame>)>) -> Result<Sequence> {
        Sequence::from_frames(results.into_iter().filter_map(|(_, r)| r.ok()).collect())
    }

    /// Reduces every frame larger than `working_size`, seeded per frame.
    pub fn downsample(&self, working_size: usize, method: Downsample, seed: u64) -> Downsampled {
        let mut out = Downsampled {
            working_size,
            method,
            ..Default::default()
        };
        for (k, f) in self.frames.iter().enumerate() {
            let (w, kept) = f.downsample(working_size, method, frame_seed(seed, k));
            out.original_sizes.push(f.points.len());
            out.kept.push(kept);
            out.sequence.frames.push(w);
        }
        out
    }

    /// Streams each file and downsamples it right away, so only one full frame is in
    /// memory at a time (frames of a million points). Same result as
    /// `from_files(paths)?.downsample(..)`.
    pub fn from_files_downsampled(
        paths: &[PathBuf],
        working_size: usize,
        method: Downsample,
        seed: u64,
    ) -> Result<Downsampled> {
        let opts = LoadOptions::default();
        let mut paths = paths.to_vec();
        sort_paths(&mut paths);
        let mut out = Downsampled {
            working_size,
            method,
            ..Default::default()
        };
        for (f, p) in paths.iter().enumerate() {
            for full in Frame::all_from_path(p, opts.mesh_samples, frame_seed(opts.seed, f))? {
                let k = out.sequence.frames.len();
                let (w, kept) = full.downsample(working_size, method, frame_seed(seed, k));
                out.original_sizes.push(full.points.len());
                out.kept.push(kept);
                out.sequence.frames.push(w);
            }
        }
        out.sequence = Sequence::from_frames(out.sequence.frames)?;
        Ok(out)
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// True when every frame carries ground-truth part labels.
    pub fn has_labels(&self) -> bool {
        self.frames.iter().all(|f| f.labels.is_some())
    }
}

/// The `gt.json` of a sequence folder, when there is one.
pub fn gt_path(dir: &Path) -> Option<PathBuf> {
    let p = dir.join("gt.json");
    p.is_file().then_some(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order() {
        let mut v = vec![
            "f10.ply", "f2.ply", "f1.ply", "F3.ply", "f02.ply", "a.ply", "f2b.ply",
        ];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            v,
            ["F3.ply", "a.ply", "f1.ply", "f02.ply", "f2.ply", "f2b.ply", "f10.ply"]
        );
        assert_eq!(natural_cmp("frame_009", "frame_010"), Ordering::Less);
        assert_eq!(
            natural_cmp("x99999999999999999999999", "x100000000000000000000000"),
            Ordering::Less
        );
        assert_eq!(natural_cmp("a", "a"), Ordering::Equal);
        assert_eq!(natural_cmp("a", "a1"), Ordering::Less);
    }

    #[test]
    fn frame_seeds_differ() {
        assert_ne!(frame_seed(0, 0), frame_seed(0, 1));
        assert_ne!(frame_seed(1, 0), frame_seed(0, 0));
    }
}
