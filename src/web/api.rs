//! wasm-bindgen API over the core for the page and its workers: PLY parsing,
//! built-in examples, one Step-1 candidate per worker, finishing (selection and
//! Steps 2–3), metrics, re-posing through forward kinematics, and exports.
//! Only conversions live here; every decision is made by the core.

use glam::{DMat3, DMat4, DVec3, Vec3};
use js_sys::{Float32Array, Object, Reflect, Uint32Array};
use serde::Serialize;
use wasm_bindgen::prelude::*;

use crate::geom::se3::{from_row_major, rigid_inverse};
use crate::io::gt::JointType;
use crate::io::result::FitResult;
use crate::kinematics::chain::Chain;

/// Installs the panic hook so a bug shows a readable message in the console.
#[wasm_bindgen(start)]
pub fn start() {
    console_error_panic_hook::set_once();
}

/// Crate version, shown in the page footer.
#[wasm_bindgen]
pub fn version() -> String {
    env!("CARGO_PKG_VERSION").to_string()
}

// ------------------------------------------------------------------ conversions

fn js_err(e: crate::Error) -> JsError {
    JsError::new(&e.to_string())
}

fn set(obj: &Object, key: &str, value: &JsValue) {
    // Setting a property on a plain fresh object cannot fail.
    let _ = Reflect::set(obj, &JsValue::from_str(key), value);
}

fn to_js<T: Serialize + ?Sized>(v: &T) -> Result<JsValue, JsError> {
    // json_compatible: maps become plain objects, not `Map`s.
    v.serialize(&serde_wasm_bindgen::Serializer::json_compatible())
        .map_err(|e| JsError::new(&format!("internal: cannot convert to JS: {e}")))
}

fn points_from_flat(flat: &[f32], name: &str) -> Result<Vec<Vec3>, JsError> {
    if !flat.len().is_multiple_of(3) {
        return Err(js_err(crate::Error::input(
            name,
            format!("{} coordinates is not a multiple of 3", flat.len()),
        )));
    }
    Ok(flat
        .chunks_exact(3)
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .collect())
}

// ------------------------------------------------------------------ the model

/// A result opened for viewing: re-posing through the core's forward kinematics
/// (the same code path as the CLI's `articulate` and the metrics), and exports.
#[wasm_bindgen]
pub struct Model {
    result: FitResult,
    chain: Option<Chain>,
    /// Input points per frame when the page has them (labels[k] order).
    frame_points: Vec<Option<Vec<Vec3>>>,
    /// Points of the canonical frame carried by the file itself (`canonical_points`).
    canonical_points: Option<Vec<Vec3>>,
    /// `inv_poses[k][p]`: inverse of poses[k][p], to bring frame k back to frame c.
    inv_poses: Vec<Vec<DMat4>>,
}

/// The extra key the page's export writes so a shared result can be viewed without
/// its frames: the canonical frame's points, flat xyz (other readers ignore it).
const POINTS_KEY: &str = "canonical_points";

#[wasm_bindgen]
impl Model {
    /// Opens a result JSON (format `gsart-result`, version 1). `file` names it in errors.
    pub fn from_json(text: &str, file: &str) -> Result<Model, JsError> {
        let result = FitResult::from_json(text, file).map_err(js_err)?;
        let mut canonical_points = None;
        if let Ok(value) = serde_json::from_str::<serde_json::Value>(text) {
            if let Some(arr) = value.get(POINTS_KEY).and_then(|v| v.as_array()) {
                let flat: Vec<f32> = arr
                    .iter()
                    .filter_map(|v| v.as_f64())
                    .map(|v| v as f32)
                    .collect();
                let n = result.labels[result.canonical_frame].len();
                if flat.len() != arr.len() || flat.len() != 3 * n {
                    return Err(js_err(crate::Error::input(
                        file,
                        format!("{POINTS_KEY} has {} numbers, expected 3 × {n}", arr.len()),
                    )));
                }
                canonical_points = Some(points_from_flat(&flat, file)?);
            }
        }
        Model::new(result, canonical_points, file)
    }

    /// Frames K.
    pub fn frames(&self) -> usize {
        self.result.frames
    }
    /// Parts P.
    pub fn parts(&self) -> usize {
        self.result.parts
    }
    pub fn canonical_frame(&self) -> usize {
        self.result.canonical_frame
    }
    pub fn has_tree(&self) -> bool {
        self.chain.is_some()
    }
    /// True when points can be shown for every frame (loaded frames or the file's own).
    pub fn has_points(&self) -> bool {
        self.canonical_points.is_some() || self.frame_points.iter().all(|f| f.is_some())
    }
    /// Root part (0 without a tree).
    pub fn root(&self) -> usize {
        self.result.tree.as_ref().map_or(0, |t| t.root)
    }
    /// Parent per part (−1 for the root); empty without a tree.
    pub fn parents(&self) -> Vec<i32> {
        self.result
            .tree
            .as_ref()
            .map(|t| t.parent.iter().map(|&p| p as i32).collect())
            .unwrap_or_default()
    }
    /// Number of labelled input points of frame k.
    pub fn label_count(&self, k: usize) -> usize {
        self.result.labels.get(k).map_or(0, |l| l.len())
    }
    /// Joints: `[{child, parent, type, axis, pivot, limits, state}]`.
    pub fn joints(&self) -> Result<JsValue, JsError> {
        to_js(self.result.joints.as_deref().unwrap_or(&[]))
    }
    pub fn joint_count(&self) -> usize {
        self.result.joints.as_ref().map_or(0, |j| j.len())
    }
    /// The free-form `info` object (options, chosen m, notes), or null.
    pub fn info(&self) -> Result<JsValue, JsError> {
        match &self.result.info {
            Some(v) => to_js(v),
            None => Ok(JsValue::NULL),
        }
    }

    /// Attaches the input points of frame k (they must match `labels[k]`).
    pub fn set_frame_points(&mut self, k: usize, points: &[f32]) -> Result<(), JsError> {
        let n = self.label_count(k);
        if k >= self.result.frames || points.len() != 3 * n {
            return Err(JsError::new(&format!(
                "frame {k}: {} coordinates, the result labels {n} points",
                points.len()
            )));
        }
        self.frame_points[k] = Some(points_from_flat(points, "frame")?);
        Ok(())
    }

    /// Joint states of frame k, indexed by child part (0 for parts without a joint).
    pub fn frame_states(&self, k: usize) -> Vec<f64> {
        self.result.joint_states(k)
    }

    /// Labels of the points [`Model::pose_points`] returns for frame k.
    pub fn labels(&self, k: usize) -> Result<Uint32Array, JsError> {
        let (_, src) = self.source(k)?;
        Ok(Uint32Array::from(self.result.labels[src].as_slice()))
    }

    /// The points of frame k moved to joint states `states` (indexed by child part):
    /// each point goes back to the canonical frame with its part's fitted pose, then
    /// forward with the chain's forward kinematics. At the frame's own states this
    /// reproduces the input.
    pub fn pose_points(&self, k: usize, states: &[f64]) -> Result<Float32Array, JsError> {
        let moves = self.part_moves(k, states)?;
        let (points, src) = self.source(k)?;
        let labels = &self.result.labels[src];
        let m32: Vec<glam::Mat4> = moves.iter().map(|m| m.as_mat4()).collect();
        let mut flat = Vec::with_capacity(points.len() * 3);
        for (x, &l) in points.iter().zip(labels) {
            let y = m32[l as usize].transform_point3(*x);
            flat.extend_from_slice(&[y.x, y.y, y.z]);
        }
        Ok(Float32Array::from(flat.as_slice()))
    }

    /// The Gaussians at frame k re-posed like [`Model::pose_points`]:
    /// `{centers, rotations (m×9 row-major), scales, parts}`, or null when the result has none.
    pub fn pose_gaussians(&self, k: usize, states: &[f64]) -> Result<JsValue, JsError> {
        let Some(gs) = &self.result.gaussians else {
            return Ok(JsValue::NULL);
        };
        let moves = self.part_moves(k, states)?;
        let n = gs.len();
        let (mut c, mut r, mut s, mut parts) = (
            Vec::with_capacity(3 * n),
            Vec::with_capacity(9 * n),
            Vec::with_capacity(3 * n),
            Vec::with_capacity(n),
        );
        for g in gs {
            let (Some(ctr), Some(rot)) = (g.center.get(k), g.rotation.get(k)) else {
                continue;
            };
            let mv = moves[g.part];
            let y = mv.transform_point3(DVec3::from(*ctr));
            let rm = DMat3::from_mat4(mv) * DMat3::from_cols_array(rot).transpose();
            // back to row-major
            let rows = rm.transpose().to_cols_array();
            c.extend(y.to_array().iter().map(|&v| v as f32));
            r.extend(rows.iter().map(|&v| v as f32));
            s.extend(g.scale.iter().map(|&v| v as f32));
            parts.push(g.part as u32);
        }
        let o = Object::new();
        set(&o, "centers", &Float32Array::from(c.as_slice()));
        set(&o, "rotations", &Float32Array::from(r.as_slice()));
        set(&o, "scales", &Float32Array::from(s.as_slice()));
        set(&o, "parts", &Uint32Array::from(parts.as_slice()));
        Ok(o.into())
    }

    /// Joint axes at frame k and states: `{origins, dirs, kinds (0 revolute, 1
    /// prismatic), children}`; each axis moves with its parent part.
    pub fn joint_axes(&self, k: usize, states: &[f64]) -> Result<JsValue, JsError> {
        let poses = self.poses_at(k, states)?;
        let joints = self.result.joints.as_deref().unwrap_or(&[]);
        let (mut o, mut d, mut kinds, mut children) = (vec![], vec![], vec![], vec![]);
        for j in joints {
            let Some(t) = poses.get(j.parent) else {
                continue;
            };
            let p = t.transform_point3(DVec3::from(j.pivot));
            let a = t.transform_vector3(DVec3::from(j.axis)).normalize_or_zero();
            o.extend(p.to_array().iter().map(|&v| v as f32));
            d.extend(a.to_array().iter().map(|&v| v as f32));
            kinds.push(match j.joint_type {
                JointType::Revolute => 0u32,
                JointType::Prismatic => 1u32,
            });
            children.push(j.child as u32);
        }
        let out = Object::new();
        set(&out, "origins", &Float32Array::from(o.as_slice()));
        set(&out, "dirs", &Float32Array::from(d.as_slice()));
        set(&out, "kinds", &Uint32Array::from(kinds.as_slice()));
        set(&out, "children", &Uint32Array::from(children.as_slice()));
        Ok(out.into())
    }

    /// The result JSON; with `with_points`, the canonical frame's points are added under
    /// `canonical_points` so the file opens on its own (`?model=URL`).
    pub fn to_json(&self, with_points: bool) -> Result<String, JsError> {
        let text = self.result.to_json();
        if !with_points {
            return Ok(text);
        }
        let c = self.result.canonical_frame;
        let Some(points) = self.frame_points[c]
            .as_ref()
            .or(self.canonical_points.as_ref())
        else {
            return Ok(text);
        };
        let mut value: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| JsError::new(&format!("internal: result JSON: {e}")))?;
        // 1e-6 of the object's size is far below any sensor noise and keeps files small.
        let round = |v: f32| ((v as f64) * 1e6).round() / 1e6;
        let flat: Vec<f64> = points
            .iter()
            .flat_map(|p| [round(p.x), round(p.y), round(p.z)])
            .collect();
        if let serde_json::Value::Object(map) = &mut value {
            map.insert(POINTS_KEY.to_string(), serde_json::json!(flat));
        }
        serde_json::to_string(&value).map_err(|e| JsError::new(&format!("internal: {e}")))
    }
}

impl Model {
    fn new(
        result: FitResult,
        canonical_points: Option<Vec<Vec3>>,
        file: &str,
    ) -> Result<Model, JsError> {
        let chain = match &result.tree {
            Some(_) => Some(
                Chain::from_result(&result).map_err(|e| JsError::new(&format!("{file}: {e}")))?,
            ),
            None => None,
        };
        let inv_poses = result
            .poses
            .iter()
            .map(|f| {
                f.iter()
                    .map(|m| rigid_inverse(&from_row_major(m)))
                    .collect()
            })
            .collect();
        Ok(Model {
            frame_points: vec![None; result.frames],
            result,
            chain,
            canonical_points,
            inv_poses,
        })
    }

    fn pose_of(&self, k: usize, p: usize) -> Option<DMat4> {
        self.result.pose(k, p)
    }

    /// Points shown for frame k and the frame whose labels they carry.
    fn source(&self, k: usize) -> Result<(&[Vec3], usize), JsError> {
        if k >= self.result.frames {
            return Err(JsError::new(&format!(
                "frame {k} does not exist (the result has {})",
                self.result.frames
            )));
        }
        if let Some(p) = &self.frame_points[k] {
            return Ok((p, k));
        }
        let c = self.result.canonical_frame;
        if let Some(p) = self.frame_points[c]
            .as_ref()
            .or(self.canonical_points.as_ref())
        {
            return Ok((p, c));
        }
        Err(JsError::new(
            "this result carries no points: load its frames to view it",
        ))
    }

    /// Part poses (canonical → posed) at frame k's root motion and `states`.
    fn poses_at(&self, k: usize, states: &[f64]) -> Result<Vec<DMat4>, JsError> {
        let n = self.result.parts;
        match &self.chain {
            Some(chain) => {
                let root = self.result.root_pose(k).unwrap_or(DMat4::IDENTITY);
                chain.part_poses(&root, states).map_err(js_err)
            }
            // Step 1 only: no joints to move, the fitted poses stand.
            None => Ok((0..n)
                .map(|p| self.pose_of(k, p).unwrap_or(DMat4::IDENTITY))
                .collect()),
        }
    }

    /// Per part, the motion applied to the points shown for frame k: back to the
    /// canonical frame with the fitted pose (when they are frame k's own points),
    /// then forward kinematics at `states`.
    fn part_moves(&self, k: usize, states: &[f64]) -> Result<Vec<DMat4>, JsError> {
        let poses = self.poses_at(k, states)?;
        let (_, src) = self.source(k)?;
        Ok(poses
            .iter()
            .enumerate()
            .map(|(p, t)| *t * self.inv_poses[src][p])
            .collect())
    }
}
