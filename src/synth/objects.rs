//! The procedural objects: a kinematic tree of rigid parts (unions of primitives in
//! each part's own frame) connected by 1-DOF joints with natural ranges, and forward
//! kinematics in the benchmark's joint model
//! `pose[child] = pose[parent] @ M(q) @ child_in_parent_at_zero`.
//!
//! Every part frame sits at its joint pivot and is aligned with its parent at state 0,
//! so `child_in_parent_at_zero` is a pure translation to the pivot. Design units are
//! roughly metres; the generator normalises afterwards. Ranges are chosen so that parts
//! do not pass through each other (checked by hand for the extreme combinations).

use glam::{DMat4, DVec3};

use super::shapes::{aabb, capsule, cylinder, sphere, Primitive};
use crate::io::gt::JointType;

/// The 1-DOF joint between a part and its parent, in the parent's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct JointDef {
    pub name: String,
    pub joint_type: JointType,
    /// Unit axis in the parent's frame.
    pub axis: DVec3,
    /// Pivot (a point on the axis) in the parent's frame; also the child's origin.
    pub pivot: DVec3,
    /// Range the trajectories are drawn from (radians or design units).
    pub range: (f64, f64),
}

#[derive(Debug, Clone, PartialEq)]
pub struct PartDef {
    pub name: String,
    pub parent: Option<usize>,
    /// `None` only for the root.
    pub joint: Option<JointDef>,
    /// Surface of the part, in the part's frame.
    pub prims: Vec<Primitive>,
}

/// An articulated object; parents precede children.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectModel {
    pub parts: Vec<PartDef>,
}

impl JointDef {
    /// `child_in_parent_at_zero`: the child frame sits at the pivot.
    pub fn child_in_parent_at_zero(&self) -> DMat4 {
        DMat4::from_translation(self.pivot)
    }

    /// The joint motion `M(q)` in the parent's frame.
    pub fn motion(&self, q: f64) -> DMat4 {
        match self.joint_type {
            JointType::Revolute => {
                DMat4::from_translation(self.pivot)
                    * DMat4::from_quat(super::axis_angle(self.axis, q))
                    * DMat4::from_translation(-self.pivot)
            }
            JointType::Prismatic => DMat4::from_translation(self.axis * q),
        }
    }
}

impl ObjectModel {
    pub fn num_parts(&self) -> usize {
        self.parts.len()
    }

    /// Indices of the parts that have a joint (all but the root), in part order.
    pub fn joint_parts(&self) -> impl Iterator<Item = usize> + '_ {
        self.parts
            .iter()
            .enumerate()
            .filter(|(_, p)| p.joint.is_some())
            .map(|(i, _)| i)
    }

    /// World poses of all parts for the root pose and one state per part
    /// (`states[0]` is ignored).
    pub fn forward(&self, root: DMat4, states: &[f64]) -> Vec<DMat4> {
        let mut poses: Vec<DMat4> = Vec::with_capacity(self.parts.len());
        for (i, part) in self.parts.iter().enumerate() {
            let pose = match (&part.joint, part.parent) {
                (Some(j), Some(par)) => {
                    let q = states.get(i).copied().unwrap_or(0.0);
                    poses[par] * j.motion(q) * j.child_in_parent_at_zero()
                }
                _ => root,
            };
            poses.push(pose);
        }
        poses
    }

    // One call per part reads like a table of the object; a builder would only add noise.
    #[allow(clippy::too_many_arguments)]
    fn add(
        &mut self,
        name: &str,
        parent: usize,
        joint_type: JointType,
        axis: [f64; 3],
        pivot: [f64; 3],
        range: (f64, f64),
        prims: Vec<Primitive>,
    ) -> usize {
        self.parts.push(PartDef {
            name: name.to_string(),
            parent: Some(parent),
            joint: Some(JointDef {
                name: format!("joint_{name}"),
                joint_type,
                axis: DVec3::from(axis).normalize(),
                pivot: DVec3::from(pivot),
                range,
            }),
            prims,
        });
        self.parts.len() - 1
    }

    fn root(name: &str, prims: Vec<Primitive>) -> Self {
        ObjectModel {
            parts: vec![PartDef {
                name: name.to_string(),
                parent: None,
                joint: None,
                prims,
            }],
        }
    }
}

const R: JointType = JointType::Revolute;
const P: JointType = JointType::Prismatic;

fn deg(d: f64) -> f64 {
    d.to_radians()
}

/// Base + lid on a hinge along the back edge (lid 20°–130° open).
pub fn laptop() -> ObjectModel {
    let mut m = ObjectModel::root(
        "base",
        vec![
            aabb([-0.17, -0.12, 0.0], [0.17, 0.12, 0.02]),
            // keyboard and touchpad stand 3 mm proud of the deck
            aabb([-0.15, -0.01, 0.015], [0.15, 0.1, 0.023]),
            aabb([-0.045, -0.105, 0.015], [0.045, -0.04, 0.022]),
        ],
    );
    // Closed lid lies on the deck, hinge at its back-bottom edge; rotating about −x
    // lifts the front edge.
    m.add(
        "lid",
        0,
        R,
        [-1.0, 0.0, 0.0],
        [0.0, 0.12, 0.02],
        (deg(20.0), deg(130.0)),
        vec![
            aabb([-0.17, -0.24, 0.0], [0.17, 0.0, 0.012]),
            // screen, slightly recessed into the inner face
            aabb([-0.155, -0.225, -0.002], [0.155, -0.02, 0.001]),
        ],
    );
    m
}

/// Cabinet body with two drawers (left column) and a door (right column).
pub fn cabinet() -> ObjectModel {
    let mut m = ObjectModel::root(
        "body",
        vec![
            aabb([-0.3, -0.225, 0.78], [0.3, 0.225, 0.8]), // top
            aabb([-0.3, -0.225, 0.0], [0.3, 0.225, 0.02]), // bottom
            aabb([-0.3, -0.225, 0.015], [-0.28, 0.225, 0.785]), // left side
            aabb([0.28, -0.225, 0.015], [0.3, 0.225, 0.785]), // right side
            aabb([-0.285, 0.205, 0.015], [0.285, 0.225, 0.785]), // back
            aabb([-0.01, -0.225, 0.015], [0.01, 0.21, 0.785]), // divider
            aabb([-0.285, -0.225, 0.39], [-0.005, 0.21, 0.41]), // shelf between drawers
        ],
    );
    let depth = 0.4;
    let drawer = || {
        vec![
            aabb([-0.133, -0.02, 0.0], [0.133, 0.0, 0.366]), // front panel
            aabb([-0.125, -0.001, 0.01], [0.125, depth, 0.025]), // tray bottom
            aabb([-0.125, -0.001, 0.01], [-0.11, depth, 0.28]), // tray sides
            aabb([0.11, -0.001, 0.01], [0.125, depth, 0.28]),
            aabb([-0.125, depth - 0.015, 0.01], [0.125, depth, 0.28]), // tray back
            aabb([-0.05, -0.04, 0.26], [0.05, -0.018, 0.285]),         // handle
        ]
    };
    let pull = (0.0, 0.8 * depth);
    m.add(
        "drawer_top",
        0,
        P,
        [0.0, -1.0, 0.0],
        [-0.145, -0.225, 0.412],
        pull,
        drawer(),
    );
    m.add(
        "drawer_bottom",
        0,
        P,
        [0.0, -1.0, 0.0],
        [-0.145, -0.225, 0.022],
        pull,
        drawer(),
    );
    // Door hinged on the right front edge, swinging outwards (towards −y).
    m.add(
        "door",
        0,
        R,
        [0.0, 0.0, 1.0],
        [0.3, -0.225, 0.02],
        (0.0, deg(100.0)),
        vec![
            aabb([-0.288, -0.02, 0.0], [-0.002, 0.0, 0.758]),
            aabb([-0.27, -0.045, 0.3], [-0.252, -0.018, 0.46]), // handle bar
        ],
    );
    m
}

/// A 6-joint arm (axes z, y, y, z, y, z like common industrial arms) with a gripper.
pub fn arm() -> ObjectModel {
    let mut m = ObjectModel::root(
        "base",
        vec![
            cylinder([0.0, 0.0, 0.0], [0.0, 0.0, 0.08], 0.1),
            cylinder([0.0, 0.0, 0.07], [0.0, 0.0, 0.12], 0.07),
        ],
    );
    let z = [0.0, 0.0, 1.0];
    let y = [0.0, 1.0, 0.0];
    let l1 = m.add(
        "shoulder_pan",
        0,
        R,
        z,
        [0.0, 0.0, 0.12],
        (-2.5, 2.5),
        vec![
            cylinder([0.0, 0.0, -0.005], [0.0, 0.0, 0.1], 0.065),
            cylinder([0.0, -0.075, 0.15], [0.0, 0.075, 0.15], 0.06),
        ],
    );
    let l2 = m.add(
        "upper_arm",
        l1,
        R,
        y,
        [0.0, 0.0, 0.15],
        (-1.2, 1.2),
        vec![
            capsule([0.0, 0.0, 0.0], [0.0, 0.0, 0.4], 0.045),
            cylinder([0.0, -0.06, 0.4], [0.0, 0.06, 0.4], 0.05),
        ],
    );
    let l3 = m.add(
        "forearm",
        l2,
        R,
        y,
        [0.0, 0.0, 0.4],
        (-2.2, 2.2),
        vec![capsule([0.0, 0.0, 0.0], [0.0, 0.0, 0.35], 0.038)],
    );
    let l4 = m.add(
        "wrist_roll",
        l3,
        R,
        z,
        [0.0, 0.0, 0.35],
        (-2.5, 2.5),
        vec![
            cylinder([0.0, 0.0, 0.0], [0.0, 0.0, 0.07], 0.036),
            cylinder([0.0, -0.045, 0.1], [0.0, 0.045, 0.1], 0.036),
        ],
    );
    let l5 = m.add(
        "wrist_pitch",
        l4,
        R,
        y,
        [0.0, 0.0, 0.1],
        (-1.9, 1.9),
        vec![cylinder([0.0, 0.0, 0.0], [0.0, 0.0, 0.08], 0.03)],
    );
    m.add(
        "gripper",
        l5,
        R,
        z,
        [0.0, 0.0, 0.08],
        (-2.8, 2.8),
        vec![
            cylinder([0.0, 0.0, 0.0], [0.0, 0.0, 0.02], 0.04),
            aabb([-0.045, -0.015, 0.018], [0.045, 0.015, 0.05]),
            aabb([-0.04, -0.01, 0.045], [-0.024, 0.01, 0.11]),
            aabb([0.024, -0.01, 0.045], [0.04, 0.01, 0.11]),
        ],
    );
    m
}

/// Palm + four fingers of three phalanges each (13 parts), flexing towards −y.
pub fn hand() -> ObjectModel {
    let mut m = ObjectModel::root(
        "palm",
        vec![
            aabb([-0.047, -0.014, 0.0], [0.047, 0.014, 0.1]),
            cylinder([0.0, 0.0, -0.025], [0.0, 0.0, 0.005], 0.026), // wrist stub
        ],
    );
    let r = 0.0095;
    let fingers = [
        ("index", -0.0345, 0.92),
        ("middle", -0.0115, 1.0),
        ("ring", 0.0115, 0.95),
        ("little", 0.0345, 0.78),
    ];
    let x_axis = [1.0, 0.0, 0.0];
    for (name, x, s) in fingers {
        let lens = [0.052 * s, 0.033 * s, 0.025 * s];
        let ranges = [(0.0, deg(80.0)), (0.0, deg(90.0)), (0.0, deg(70.0))];
        let labels = ["proximal", "middle", "distal"];
        let mut parent = 0;
        let mut pivot = [x, 0.0, 0.102];
        for k in 0..3 {
            let l = lens[k];
            let mut prims = vec![capsule([0.0, 0.0, 0.0], [0.0, 0.0, l], r)];
            if k == 2 {
                // fingernail, so the distal phalanx's roll is visible
                prims.push(aabb([-0.006, 0.006, l * 0.45], [0.006, 0.011, l * 1.05]));
            }
            parent = m.add(
                &format!("{name}_{}", labels[k]),
                parent,
                R,
                x_axis,
                pivot,
                ranges[k],
                prims,
            );
            pivot = [0.0, 0.0, l];
        }
    }
    m
}

/// Body (with head and tail) + four legs of two segments (9 parts).
pub fn quadruped() -> ObjectModel {
    let mut m = ObjectModel::root(
        "body",
        vec![
            aabb([-0.35, -0.12, -0.06], [0.35, 0.12, 0.06]),
            capsule([0.3, 0.0, 0.02], [0.4, 0.0, 0.08], 0.05), // neck
            sphere([0.42, 0.0, 0.1], 0.075),                   // head
            aabb([0.45, -0.035, 0.05], [0.53, 0.035, 0.11]),   // snout
            capsule([-0.34, 0.0, 0.03], [-0.45, 0.0, 0.1], 0.015), // tail
        ],
    );
    let y = [0.0, 1.0, 0.0];
    // Rotation about +y by a positive angle swings the foot backwards (−x). Front legs
    // mostly swing forwards and bend backwards, hind legs the mirror image, so front
    // and hind feet never meet.
    let legs = [
        ("front_left", 0.3, 0.165, (-0.7, 0.25), (0.0, 1.4)),
        ("front_right", 0.3, -0.165, (-0.7, 0.25), (0.0, 1.4)),
        ("hind_left", -0.3, 0.165, (-0.25, 0.7), (-1.4, 0.0)),
        ("hind_right", -0.3, -0.165, (-0.25, 0.7), (-1.4, 0.0)),
    ];
    for (name, x, yy, hip, knee) in legs {
        let thigh = m.add(
            &format!("{name}_thigh"),
            0,
            R,
            y,
            [x, yy, -0.02],
            hip,
            vec![
                cylinder([0.0, -0.035, 0.0], [0.0, 0.035, 0.0], 0.045),
                capsule([0.0, 0.0, 0.0], [0.0, 0.0, -0.2], 0.032),
            ],
        );
        m.add(
            &format!("{name}_shank"),
            thigh,
            R,
            y,
            [0.0, 0.0, -0.2],
            knee,
            vec![
                capsule([0.0, 0.0, 0.0], [0.0, 0.0, -0.2], 0.024),
                sphere([0.0, 0.0, -0.2], 0.034),
            ],
        );
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all() -> Vec<ObjectModel> {
        vec![laptop(), cabinet(), arm(), hand(), quadruped()]
    }

    #[test]
    fn trees_are_well_formed() {
        for m in all() {
            assert!(m.parts[0].parent.is_none() && m.parts[0].joint.is_none());
            for (i, p) in m.parts.iter().enumerate().skip(1) {
                let par = p.parent.unwrap_or(usize::MAX);
                assert!(par < i, "parent must precede child");
                let j = p.joint.as_ref().map(|j| j.range).unwrap_or((1.0, 0.0));
                assert!(j.0 < j.1);
                assert!(!p.prims.is_empty());
                assert!(p.prims.iter().all(|q| q.area() > 1e-5));
            }
        }
        assert_eq!(laptop().num_parts(), 2);
        assert_eq!(cabinet().num_parts(), 4);
        assert_eq!(arm().num_parts(), 7);
        assert_eq!(hand().num_parts(), 13);
        assert_eq!(quadruped().num_parts(), 9);
    }

    #[test]
    fn forward_at_zero_is_translation_chain() {
        let m = arm();
        let poses = m.forward(DMat4::IDENTITY, &vec![0.0; m.num_parts()]);
        // at zero the arm stands straight up: gripper frame at the summed heights
        let top = poses[6].w_axis.truncate();
        assert!(
            (top - DVec3::new(0.0, 0.0, 0.12 + 0.15 + 0.4 + 0.35 + 0.1 + 0.08)).length() < 1e-12
        );
    }

    #[test]
    fn revolute_motion_keeps_pivot_fixed() {
        let m = laptop();
        let j = m.parts[1].joint.clone().unwrap();
        let p = j.motion(1.0).transform_point3(j.pivot);
        assert!((p - j.pivot).length() < 1e-12);
        // lid opens upwards: the front edge rises
        let poses = m.forward(DMat4::IDENTITY, &[0.0, deg(90.0)]);
        let front = poses[1].transform_point3(DVec3::new(0.0, -0.24, 0.0));
        assert!(front.z > 0.2);
    }
}
