//! Reading and writing everything that crosses the product's boundary: PLY point
//! clouds, sequences of frames, ground truth (`gt.json`), the result format, and the
//! exports' containers (URDF with STL meshes, the page's video: WebM and MP4).

pub mod gt;
pub mod ply;
pub mod result;
pub mod sequence;
pub mod stl;
pub mod urdf;
pub mod video;
