//! Steps 2 and 3: merging static parts, 1-DOF screw fits, the kinematic tree,
//! forward kinematics and joint refinement.

pub mod build;
pub mod chain;
pub mod coverage;
pub mod flips;
pub mod frame_gmm;
pub mod half_turns;
pub mod invisible_joints;
pub mod joint_sweep;
pub mod merge;
pub mod mimic;
pub mod observed;
pub mod parallel;
pub mod project;
pub mod refine;
pub mod relabel;
pub mod screw;
pub mod spatial;
pub mod spin_free;
pub mod track;
pub mod tree;

pub use build::{build_articulated, KinOptions, KinReport};
