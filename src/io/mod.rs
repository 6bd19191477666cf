//! Reading and writing everything that crosses the product's boundary: point-cloud
//! frames (PLY; PCD, NumPy `.npy`/`.npz`, OBJ and text tables through `cloud_file`),
//! sequences of frames, ground truth (`gt.json`), the result format, and the
//! exports' containers (URDF with STL meshes, the page's video: WebM and MP4).

pub mod cloud_file;
pub mod gt;
pub mod npy;
pub mod npz;
pub mod obj;
pub mod pcd;
pub mod ply;
pub mod result;
pub mod sequence;
pub mod stl;
pub mod text_cloud;
pub mod urdf;
pub mod video;
