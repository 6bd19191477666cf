//! Geometry shared by every stage: rigid transforms, rotations, nearest neighbours,
//! sampling and assignment.

pub mod se3;
