//! URDF export: the exported file parses (roxmltree), and forward kinematics of the
//! URDF (composing joint origins and joint motions from the base link) equals the
//! crate's `Chain` FK times each link's offset, for random states. With python3 and
//! `yourdfpy` present, the same check runs through that standard URDF parser, on the
//! URDF with its link meshes (convex hulls, STL): every mesh loads, is closed, and its
//! centre of mass and inertia as trimesh computes them are the URDF's `<inertial>`.

mod kin_common;
mod python_common;

use std::collections::HashMap;

use glam::{DMat3, DMat4, DVec3};
use gsart::geom::se3::to_row_major;
use gsart::io::result::FitResult;
use gsart::io::urdf::{canonical_part_points, export, joint_name, link_name, Geometry};
use gsart::kinematics::chain::Chain;
use gsart::kinematics::mimic::follow;
use gsart::kinematics::{build_articulated, KinOptions};
use gsart::math::Libm;
use gsart::pipeline::Control;
use kin_common::{load, sequences};
use rand::{rngs::StdRng, Rng, SeedableRng};

fn parse3(s: &str) -> DVec3 {
    let v: Vec<f64> = s.split_whitespace().map(|x| x.parse().unwrap()).collect();
    assert_eq!(v.len(), 3, "{s}");
    DVec3::new(v[0], v[1], v[2])
}

/// Link poses of a URDF at joint values `q` (by joint name), base link at identity.
fn urdf_fk(text: &str, q: &HashMap<String, f64>) -> HashMap<String, DMat4> {
    let doc = roxmltree::Document::parse(text).unwrap();
    let robot = doc.root_element();
    assert_eq!(robot.tag_name().name(), "robot");
    let links: Vec<String> = robot
        .children()
        .filter(|n| n.has_tag_name("link"))
        .map(|n| n.attribute("name").unwrap().to_string())
        .collect();
    struct J {
        name: String,
        ty: String,
        parent: String,
        child: String,
        origin: DMat4,
        axis: DVec3,
        /// (leader joint, multiplier, offset) of a `<mimic>`.
        mimic: Option<(String, f64, f64)>,
    }
    let mut joints = Vec::new();
    for j in robot.children().filter(|n| n.has_tag_name("joint")) {
        let get = |tag: &str| j.children().find(|n| n.has_tag_name(tag));
        let o = get("origin").unwrap();
        let xyz = parse3(o.attribute("xyz").unwrap());
        let rpy = parse3(o.attribute("rpy").unwrap());
        let r = DMat3::from_rotation_z(rpy.z)
            * DMat3::from_rotation_y(rpy.y)
            * DMat3::from_rotation_x(rpy.x);
        let ty = j.attribute("type").unwrap().to_string();
        if ty != "fixed" {
            let l = get("limit").unwrap();
            let lo: f64 = l.attribute("lower").unwrap().parse().unwrap();
            let hi: f64 = l.attribute("upper").unwrap().parse().unwrap();
            assert!(lo <= hi);
            assert!(l.attribute("effort").is_some() && l.attribute("velocity").is_some());
        }
        joints.push(J {
            name: j.attribute("name").unwrap().to_string(),
            ty,
            parent: get("parent")
                .unwrap()
                .attribute("link")
                .unwrap()
                .to_string(),
            child: get("child").unwrap().attribute("link").unwrap().to_string(),
            origin: DMat4::from_translation(xyz) * DMat4::from_mat3(r),
            axis: get("axis")
                .map(|a| parse3(a.attribute("xyz").unwrap()))
                .unwrap_or(DVec3::X),
            mimic: get("mimic").map(|m| {
                let num = |a: &str| m.attribute(a).map_or(0.0, |v| v.parse().unwrap());
                let mul = m
                    .attribute("multiplier")
                    .map_or(1.0, |v| v.parse().unwrap());
                (
                    m.attribute("joint").unwrap().to_string(),
                    mul,
                    num("offset"),
                )
            }),
        });
    }
    let children: Vec<&str> = joints.iter().map(|j| j.child.as_str()).collect();
    let bases: Vec<&String> = links
        .iter()
        .filter(|l| !children.contains(&l.as_str()))
        .collect();
    assert_eq!(bases.len(), 1, "exactly one base link");
    let mut pose = HashMap::from([(bases[0].clone(), DMat4::IDENTITY)]);
    while pose.len() < links.len() {
        let before = pose.len();
        for j in &joints {
            if pose.contains_key(&j.child) {
                continue;
            }
            let Some(&wp) = pose.get(&j.parent) else {
                continue;
            };
            // A mimic joint's value is its leader's, scaled and offset (URDF spec).
            let v = match &j.mimic {
                Some((lead, mul, off)) => mul * q.get(lead).copied().unwrap_or(0.0) + off,
                None => q.get(&j.name).copied().unwrap_or(0.0),
            };
            let m = match j.ty.as_str() {
                "revolute" | "continuous" => DMat4::from_axis_angle(j.axis.normalize(), v),
                "prismatic" => DMat4::from_translation(j.axis.normalize() * v),
                _ => DMat4::IDENTITY,
            };
            pose.insert(j.child.clone(), wp * j.origin * m);
        }
        assert!(pose.len() > before, "URDF tree is not connected");
    }
    pose
}

/// Results to export: the pipeline's output on two bench-dev sequences (revolute chain
/// and prismatic joints).
fn results() -> Vec<(String, FitResult, Vec<Vec<glam::Vec3>>)> {
    let mut out = Vec::new();
    for dir in sequences() {
        let name = dir.file_name().unwrap().to_string_lossy().into_owned();
        if !(name.starts_with("xarm7")
            || name.starts_with("panda_gripper")
            || name.starts_with("laikago"))
        {
            continue;
        }
        let seq = load(&dir);
        let opts = KinOptions {
            refine: None,
            ..Default::default()
        };
        let (res, _) = build_articulated(
            &seq.points,
            &seq.labels,
            &seq.gt.poses,
            0,
            &opts,
            &|| 0.0,
            &mut |_| Control::Continue,
        )
        .unwrap();
        let pts = canonical_part_points(&res, &seq.points[0]);
        out.push((name, res, pts));
    }
    out
}

/// Expected pose of part p's link: Chain FK (root at identity) · Tr(link origin).
fn expected(res: &FitResult, chain: &Chain, states: &[f64]) -> Vec<DMat4> {
    let mut origin = vec![DVec3::ZERO; res.parts];
    for j in res.joints.as_ref().unwrap() {
        origin[j.child] = DVec3::from(j.pivot);
    }
    chain
        .part_poses(&DMat4::IDENTITY, states)
        .unwrap()
        .iter()
        .zip(&origin)
        .map(|(m, o)| *m * DMat4::from_translation(*o))
        .collect()
}

/// The values a URDF reader is given, by joint name: every joint's but the followers'
/// (their `<mimic>` must move them).
fn leader_values(res: &FitResult, q: &[f64]) -> HashMap<String, f64> {
    res.joints
        .as_ref()
        .unwrap()
        .iter()
        .filter(|j| j.mimic.is_none())
        .map(|j| (joint_name(j.child), q[j.child]))
        .collect()
}

/// Random joint states, each follower's then set from its leader's (a URDF reader
/// moves a mimic joint with its leader whatever value it is given).
fn random_states(res: &FitResult, rng: &mut StdRng) -> Vec<f64> {
    let mut q = vec![0.0; res.parts];
    let joints = res.joints.as_ref().unwrap();
    for j in joints {
        let (lo, hi) = (j.limits[0] - 0.5, j.limits[1] + 0.5);
        q[j.child] = rng.random_range(lo..hi);
    }
    follow(joints, &mut q);
    q
}

#[test]
fn urdf_fk_matches_chain_fk() {
    let rs = results();
    if rs.is_empty() {
        eprintln!("skip: bench-dev not present");
        return;
    }
    let mut rng = StdRng::seed_from_u64(7);
    for (name, res, pts) in rs {
        let text = export(&res, &pts, &name, Geometry::Box, "").unwrap().urdf;
        // The gripper's fingers move together (their true states are equal); no joint of
        // the arm or the quadruped follows another.
        let mimics = text.matches("<mimic ").count();
        assert_eq!(mimics, usize::from(name.starts_with("panda")), "{name}");
        let chain = Chain::from_result(&res).unwrap();
        let mut worst: f64 = 0.0;
        for _ in 0..10 {
            let q = random_states(&res, &mut rng);
            let named = leader_values(&res, &q);
            let got = urdf_fk(&text, &named);
            let root = res.tree.as_ref().unwrap().root;
            for (p, e) in expected(&res, &chain, &q).iter().enumerate() {
                // the URDF base link sits at the root's link origin
                let base = expected(&res, &chain, &q)[root];
                let g = base * got[&link_name(p)];
                worst = worst.max(
                    (g - *e)
                        .to_cols_array()
                        .iter()
                        .fold(0.0f64, |a, b| a.max(b.abs())),
                );
            }
        }
        eprintln!("{name}: max |URDF FK − Chain FK| = {worst:.2e}");
        assert!(worst < 1e-6, "{name}: {worst}");
    }
}

/// The largest |a[i] − b[i]|.
fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

/// What `tests/urdf_check.py` prints.
#[derive(serde::Deserialize)]
struct Read {
    poses: HashMap<String, Vec<f64>>,
    meshes: HashMap<String, MeshRead>,
}

#[derive(serde::Deserialize, Debug)]
struct MeshRead {
    volume: f64,
    watertight: bool,
    center_mass: Vec<f64>,
    inertia: Vec<f64>,
    inertial_origin: Vec<f64>,
    mass: f64,
    inertia_urdf: Vec<f64>,
}

#[test]
fn urdf_loads_in_yourdfpy_with_matching_fk() {
    if !python_common::python_has("yourdfpy") {
        return;
    }
    let rs = results();
    if rs.is_empty() {
        eprintln!("skip: bench-dev not present");
        return;
    }
    let dir = std::env::temp_dir().join(format!("gsart_kin_urdf_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut rng = StdRng::seed_from_u64(9);
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/urdf_check.py");
    for (name, res, pts) in rs {
        let mesh_dir = format!("{name}_meshes");
        let files = export(&res, &pts, &name, Geometry::Hull, &mesh_dir).unwrap();
        let urdf = dir.join(format!("{name}.urdf"));
        std::fs::write(&urdf, &files.urdf).unwrap();
        std::fs::create_dir_all(dir.join(&mesh_dir)).unwrap();
        for m in &files.meshes {
            std::fs::write(dir.join(&m.path), &m.bytes).unwrap();
        }
        // Every part with points spanning a volume has its hull.
        let solid = pts.iter().filter(|p| p.len() >= 4).count();
        assert_eq!(files.meshes.len(), solid, "{name}: a mesh per part");
        let q = random_states(&res, &mut rng);
        let named = leader_values(&res, &q);
        let sfile = dir.join(format!("{name}.json"));
        std::fs::write(&sfile, serde_json::to_string(&named).unwrap()).unwrap();
        let out = std::process::Command::new("python3")
            .arg(script)
            .arg(&urdf)
            .arg(&sfile)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let read: Read = serde_json::from_slice(&out.stdout).unwrap();
        let poses = read.poses;
        assert_eq!(
            read.meshes.len(),
            files.meshes.len(),
            "{name}: yourdfpy loads every mesh"
        );
        for (link, m) in &read.meshes {
            assert!(m.watertight && m.volume > 0.0, "{name} {link}: {m:?}");
            assert_eq!(m.mass, 1.0);
            let size = m.volume.lcbrt();
            let com = max_abs_diff(&m.center_mass, &m.inertial_origin);
            assert!(
                com < 1e-5 * size,
                "{name} {link}: centre of mass {:?} against {:?}",
                m.center_mass,
                m.inertial_origin
            );
            let scale = m.inertia.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            let di = max_abs_diff(&m.inertia, &m.inertia_urdf);
            assert!(
                di < 1e-4 * scale,
                "{name} {link}: inertia {:?} against {:?}",
                m.inertia,
                m.inertia_urdf
            );
        }
        let chain = Chain::from_result(&res).unwrap();
        let exp = expected(&res, &chain, &q);
        let root = res.tree.as_ref().unwrap().root;
        let mut worst: f64 = 0.0;
        for (p, e) in exp.iter().enumerate() {
            let g = &poses[&link_name(p)];
            let m = to_row_major(&(exp[root].inverse() * *e));
            worst = worst.max(max_abs_diff(&m, g));
        }
        eprintln!("{name}: yourdfpy max |URDF FK − Chain FK| = {worst:.2e}");
        assert!(worst < 1e-6, "{name}: {worst}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
