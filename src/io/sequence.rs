//! A sequence of point-cloud frames of one articulated object.
//!
//! Loading from a folder or a file list (natural filename order), downsampling
//! to the working size and validation live here.

use glam::Vec3;

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
