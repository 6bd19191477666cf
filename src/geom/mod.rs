//! Geometry shared by every stage: rigid transforms, rotations, nearest neighbours,
//! sampling and assignment.

pub mod assignment;
pub mod fps;
pub mod knn;
pub mod se3;
