//! Reading and writing everything that crosses the product's boundary: PLY point
//! clouds, sequences of frames, ground truth (`gt.json`) and the result format.

pub mod gt;
pub mod ply;
pub mod result;
pub mod sequence;
pub mod stl;
pub mod urdf;
