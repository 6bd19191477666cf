//! URDF export of a fitted articulated model, for simulators and robotics tools.
//!
//! One link per part, one joint per tree edge. Link frames sit at their joint's pivot
//! (the root link at the world origin) with the world orientation of the canonical
//! frame c, so joint `<origin>`s are pure translations between pivots and `<axis>` is
//! the world axis; the model's zero configuration is the canonical frame (the root
//! motion is not part of a URDF). Geometry, for `<visual>` and `<collision>`:
//! - [`Geometry::Hull`] (the default): the convex hull of the part's canonical points
//!   as a binary STL mesh file ([`crate::geom::hull`], [`crate::io::stl`]), named by a
//!   path relative to the URDF; `<inertial>` is the solid hull's at mass 1 (centre of
//!   mass and full inertia tensor), which a simulator can use as it is;
//! - [`Geometry::Box`]: a `<box>` fitted to the points by a PCA-oriented bounding box,
//!   one file with no meshes, the box's inertia at mass 1. A part whose points span no
//!   volume (flat, or fewer than four) gets its box with either choice.
//!
//! FK of the URDF (origin · joint motion composed from the root) equals the crate's
//! [`crate::kinematics::chain::Chain`] FK times the link offset `Tr(pivot)`; the tests
//! check it.

use crate::math::Libm;
use std::fmt::Write;

use glam::{DMat3, DVec3, Vec3};
use nalgebra::{Matrix3, SymmetricEigen};

use crate::geom::hull::convex_hull;
use crate::io::gt::JointType;
use crate::io::result::FitResult;
use crate::io::stl::binary_stl;

/// Smallest box side written (a flat or single-point part still gets a valid box).
const MIN_SIDE: f64 = 1e-3;
/// `<limit>` effort and velocity (URDF requires them; the fit knows nothing of dynamics).
const EFFORT: f64 = 100.0;
const VELOCITY: f64 = 1.0;

/// A link's geometry in the URDF export.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Geometry {
    /// The convex hull of the part's points, as a mesh file.
    #[default]
    Hull,
    /// A bounding box (`<box>`): one URDF file, no meshes.
    Box,
}

impl std::str::FromStr for Geometry {
    type Err = crate::Error;

    /// "hull" or "box", as the CLI's `--urdf-geometry` and the page name them.
    fn from_str(s: &str) -> crate::Result<Geometry> {
        match s {
            "hull" => Ok(Geometry::Hull),
            "box" => Ok(Geometry::Box),
            other => Err(crate::Error::InvalidArgument(format!(
                "URDF geometry {other:?}: use \"hull\" or \"box\""
            ))),
        }
    }
}

/// A mesh file the URDF names: its path relative to the URDF's folder, and its bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshFile {
    pub path: String,
    pub bytes: Vec<u8>,
}

/// A URDF and the mesh files it names (none with [`Geometry::Box`]).
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfExport {
    pub urdf: String,
    pub meshes: Vec<MeshFile>,
}

/// An oriented bounding box: centre, orientation (columns = box axes, right-handed)
/// and full side lengths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrientedBox {
    pub center: DVec3,
    pub rotation: DMat3,
    pub size: DVec3,
}

/// PCA-oriented bounding box of `points` (`None` if empty).
pub fn oriented_box(points: &[Vec3]) -> Option<OrientedBox> {
    if points.is_empty() {
        return None;
    }
    let n = points.len() as f64;
    let mean = points.iter().map(|p| p.as_dvec3()).sum::<DVec3>() / n;
    let mut cov = Matrix3::<f64>::zeros();
    for p in points {
        let d = p.as_dvec3() - mean;
        let v = nalgebra::Vector3::new(d.x, d.y, d.z);
        cov += v * v.transpose();
    }
    let e = SymmetricEigen::new(cov / n);
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&a, &b| e.eigenvalues[b].total_cmp(&e.eigenvalues[a]));
    let col = |k: usize| {
        let c = e.eigenvectors.column(idx[k]);
        DVec3::new(c[0], c[1], c[2]).normalize_or(DVec3::X)
    };
    let (x, y) = (col(0), col(1));
    let mut rotation = DMat3::from_cols(x, y, x.cross(y).normalize_or(DVec3::Z));
    if !rotation.is_finite() || (rotation.determinant() - 1.0).abs() > 1e-6 {
        rotation = DMat3::IDENTITY;
    }
    let rt = rotation.transpose();
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for p in points {
        let l = rt * (p.as_dvec3() - mean);
        lo = lo.min(l);
        hi = hi.max(l);
    }
    Some(OrientedBox {
        center: mean + rotation * ((lo + hi) * 0.5),
        rotation,
        size: (hi - lo).max(DVec3::splat(MIN_SIDE)),
    })
}

/// URDF roll-pitch-yaw (fixed axes: R = Rz(yaw) Ry(pitch) Rx(roll)) of a rotation.
pub fn rpy(r: &DMat3) -> DVec3 {
    // glam is column-major: r.col(j)[i] = R[i][j]
    let m = |i: usize, j: usize| r.col(j)[i];
    let pitch = (-m(2, 0)).clamp(-1.0, 1.0).lasin();
    if m(2, 0).abs() < 1.0 - 1e-12 {
        DVec3::new(m(2, 1).latan2(m(2, 2)), pitch, m(1, 0).latan2(m(0, 0)))
    } else {
        // gimbal lock: put everything into yaw
        DVec3::new(0.0, pitch, (-m(0, 1)).latan2(m(1, 1)))
    }
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&apos;")
}

fn v(x: DVec3) -> String {
    format!("{} {} {}", x.x, x.y, x.z)
}

/// Name of part p's link.
pub fn link_name(p: usize) -> String {
    format!("part_{p}")
}

/// Name of the joint whose child is part p.
pub fn joint_name(p: usize) -> String {
    format!("joint_{p}")
}

/// The URDF of `result` (which needs a tree and joints) and its mesh files.
/// `part_points[p]`: part p's points at the canonical frame (world coordinates) for its
/// geometry; `name`: robot name; `mesh_dir`: the folder of the mesh files, relative to
/// the URDF's (their paths are `mesh_dir/part_P.stl`).
pub fn export(
    result: &FitResult,
    part_points: &[Vec<Vec3>],
    name: &str,
    geometry: Geometry,
    mesh_dir: &str,
) -> crate::Result<UrdfExport> {
    let bad = |s: String| crate::Error::InvalidArgument(format!("URDF export: {s}"));
    let tree = result
        .tree
        .as_ref()
        .ok_or_else(|| bad("the result has no kinematic tree".into()))?;
    let joints = result
        .joints
        .as_ref()
        .ok_or_else(|| bad("the result has no joints".into()))?;
    let n = result.parts;
    if tree.parent.len() != n || tree.root >= n {
        return Err(bad("tree does not match the part count".into()));
    }
    // Link frame origins: the pivot of the joint above each part, the world origin for
    // the root and for parts attached without a joint.
    let mut origin = vec![DVec3::ZERO; n];
    let mut joint_of = vec![None; n];
    for j in joints {
        if j.child >= n || j.parent >= n || tree.parent[j.child] != j.parent as i64 {
            return Err(bad(format!(
                "joint of part {} does not match the tree",
                j.child
            )));
        }
        origin[j.child] = DVec3::from(j.pivot);
        joint_of[j.child] = Some(j);
    }
    let mut s = String::new();
    let mut meshes = Vec::new();
    // Writing to a String cannot fail.
    let _ = writeln!(s, "<?xml version=\"1.0\"?>");
    let _ = writeln!(s, "<robot name=\"{}\">", esc(name));
    for (p, &o) in origin.iter().enumerate() {
        let _ = writeln!(s, "  <link name=\"{}\">", link_name(p));
        let pts = part_points.get(p).map(|v| v.as_slice()).unwrap_or(&[]);
        let hull = match geometry {
            Geometry::Hull => convex_hull(pts).and_then(|h| Some((h.mass_properties()?, h))),
            Geometry::Box => None,
        };
        if let Some((mass, hull)) = hull {
            let path = if mesh_dir.is_empty() {
                format!("{}.stl", link_name(p))
            } else {
                format!("{}/{}.stl", mesh_dir.trim_end_matches('/'), link_name(p))
            };
            let i = mass.inertia;
            let _ = writeln!(
                s,
                "    <inertial>\n      <origin xyz=\"{}\" rpy=\"0 0 0\"/>\n      <mass value=\"1\"/>\n      <inertia ixx=\"{}\" ixy=\"{}\" ixz=\"{}\" iyy=\"{}\" iyz=\"{}\" izz=\"{}\"/>\n    </inertial>",
                v(mass.center - o),
                i.x_axis.x,
                i.y_axis.x,
                i.z_axis.x,
                i.y_axis.y,
                i.z_axis.y,
                i.z_axis.z
            );
            for tag in ["visual", "collision"] {
                let _ = writeln!(
                    s,
                    "    <{tag}>\n      <origin xyz=\"0 0 0\" rpy=\"0 0 0\"/>\n      <geometry>\n        <mesh filename=\"{}\"/>\n      </geometry>\n    </{tag}>",
                    esc(&path)
                );
            }
            meshes.push(MeshFile {
                path,
                bytes: binary_stl(&hull.vertices, &hull.triangles, -o),
            });
        } else if let Some(b) = oriented_box(pts) {
            let xyz = v(b.center - o);
            let r = v(rpy(&b.rotation));
            let size = v(b.size);
            let (x2, y2, z2) = (
                b.size.x * b.size.x,
                b.size.y * b.size.y,
                b.size.z * b.size.z,
            );
            let _ = writeln!(
                s,
                "    <inertial>\n      <origin xyz=\"{xyz}\" rpy=\"{r}\"/>\n      <mass value=\"1\"/>\n      <inertia ixx=\"{}\" ixy=\"0\" ixz=\"0\" iyy=\"{}\" iyz=\"0\" izz=\"{}\"/>\n    </inertial>",
                (y2 + z2) / 12.0,
                (x2 + z2) / 12.0,
                (x2 + y2) / 12.0
            );
            for tag in ["visual", "collision"] {
                let _ = writeln!(
                    s,
                    "    <{tag}>\n      <origin xyz=\"{xyz}\" rpy=\"{r}\"/>\n      <geometry>\n        <box size=\"{size}\"/>\n      </geometry>\n    </{tag}>"
                );
            }
        }
        let _ = writeln!(s, "  </link>");
    }
    for p in 0..n {
        let par = tree.parent[p];
        if par < 0 {
            continue;
        }
        let a = par as usize;
        let xyz = v(origin[p] - origin[a]);
        match joint_of[p] {
            Some(j) => {
                let ty = match j.joint_type {
                    JointType::Revolute => "revolute",
                    JointType::Prismatic => "prismatic",
                };
                let axis = DVec3::from(j.axis).normalize_or(DVec3::Z);
                // URDF joint values are the result's states (0 at the canonical frame,
                // the links' frames posed there), so a coupling carries over as it is.
                let mimic = match j.mimic {
                    Some(m) if joint_of.get(m.joint).is_some_and(Option::is_some) => format!(
                        "\n    <mimic joint=\"{}\" multiplier=\"{}\" offset=\"{}\"/>",
                        joint_name(m.joint),
                        m.multiplier,
                        m.offset
                    ),
                    _ => String::new(),
                };
                let _ = writeln!(
                    s,
                    "  <joint name=\"{}\" type=\"{ty}\">\n    <parent link=\"{}\"/>\n    <child link=\"{}\"/>\n    <origin xyz=\"{xyz}\" rpy=\"0 0 0\"/>\n    <axis xyz=\"{}\"/>\n    <limit lower=\"{}\" upper=\"{}\" effort=\"{EFFORT}\" velocity=\"{VELOCITY}\"/>{mimic}\n  </joint>",
                    joint_name(p),
                    link_name(a),
                    link_name(p),
                    v(axis),
                    j.limits[0],
                    j.limits[1]
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "  <joint name=\"{}\" type=\"fixed\">\n    <parent link=\"{}\"/>\n    <child link=\"{}\"/>\n    <origin xyz=\"{xyz}\" rpy=\"0 0 0\"/>\n  </joint>",
                    joint_name(p),
                    link_name(a),
                    link_name(p)
                );
            }
        }
    }
    let _ = writeln!(s, "</robot>");
    Ok(UrdfExport { urdf: s, meshes })
}

/// Canonical-frame points of each part from a result and the working points of its
/// canonical frame (`points` in the order of `result.labels[c]`).
pub fn canonical_part_points(result: &FitResult, points: &[Vec3]) -> Vec<Vec<Vec3>> {
    let mut out = vec![Vec::new(); result.parts];
    if let Some(labels) = result.labels.get(result.canonical_frame) {
        for (p, &l) in points.iter().zip(labels) {
            if let Some(v) = out.get_mut(l as usize) {
                v.push(*p);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_round_trip() {
        for (r, p, y) in [(0.3, -0.4, 1.2), (-2.0, 0.1, -3.0), (0.0, 0.0, 0.0)] {
            let m =
                DMat3::from_rotation_z(y) * DMat3::from_rotation_y(p) * DMat3::from_rotation_x(r);
            let e = rpy(&m);
            let m2 = DMat3::from_rotation_z(e.z)
                * DMat3::from_rotation_y(e.y)
                * DMat3::from_rotation_x(e.x);
            assert!(m.abs_diff_eq(m2, 1e-12));
        }
    }

    #[test]
    fn box_contains_points_and_is_tight_for_a_box() {
        let rot = DMat3::from_rotation_z(0.5) * DMat3::from_rotation_x(0.3);
        let mut pts = Vec::new();
        for i in 0..5 {
            for j in 0..3 {
                for k in 0..2 {
                    let l = DVec3::new(i as f64 * 0.1, j as f64 * 0.05, k as f64 * 0.02);
                    pts.push((rot * l + DVec3::new(1.0, 2.0, 3.0)).as_vec3());
                }
            }
        }
        let b = oriented_box(&pts).unwrap();
        assert!(
            (b.size - DVec3::new(0.4, 0.1, 0.02)).abs().max_element() < 1e-5,
            "{:?}",
            b.size
        );
        for p in &pts {
            let l = b.rotation.transpose() * (p.as_dvec3() - b.center);
            assert!((l.abs() - b.size * 0.5).max_element() < 1e-6);
        }
    }
}
