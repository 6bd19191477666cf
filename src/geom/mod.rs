//! Geometry shared by every stage: rigid transforms, rotations, nearest neighbours,
//! sampling and assignment.

pub mod camera;
pub mod se3;
