//! Steps 2 and 3: merging static parts, 1-DOF screw fits, the kinematic tree,
//! forward kinematics and joint refinement.
pub mod chain;
