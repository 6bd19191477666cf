//! Procedural articulated objects (laptop, cabinet, arm, hand, quadruped) with exact
//! ground truth in the benchmark format (`bench-dev/README.md`), occluded variants
//! (hidden point removal from a random camera) and held-out novel poses.
//!
//! Pure computation, no file I/O: the page uses it for its built-in examples, the CLI
//! writes the result with `write` (PLY frames + `gt.json`). Deterministic for a seed
//! on every platform (seeded `StdRng` streams, no hash-order dependence).

pub mod objects;
pub mod occlusion;
pub mod shapes;
pub mod trajectory;
pub mod write;

pub use write::{write_sequence_dir, write_sequence_dir_with};

use std::fmt;
use std::str::FromStr;

use glam::{DMat3, DMat4, DQuat, DVec3, Vec3};
use rand::{rngs::StdRng, Rng, SeedableRng};
use serde_json::{json, Value};

use crate::geom::se3::to_nested;
use crate::io::gt::{GroundTruth, GtJoint, JointType};
use crate::io::sequence::{Frame, Sequence};
use crate::math::Libm;
use objects::ObjectModel;

/// Rotation by `angle` about the unit `axis` (trigonometry from `crate::math`, so
/// generated sequences are bit-identical natively and in wasm).
pub(crate) fn axis_angle(axis: DVec3, angle: f64) -> glam::DQuat {
    let (s, c) = ((angle * 0.5).lsin(), (angle * 0.5).lcos());
    glam::DQuat::from_xyzw(axis.x * s, axis.y * s, axis.z * s, c)
}

/// The built-in procedural objects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ObjectKind {
    Laptop,
    Cabinet,
    Arm,
    Hand,
    Quadruped,
}

impl ObjectKind {
    pub const ALL: [ObjectKind; 5] = [
        ObjectKind::Laptop,
        ObjectKind::Cabinet,
        ObjectKind::Arm,
        ObjectKind::Hand,
        ObjectKind::Quadruped,
    ];

    pub fn name(self) -> &'static str {
        match self {
            ObjectKind::Laptop => "laptop",
            ObjectKind::Cabinet => "cabinet",
            ObjectKind::Arm => "arm",
            ObjectKind::Hand => "hand",
            ObjectKind::Quadruped => "quadruped",
        }
    }

    /// The object's part tree and shapes (design units).
    pub fn model(self) -> ObjectModel {
        match self {
            ObjectKind::Laptop => objects::laptop(),
            ObjectKind::Cabinet => objects::cabinet(),
            ObjectKind::Arm => objects::arm(),
            ObjectKind::Hand => objects::hand(),
            ObjectKind::Quadruped => objects::quadruped(),
        }
    }

    /// Default points per frame: small objects 2048 (Sapien-like), robots 4096.
    pub fn default_points(self) -> usize {
        match self {
            ObjectKind::Laptop | ObjectKind::Cabinet => 2048,
            _ => 4096,
        }
    }

    /// Short description for menus.
    pub fn describe(self) -> &'static str {
        match self {
            ObjectKind::Laptop => "laptop: base + lid, 1 revolute joint",
            ObjectKind::Cabinet => "cabinet: 2 drawers (prismatic) + door (revolute), 4 parts",
            ObjectKind::Arm => "arm: 6 revolute joints, 7 parts",
            ObjectKind::Hand => "hand: palm + 4 fingers x 3 phalanges, 13 parts",
            ObjectKind::Quadruped => "quadruped: body + 4 legs x 2, 9 parts",
        }
    }
}

impl fmt::Display for ObjectKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ObjectKind {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        let t = s.trim().to_ascii_lowercase();
        ObjectKind::ALL
            .iter()
            .copied()
            .find(|k| k.name() == t)
            .ok_or_else(|| {
                crate::Error::InvalidArgument(format!(
                    "unknown object '{s}' (expected one of: {})",
                    example_names().join(", ")
                ))
            })
    }
}

/// Names of the built-in examples, in menu order.
pub fn example_names() -> &'static [&'static str] {
    &["laptop", "cabinet", "arm", "hand", "quadruped"]
}

/// Options of [`generate`].
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    pub kind: ObjectKind,
    /// Frames K (≥ 2).
    pub frames: usize,
    /// Points per frame before occlusion (≥ 16).
    pub points: usize,
    /// Held-out novel poses.
    pub heldout: usize,
    /// Keep only the points visible from a random camera in each frame.
    pub occluded: bool,
    /// Sensor noise: every frame point moves by a normal offset of this standard
    /// deviation per axis, as a fraction of the object's longest side (0 ≤ σ ≤
    /// [`MAX_NOISE`]; a depth camera a metre from a robot of a metre: about 0.002).
    pub noise: f64,
    /// Flying pixels: this fraction of each frame's points (0 ≤ f ≤ [`MAX_OUTLIERS`])
    /// thrown 5–15 % of the object's longest side off the surface in a random
    /// direction, keeping their part's label.
    pub outliers: f64,
    /// The whole object turns this many degrees a frame about the vertical (z) axis
    /// through its centre, as on a turntable (|turn| ≤ [`MAX_TURN`]; 0: still). The
    /// ground-truth poses turn with it; frame 0 and the held-out poses do not.
    pub turn: f64,
    /// The whole object in an orientation drawn uniformly over all rotations (from the
    /// seed) before the normalisation, as the benchmark generator's `random_rotation`:
    /// the same object and motion, seen from no preferred axis.
    pub random_rotation: bool,
    pub seed: u64,
}

impl SynthOptions {
    /// The page's defaults for an object: 10 frames, its default point count, 3 held-out.
    pub fn new(kind: ObjectKind) -> Self {
        SynthOptions {
            kind,
            frames: 10,
            points: kind.default_points(),
            heldout: 3,
            occluded: false,
            noise: 0.0,
            outliers: 0.0,
            turn: 0.0,
            random_rotation: false,
            seed: 0,
        }
    }
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions::new(ObjectKind::Laptop)
    }
}

/// Extra facts of a generated sequence (the optional keys of the benchmark format).
#[derive(Debug, Clone)]
pub struct SynthInfo {
    pub kind: ObjectKind,
    pub seed: u64,
    pub points_requested: usize,
    pub part_names: Vec<String>,
    /// Per part (None for the root): axis / pivot in the parent's frame, normalised units.
    pub axis_parent: Vec<Option<DVec3>>,
    pub pivot_parent: Vec<Option<DVec3>>,
    pub child_in_parent_at_zero: Vec<Option<DMat4>>,
    /// Sampling range per joint (radians, or normalised units for prismatic joints).
    pub ranges: Vec<Option<(f64, f64)>>,
    /// `x = scale * (x_design - center)`.
    pub scale: f64,
    pub center: DVec3,
    /// Occluded variant: camera per frame (looking at the origin), and for each frame
    /// the indices of the visible points in the full cloud.
    pub cameras: Vec<DVec3>,
    pub visible: Vec<Vec<u32>>,
    pub occlusion_method: Option<occlusion::Method>,
    /// The sensor noise and share of flying pixels the frames were given
    /// (`SynthOptions::noise`, `outliers`).
    pub noise: f64,
    pub outliers: f64,
    /// `SynthOptions::turn`.
    pub turn: f64,
    /// The orientation `SynthOptions::random_rotation` drew (design to world, before
    /// the normalisation), if any.
    pub rotation: Option<DMat3>,
}

/// A generated sequence: observed frames (with part labels), ground truth, and
/// held-out full clouds.
#[derive(Debug, Clone)]
pub struct SynthOutput {
    pub sequence: Sequence,
    pub gt: GroundTruth,
    pub heldout: Vec<Frame>,
    pub info: SynthInfo,
}

/// Largest accepted point count per frame (keeps a mistyped option from exhausting memory).
pub const MAX_POINTS: usize = 2_000_000;
pub const MAX_FRAMES: usize = 1000;
/// Largest sensor noise (σ as a fraction of the object's longest side).
pub const MAX_NOISE: f64 = 0.1;
/// Largest share of flying pixels.
pub const MAX_OUTLIERS: f64 = 0.5;

/// Largest turn a frame (degrees, `SynthOptions::turn`).
pub const MAX_TURN: f64 = 30.0;
/// How far a flying pixel is thrown off the surface, as fractions of the longest side.
const OUTLIER_REACH: (f64, f64) = (0.05, 0.15);

/// Independent seeded stream per purpose, so e.g. the occluded variant samples the
/// same full clouds as the full variant.
fn stream(seed: u64, purpose: u64) -> StdRng {
    // splitmix64 of seed and purpose
    let mut z = seed ^ purpose.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    StdRng::seed_from_u64(z ^ (z >> 31))
}

/// Area-weighted table of all (part, primitive) pairs.
struct Sampler<'a> {
    model: &'a ObjectModel,
    cdf: Vec<f64>,
    index: Vec<(usize, usize)>,
    margin: f64,
}

impl<'a> Sampler<'a> {
    fn new(model: &'a ObjectModel) -> Self {
        let mut cdf = Vec::new();
        let mut index = Vec::new();
        let mut acc = 0.0;
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for (p, part) in model.parts.iter().enumerate() {
            for (k, prim) in part.prims.iter().enumerate() {
                acc += prim.area();
                cdf.push(acc);
                index.push((p, k));
                let (a, b) = prim.bounds();
                lo = lo.min(a);
                hi = hi.max(b);
            }
        }
        Sampler {
            model,
            cdf,
            index,
            margin: 1e-9 * (hi - lo).max_element().max(1e-12),
        }
    }

    /// `n` points uniformly on the union surface of every part, in world coordinates
    /// for the given part poses, with their part labels.
    fn sample(
        &self,
        rng: &mut StdRng,
        poses: &[DMat4],
        n: usize,
    ) -> crate::Result<(Vec<DVec3>, Vec<u32>)> {
        let total = self.cdf.last().copied().unwrap_or(0.0);
        if total <= 0.0 {
            return Err(crate::Error::Sequence("object has no surface".into()));
        }
        let mut pts = Vec::with_capacity(n);
        let mut labels = Vec::with_capacity(n);
        let mut attempts = 0usize;
        while pts.len() < n {
            attempts += 1;
            if attempts > 100 * n + 1000 {
                return Err(crate::Error::Sequence(
                    "surface sampling rejected too many points".into(),
                ));
            }
            let u = rng.random::<f64>() * total;
            let i = self
                .cdf
                .partition_point(|&c| c <= u)
                .min(self.cdf.len() - 1);
            let (p, k) = self.index[i];
            let prims = &self.model.parts[p].prims;
            let x = prims[k].sample(rng);
            // Union surface: drop points buried inside another primitive of the part.
            let buried = prims
                .iter()
                .enumerate()
                .any(|(j, q)| j != k && q.contains(x, self.margin));
            if buried {
                continue;
            }
            pts.push(poses[p].transform_point3(x));
            labels.push(p as u32);
        }
        Ok((pts, labels))
    }
}

fn check(opts: &SynthOptions) -> crate::Result<()> {
    let bad = |m: String| Err(crate::Error::InvalidArgument(m));
    if opts.frames < 2 || opts.frames > MAX_FRAMES {
        return bad(format!(
            "frames must be between 2 and {MAX_FRAMES}, got {}",
            opts.frames
        ));
    }
    if opts.points < 16 || opts.points > MAX_POINTS {
        return bad(format!(
            "points per frame must be between 16 and {MAX_POINTS}, got {}",
            opts.points
        ));
    }
    if opts.heldout > MAX_FRAMES {
        return bad(format!(
            "held-out poses must be at most {MAX_FRAMES}, got {}",
            opts.heldout
        ));
    }
    if !(0.0..=MAX_NOISE).contains(&opts.noise) {
        return bad(format!(
            "noise must be between 0 and {MAX_NOISE} (a fraction of the object's size), got {}",
            opts.noise
        ));
    }
    if !(0.0..=MAX_OUTLIERS).contains(&opts.outliers) {
        return bad(format!(
            "the share of outliers must be between 0 and {MAX_OUTLIERS}, got {}",
            opts.outliers
        ));
    }
    if !(-MAX_TURN..=MAX_TURN).contains(&opts.turn) {
        return bad(format!(
            "the turn must be between -{MAX_TURN} and {MAX_TURN} degrees a frame, got {}",
            opts.turn
        ));
    }
    Ok(())
}

/// Pose in normalised units: `x' = s (x − c)` keeps rotations, scales translations.
fn normalise_pose(m: &DMat4, s: f64, c: DVec3) -> DMat4 {
    let r = DMat3::from_mat4(*m);
    let t = m.w_axis.truncate();
    DMat4::from_mat3_translation(r, (t - c) * s)
}

fn to_frame(name: String, pts: &[DVec3], labels: Vec<u32>, s: f64, c: DVec3) -> Frame {
    Frame {
        name,
        points: pts
            .iter()
            .map(|p| {
                let q = (*p - c) * s;
                Vec3::new(q.x as f32, q.y as f32, q.z as f32)
            })
            .collect(),
        labels: Some(labels),
    }
}

/// A standard normal draw (Box–Muller, with `crate::math`'s functions so that the draws
/// are the same natively and in wasm).
fn normal(rng: &mut StdRng) -> f64 {
    let u = 1.0 - rng.random::<f64>(); // (0, 1]: ln stays finite
    let v = rng.random::<f64>();
    (-2.0 * u.lln()).sqrt() * (std::f64::consts::TAU * v).lcos()
}

/// Moves every point by a normal offset of standard deviation `sigma` per axis, and
/// throws each point, with probability `outliers`, `OUTLIER_REACH` off in a random
/// direction (normalised units: the object's longest side is 1).
fn perturb(points: &mut [Vec3], sigma: f64, outliers: f64, rng: &mut StdRng) {
    for p in points {
        let mut q = p.as_dvec3();
        if sigma > 0.0 {
            q += DVec3::new(normal(rng), normal(rng), normal(rng)) * sigma;
        }
        if outliers > 0.0 && rng.random::<f64>() < outliers {
            let dir = DVec3::new(normal(rng), normal(rng), normal(rng)).normalize_or(DVec3::X);
            let (lo, hi) = OUTLIER_REACH;
            q += dir * (lo + (hi - lo) * rng.random::<f64>());
        }
        *p = q.as_vec3();
    }
}

/// Generate one sequence.
pub fn generate(opts: &SynthOptions) -> crate::Result<SynthOutput> {
    check(opts)?;
    let model = opts.kind.model();
    let np = model.num_parts();
    let k = opts.frames;
    let h = opts.heldout;

    // Joint trajectories (design units) and held-out states, one stream each.
    let mut traj_rng = stream(opts.seed, 1);
    let mut held_rng = stream(opts.seed, 3);
    let mut states = vec![vec![0.0; k]; np];
    let mut held_states = vec![vec![0.0; h]; np];
    for p in model.joint_parts() {
        if let Some(j) = &model.parts[p].joint {
            states[p] = trajectory::smooth_states(&mut traj_rng, k, j.range);
            held_states[p] = (0..h)
                .map(|_| trajectory::random_state(&mut held_rng, j.range))
                .collect();
        }
    }
    let at = |s: &Vec<Vec<f64>>, t: usize| s.iter().map(|v| v[t]).collect::<Vec<f64>>();
    // The object's orientation: the identity, or one drawn uniformly over rotations
    // (a normalised 4-D normal draw is a uniform unit quaternion).
    let rotation = opts.random_rotation.then(|| {
        let mut rot_rng = stream(opts.seed, 6);
        let q = [(); 4].map(|_| normal(&mut rot_rng));
        DMat3::from_quat(DQuat::from_xyzw(q[0], q[1], q[2], q[3]).normalize())
    });
    let root = rotation.map_or(DMat4::IDENTITY, DMat4::from_mat3);
    let poses: Vec<Vec<DMat4>> = (0..k)
        .map(|t| model.forward(root, &at(&states, t)))
        .collect();
    // Held-out root pose = frame 0's root pose.
    let held_poses: Vec<Vec<DMat4>> = (0..h)
        .map(|i| model.forward(poses[0][0], &at(&held_states, i)))
        .collect();

    // Independent surface samples per frame.
    let sampler = Sampler::new(&model);
    let mut sample_rng = stream(opts.seed, 2);
    let mut clouds = Vec::with_capacity(k);
    for pose in &poses {
        clouds.push(sampler.sample(&mut sample_rng, pose, opts.points)?);
    }
    let mut held_clouds = Vec::with_capacity(h);
    for pose in &held_poses {
        held_clouds.push(sampler.sample(&mut sample_rng, pose, opts.points)?);
    }

    // Normalisation over all observed frames: centre the bounding box, longest side 1.
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for (pts, _) in &clouds {
        for p in pts {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    let extent = (hi - lo).max_element();
    if !(extent.is_finite() && extent > 0.0) {
        return Err(crate::Error::Sequence("degenerate object extent".into()));
    }
    // A hair under 1 so that f32 rounding keeps every coordinate inside [-0.5, 0.5].
    let s = (1.0 - 1e-6) / extent;
    let c = (lo + hi) * 0.5;

    // The turntable (`SynthOptions::turn`) turns frame t about z through the centre.
    let turned = |t: usize| DMat4::from_rotation_z((opts.turn * t as f64).to_radians());
    let norm_poses: Vec<Vec<DMat4>> = poses
        .iter()
        .enumerate()
        .map(|(t, f)| {
            f.iter()
                .map(|m| turned(t) * normalise_pose(m, s, c))
                .collect()
        })
        .collect();
    let norm_held: Vec<Vec<DMat4>> = held_poses
        .iter()
        .map(|f| f.iter().map(|m| normalise_pose(m, s, c)).collect())
        .collect();

    // Ground truth joints (normalised units).
    let mut joints: Vec<Option<GtJoint>> = vec![None; np];
    let mut axis_parent = vec![None; np];
    let mut pivot_parent = vec![None; np];
    let mut cip = vec![None; np];
    let mut ranges = vec![None; np];
    let mut parent = vec![-1i64; np];
    for (p, part) in model.parts.iter().enumerate() {
        let (Some(j), Some(par)) = (&part.joint, part.parent) else {
            continue;
        };
        parent[p] = par as i64;
        let unit = match j.joint_type {
            JointType::Revolute => 1.0,
            JointType::Prismatic => s,
        };
        let parent0 = norm_poses[0][par];
        let pivot_p = j.pivot * s;
        joints[p] = Some(GtJoint {
            part: p,
            parent_part: par,
            name: j.name.clone(),
            joint_type: j.joint_type,
            axis_world_frame0: DMat3::from_mat4(parent0) * j.axis,
            pivot_world_frame0: parent0.transform_point3(pivot_p),
            states: states[p].iter().map(|q| q * unit).collect(),
            heldout_states: held_states[p].iter().map(|q| q * unit).collect(),
        });
        axis_parent[p] = Some(j.axis);
        pivot_parent[p] = Some(pivot_p);
        cip[p] = Some(DMat4::from_translation(pivot_p));
        ranges[p] = Some((j.range.0 * unit, j.range.1 * unit));
    }

    let frame_names: Vec<String> = (0..k).map(|t| format!("frame_{t:03}.ply")).collect();
    let held_names: Vec<String> = (0..h)
        .map(|i| format!("heldout/frame_{i:03}.ply"))
        .collect();
    let mut frames: Vec<Frame> = clouds
        .into_iter()
        .zip(&frame_names)
        .map(|((pts, labels), name)| to_frame(name.clone(), &pts, labels, s, c))
        .collect();
    if opts.turn != 0.0 {
        // Before the occlusion: the camera sees the object turn.
        for (t, frame) in frames.iter_mut().enumerate() {
            let w = turned(t);
            for p in &mut frame.points {
                *p = w.transform_point3(p.as_dvec3()).as_vec3();
            }
        }
    }
    let heldout: Vec<Frame> = held_clouds
        .into_iter()
        .zip(&held_names)
        .map(|((pts, labels), name)| to_frame(name.clone(), &pts, labels, s, c))
        .collect();

    // Occlusion: visible subset per frame from a camera at distance 2 drifting smoothly
    // around the object.
    let mut cameras = Vec::new();
    let mut visible = Vec::new();
    let mut method = None;
    if opts.occluded {
        let mut cam_rng = stream(opts.seed, 4);
        let az0 = cam_rng.random::<f64>() * std::f64::consts::TAU;
        let az = trajectory::smooth_states(&mut cam_rng, k, (-1.0, 1.0));
        let el = trajectory::smooth_states(&mut cam_rng, k, (-0.25, 0.85));
        for (t, frame) in frames.iter_mut().enumerate() {
            let (a, e) = (az0 + az[t], el[t]);
            let cam = DVec3::new(e.lcos() * a.lcos(), e.lcos() * a.lsin(), e.lsin()) * 2.0;
            let pts: Vec<DVec3> = frame.points.iter().map(|p| p.as_dvec3()).collect();
            let (mask, m) = occlusion::visible(&pts, cam);
            // Report the weaker method if any frame needed the fallback.
            if method != Some(occlusion::Method::ZBuffer) {
                method = Some(m);
            }
            let idx: Vec<u32> = (0..pts.len() as u32)
                .filter(|&i| mask[i as usize])
                .collect();
            let labels = frame.labels.take().unwrap_or_default();
            frame.points = idx.iter().map(|&i| frame.points[i as usize]).collect();
            frame.labels = Some(idx.iter().map(|&i| labels[i as usize]).collect());
            cameras.push(cam);
            visible.push(idx);
        }
    }

    // Sensor noise and flying pixels on what the camera sees (the held-out clouds, the
    // re-animation error's truth, stay exact).
    if opts.noise > 0.0 || opts.outliers > 0.0 {
        let mut noise_rng = stream(opts.seed, 5);
        for frame in &mut frames {
            perturb(&mut frame.points, opts.noise, opts.outliers, &mut noise_rng);
        }
    }

    let gt = GroundTruth {
        sequence: format!("{}_{:02}", opts.kind, opts.seed),
        num_parts: np,
        parent,
        poses: norm_poses,
        joints,
        heldout_frames: held_names,
        heldout_poses: norm_held,
        variant: if opts.occluded { "occluded" } else { "full" }.to_string(),
        frames: frame_names,
    };
    Ok(SynthOutput {
        sequence: Sequence { frames },
        gt,
        heldout,
        info: SynthInfo {
            kind: opts.kind,
            seed: opts.seed,
            points_requested: opts.points,
            part_names: model.parts.iter().map(|p| p.name.clone()).collect(),
            axis_parent,
            pivot_parent,
            child_in_parent_at_zero: cip,
            ranges,
            scale: s,
            center: c,
            cameras,
            visible,
            occlusion_method: method,
            noise: opts.noise,
            outliers: opts.outliers,
            turn: opts.turn,
            rotation,
        },
    })
}

/// `gt.json` text: the keys [`GroundTruth::to_json`] writes plus the optional keys of
/// the benchmark format (parts, normalisation, per-joint parent-frame axis/pivot,
/// point counts, occlusion cameras). `GroundTruth::from_json` reads it back.
pub fn gt_json(out: &SynthOutput) -> String {
    let base = out.gt.to_json();
    let Ok(Value::Object(mut map)) = serde_json::from_str::<Value>(&base) else {
        return base;
    };
    let info = &out.info;
    let np = out.gt.num_parts;
    let v3 = |v: DVec3| json!([v.x, v.y, v.z]);
    map.insert("robot".into(), json!(info.kind.name()));
    map.insert("robot_kind".into(), json!(info.kind.describe()));
    map.insert(
        "source".into(),
        json!({"package": "gsart", "geometry": "procedural primitives (boxes, cylinders, capsules, spheres)"}),
    );
    map.insert("seed".into(), json!(info.seed));
    map.insert("num_frames".into(), json!(out.gt.num_frames()));
    map.insert("num_heldout".into(), json!(out.heldout.len()));
    map.insert(
        "points_per_frame_requested".into(),
        json!(info.points_requested),
    );
    map.insert(
        "normalization".into(),
        json!({"scale": info.scale, "center": v3(info.center),
               "note": "x = scale * (x_design - center); all coordinates, poses and prismatic states are in these normalised units"}),
    );
    map.insert(
        "base_motion".into(),
        if info.turn == 0.0 {
            json!("none")
        } else {
            json!({"type": "turntable", "degrees_per_frame": info.turn, "axis": [0.0, 0.0, 1.0],
                   "note": "frame t is turned by degrees_per_frame · t about the axis through the origin; the poses include it, frame 0 and the held-out poses are not turned"})
        },
    );
    map.insert("random_rotation".into(), json!(info.rotation.is_some()));
    if let Some(r) = info.rotation {
        map.insert(
            "rotation".into(),
            json!({"matrix": r.transpose().to_cols_array_2d(),
                   "note": "the design-frame object was rotated by this row-major matrix (about the origin) before the normalisation"}),
        );
    }
    let counts = |f: &Frame| {
        let mut c = vec![0usize; np];
        for &l in f.labels.iter().flatten() {
            if let Some(x) = c.get_mut(l as usize) {
                *x += 1;
            }
        }
        c
    };
    let all_counts: Vec<Vec<usize>> = out.heldout.iter().map(counts).collect();
    let total: usize = all_counts.iter().flatten().sum();
    let mut area = vec![0usize; np];
    for c in &all_counts {
        for (a, x) in area.iter_mut().zip(c) {
            *a += x;
        }
    }
    map.insert(
        "parts".into(),
        Value::Array(
            (0..np)
                .map(|p| {
                    json!({"index": p, "name": info.part_names.get(p), "links": [info.part_names.get(p)],
                           "parent": out.gt.parent[p],
                           "area_fraction": if total > 0 { area[p] as f64 / total as f64 } else { 0.0 }})
                })
                .collect(),
        ),
    );
    map.insert(
        "points_per_frame".into(),
        json!(out
            .sequence
            .frames
            .iter()
            .map(|f| f.points.len())
            .collect::<Vec<_>>()),
    );
    map.insert(
        "part_point_counts".into(),
        json!(out.sequence.frames.iter().map(counts).collect::<Vec<_>>()),
    );
    map.insert(
        "pose_convention".into(),
        json!("x_world = T[:3,:3] @ x_part + T[:3,3]; points of part p move from frame k to frame t by poses[t][p] @ inv(poses[k][p]); poses[t][child] = poses[t][parent] @ M(q_t) @ child_in_parent_at_zero"),
    );
    if let Some(Value::Array(js)) = map.get_mut("joints") {
        for (p, j) in js.iter_mut().enumerate() {
            let Value::Object(o) = j else { continue };
            if let (Some(a), Some(piv), Some(m), Some(r)) = (
                info.axis_parent[p],
                info.pivot_parent[p],
                info.child_in_parent_at_zero[p],
                info.ranges[p],
            ) {
                o.insert("axis_parent".into(), v3(a));
                o.insert("pivot_parent".into(), v3(piv));
                o.insert("child_in_parent_at_zero".into(), json!(to_nested(&m)));
                o.insert("sampling_range".into(), json!([r.0, r.1]));
                o.insert("mimic".into(), Value::Null);
            }
        }
    }
    if !info.cameras.is_empty() {
        let invisible: Vec<Vec<usize>> = out
            .sequence
            .frames
            .iter()
            .map(|f| {
                counts(f)
                    .iter()
                    .enumerate()
                    .filter(|(_, &c)| c == 0)
                    .map(|(p, _)| p)
                    .collect()
            })
            .collect();
        let method = match info.occlusion_method {
            Some(occlusion::Method::ZBuffer) => {
                "z-buffer splat visibility (hidden point removal hull failed on some frame)"
                    .to_string()
            }
            _ => format!(
                "hidden point removal (Katz et al. 2007), spherical flipping radius = {} x max camera distance",
                occlusion::HPR_RADIUS_FACTOR
            ),
        };
        map.insert(
            "occlusion".into(),
            json!({"method": method,
                   "camera_positions": info.cameras.iter().map(|c| v3(*c)).collect::<Vec<_>>(),
                   "look_at": [0.0, 0.0, 0.0],
                   "invisible_parts": invisible}),
        );
    }
    if info.noise > 0.0 || info.outliers > 0.0 {
        map.insert(
            "sensor_noise".into(),
            json!({"sigma": info.noise, "outlier_fraction": info.outliers,
                   "outlier_reach": [OUTLIER_REACH.0, OUTLIER_REACH.1],
                   "note": "input frames only (held-out clouds are exact): every point moved by N(0, sigma²) per axis, and each point with probability outlier_fraction thrown outlier_reach off in a random direction, keeping its part; normalised units"}),
        );
    }
    serde_json::to_string_pretty(&Value::Object(map)).unwrap_or(base)
}
