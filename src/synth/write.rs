//! Writes a generated sequence as a benchmark folder, exactly the `bench-dev` layout:
//! `frame_000.ply …` (float x y z, int part), `gt.json`, `heldout/frame_000.ply …`.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::{gt_json, SynthOutput};
use crate::io::ply::write_ply;
use crate::io::sequence::Frame;

/// Write `out` into `dir` (created if needed) with binary little-endian PLY files.
pub fn write_sequence_dir(out: &SynthOutput, dir: &Path) -> crate::Result<()> {
    write_sequence_dir_with(out, dir, false)
}

/// [`write_sequence_dir`] choosing ascii or binary PLY.
pub fn write_sequence_dir_with(out: &SynthOutput, dir: &Path, ascii: bool) -> crate::Result<()> {
    let shown = |p: &Path| p.display().to_string();
    std::fs::create_dir_all(dir).map_err(|e| crate::Error::io(shown(dir), e))?;
    if out.gt.frames.len() != out.sequence.frames.len()
        || out.gt.heldout_frames.len() != out.heldout.len()
    {
        return Err(crate::Error::Sequence(
            "ground truth frame names do not match the frames".into(),
        ));
    }
    if !out.heldout.is_empty() {
        let h = dir.join("heldout");
        std::fs::create_dir_all(&h).map_err(|e| crate::Error::io(shown(&h), e))?;
    }
    let names = out.gt.frames.iter().chain(&out.gt.heldout_frames);
    let frames = out.sequence.frames.iter().chain(&out.heldout);
    for (name, frame) in names.zip(frames) {
        write_frame(&dir.join(name), frame, ascii)?;
    }
    let gt = dir.join("gt.json");
    std::fs::write(&gt, gt_json(out)).map_err(|e| crate::Error::io(shown(&gt), e))?;
    Ok(())
}

fn write_frame(path: &Path, frame: &Frame, ascii: bool) -> crate::Result<()> {
    let err = |e| crate::Error::io(path.display().to_string(), e);
    let file = File::create(path).map_err(err)?;
    let mut w = BufWriter::new(file);
    write_ply(&mut w, &frame.points, frame.labels.as_deref(), ascii).map_err(err)?;
    w.flush().map_err(err)
}
