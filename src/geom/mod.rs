//! Geometry shared by every stage: rigid transforms, rotations, nearest neighbours,
//! sampling and assignment, and the viewer's camera math.

pub mod assignment;
pub mod camera;
pub mod cap_bound;
pub mod cap_mask;
pub mod fps;
pub mod hull;
pub mod knn;
pub mod layers;
pub mod outliers;
pub mod se3;
