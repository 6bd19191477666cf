//! Geometry shared by every stage: rigid transforms, rotations, nearest neighbours,
//! sampling and assignment.

pub mod fps;
pub mod se3;
