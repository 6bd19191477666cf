//! wasm-bindgen API over the core for the page and its workers: PLY parsing,
//! built-in examples, one Step-1 candidate per worker, finishing (selection and
//! Steps 2–3), metrics, re-posing through forward kinematics, and exports.
//! Only conversions live here; every decision is made by the core.

use glam::{DMat3, DMat4, DVec3, Vec3};
use js_sys::{Array, Float32Array, Function, Object, Reflect, Uint32Array, Uint8Array};
use serde::Serialize;
use std::cell::RefCell;

use wasm_bindgen::prelude::*;

use crate::fit::Step1Result;
use crate::geom::se3::{from_row_major, rigid_inverse};
use crate::io::gt::{GroundTruth, JointType};
use crate::io::ply::write_ply;
use crate::io::result::FitResult;
use crate::io::sequence::{natural_cmp, Frame, LoadOptions, Sequence};
use crate::kinematics::chain::Chain;
use crate::pipeline::{Control, FitOptions, Progress, Stage};
use crate::synth::{self, ObjectKind, SynthOptions};

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

fn flat_points(points: &[Vec3]) -> Float32Array {
    let mut flat = Vec::with_capacity(points.len() * 3);
    for p in points {
        flat.extend_from_slice(&[p.x, p.y, p.z]);
    }
    Float32Array::from(flat.as_slice())
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

fn frame_js(frame: &Frame) -> Object {
    let o = Object::new();
    set(&o, "name", &JsValue::from_str(&frame.name));
    set(&o, "points", &flat_points(&frame.points));
    match &frame.labels {
        Some(l) => set(&o, "labels", &Uint32Array::from(l.as_slice())),
        None => set(&o, "labels", &JsValue::NULL),
    }
    o
}

/// A sequence from the page's frames (`Float32Array` xyz per frame) and their names.
fn sequence_from_js(frames: &Array, names: &Array) -> Result<Sequence, JsError> {
    let mut out = Vec::with_capacity(frames.length() as usize);
    for (k, f) in frames.iter().enumerate() {
        let name = names
            .get(k as u32)
            .as_string()
            .unwrap_or_else(|| format!("frame {k}"));
        let arr: Float32Array = f
            .dyn_into()
            .map_err(|_| JsError::new(&format!("{name}: frame data is not a Float32Array")))?;
        let points = points_from_flat(&arr.to_vec(), &name)?;
        out.push(Frame {
            name,
            points,
            labels: None,
        });
    }
    Sequence::from_frames(out).map_err(js_err)
}

fn options_from_js(options: JsValue) -> Result<FitOptions, JsError> {
    if options.is_undefined() || options.is_null() {
        return Ok(FitOptions::default());
    }
    serde_wasm_bindgen::from_value(options)
        .map_err(|e| JsError::new(&format!("invalid fit options: {e}")))
}

// ------------------------------------------------------------------ loading

/// Parses frame files (PLY, PCD, NumPy, OBJ, text tables: `io::cloud_file`) given as
/// parallel arrays of names and `Uint8Array` bytes. Each frame gets its own entry
/// `{name, points, labels}` (a file of several frames one a frame, `walk.npy[0]`, …)
/// and each bad file `{name, error}` (the error names the file and the problem), in
/// natural filename order.
#[wasm_bindgen]
pub fn parse_frames(names: Vec<String>, buffers: Array) -> Result<Array, JsError> {
    if names.len() != buffers.length() as usize {
        return Err(JsError::new(
            "parse_frames: names and buffers differ in length",
        ));
    }
    let files: Vec<(String, Vec<u8>)> = names
        .into_iter()
        .zip(buffers.iter())
        .map(|(n, b)| (n, Uint8Array::new(&b).to_vec()))
        .collect();
    let out = Array::new();
    for (name, result) in Sequence::from_named_bytes(files, LoadOptions::default()) {
        let o = match result {
            Ok(frame) => frame_js(&frame),
            Err(e) => {
                let o = Object::new();
                set(&o, "name", &JsValue::from_str(&name));
                set(&o, "error", &JsValue::from_str(&e.to_string()));
                o
            }
        };
        out.push(&o);
    }
    Ok(out)
}

/// A frame's name made a file stem for its exports (`f1.ply` → `f1`, `walk.npy[3]` →
/// `walk_3`), as the CLI's `--ply-out` names them.
#[wasm_bindgen]
pub fn frame_stem(name: &str) -> String {
    crate::io::cloud_file::frame_stem(name)
}

/// Indices that put `names` in natural order (`f2` before `f10`), as the core sorts files.
#[wasm_bindgen]
pub fn natural_order(names: Vec<String>) -> Vec<u32> {
    let mut idx: Vec<u32> = (0..names.len() as u32).collect();
    idx.sort_by(|&a, &b| natural_cmp(&names[a as usize], &names[b as usize]));
    idx
}

// ------------------------------------------------------------------ fitting

thread_local! {
    /// Step-1 candidates fitted by this worker (or sent to it, `put_candidate`), kept
    /// so the worker holding the best one can go on with Steps 2–3; only a runner-up
    /// that shares its worker with the best is copied to another (`candidate_bytes`).
    static CANDIDATES: RefCell<Vec<Step1Result>> = const { RefCell::new(Vec::new()) };
    /// The prepared inputs of the sequence this worker fits, for its next candidate.
    static PREPARED: RefCell<crate::fit::select::PrepareCache> = RefCell::default();
}

/// The core's default part-count range for these frames: `[lo, hi]`.
#[wasm_bindgen]
pub fn default_part_range(frames: Array, names: Array) -> Result<Vec<u32>, JsError> {
    let seq = sequence_from_js(&frames, &names)?;
    let (lo, hi) = crate::pipeline::default_part_range(&seq);
    Ok(vec![lo as u32, hi as u32])
}

/// The part counts a fit of these frames with these options tries in `lo..=hi` (the
/// core's rule: fast thins the list on full input, see
/// `fit::select::candidate_parts`).
#[wasm_bindgen]
pub fn candidate_parts(
    frames: Array,
    names: Array,
    lo: u32,
    hi: u32,
    options: JsValue,
) -> Result<Vec<u32>, JsError> {
    let seq = sequence_from_js(&frames, &names)?;
    let opts = FitOptions {
        parts: Some((lo as usize, hi as usize)),
        ..options_from_js(options)?
    };
    let ms = crate::fit::select::candidates(&seq, &opts).map_err(js_err)?;
    Ok(ms.into_iter().map(|m| m as u32).collect())
}

/// The working clouds the fit sees (frames above the working size downsampled, as
/// the core does it), so snapshot labels can be drawn on their points.
#[wasm_bindgen]
pub fn working_clouds(frames: Array, names: Array, options: JsValue) -> Result<Array, JsError> {
    let seq = sequence_from_js(&frames, &names)?;
    let opts = options_from_js(options)?;
    let (clouds, _) = crate::fit::select::working_clouds(&seq, opts.working_size, opts.seed);
    let out = Array::new();
    for c in &clouds {
        out.push(&flat_points(c));
    }
    Ok(out)
}

/// Step 1 for one candidate part count `m`, reporting progress to `on_progress`
/// (≤ ~20 calls/s). Keeps the candidate in this worker and returns
/// `{m, loss, iterations, occlusion_used}` (`loss`: the model-selection Chamfer).
#[wasm_bindgen]
pub fn fit_candidate(
    frames: Array,
    names: Array,
    m: usize,
    options: JsValue,
    on_progress: &Function,
) -> Result<JsValue, JsError> {
    let seq = sequence_from_js(&frames, &names)?;
    let opts = options_from_js(options)?;
    let mut throttle = Throttle::new(on_progress);
    let r = PREPARED
        .with(|c| {
            crate::pipeline::fit_step1_cached(&mut c.borrow_mut(), &seq, m, &opts, &mut |p| {
                throttle.report(p)
            })
        })
        .map_err(js_err)?;
    let o = Object::new();
    set(&o, "m", &JsValue::from_f64(m as f64));
    set(&o, "loss", &JsValue::from_f64(r.final_chamfer));
    set(&o, "iterations", &JsValue::from_f64(r.iterations as f64));
    set(&o, "occlusion_used", &JsValue::from_bool(r.occlusion_used));
    CANDIDATES.with(|c| c.borrow_mut().push(r));
    Ok(o.into())
}

/// The error for a candidate this worker does not hold (a page bug, not user input).
fn not_in_worker(m: usize) -> JsError {
    JsError::new(&format!(
        "internal: candidate m = {m} is not in this worker"
    ))
}

/// A copy of Step-1 candidate `m` held by this worker, as bytes
/// (`fit::candidate_bytes`), so another worker can finish it beside this one's; this
/// worker keeps its own.
#[wasm_bindgen]
pub fn candidate_bytes(m: usize) -> Result<Vec<u8>, JsError> {
    CANDIDATES
        .with(|c| {
            c.borrow()
                .iter()
                .find(|r| r.m == m)
                .map(crate::fit::candidate_bytes::to_bytes)
        })
        .ok_or_else(|| not_in_worker(m))
}

/// Keeps a candidate another worker sent (`candidate_bytes`), to finish here;
/// returns its m.
#[wasm_bindgen]
pub fn put_candidate(bytes: &[u8]) -> Result<u32, JsError> {
    let r = crate::fit::candidate_bytes::from_bytes(bytes).map_err(js_err)?;
    let m = r.m as u32;
    CANDIDATES.with(|c| {
        let mut c = c.borrow_mut();
        c.retain(|o| o.m != r.m);
        c.push(r);
    });
    Ok(m)
}

/// Steps 2–3 on candidate `m` held by this worker (fitted here, or sent here by
/// `put_candidate`; the best or the runner-up of the page's selection),
/// with every candidate's `[m, loss]` for the result's notes. Returns the result JSON
/// (with the canonical points, so it opens on its own).
#[wasm_bindgen]
pub fn finish(
    frames: Array,
    names: Array,
    m: usize,
    candidates: Array,
    on_progress: &Function,
) -> Result<String, JsError> {
    let seq = sequence_from_js(&frames, &names)?;
    let mut step1 = CANDIDATES
        .with(|c| {
            let mut c = c.borrow_mut();
            let i = c.iter().position(|r| r.m == m)?;
            Some(c.swap_remove(i))
        })
        .ok_or_else(|| not_in_worker(m))?;
    let mut all = Vec::new();
    for pair in candidates.iter() {
        let pair = Array::from(&pair);
        if let (Some(cm), Some(loss)) = (pair.get(0).as_f64(), pair.get(1).as_f64()) {
            all.push((cm as usize, loss));
        }
    }
    if !all.is_empty() {
        step1.candidates = all;
    }
    let mut throttle = Throttle::new(on_progress);
    let clock = || js_sys::Date::now() / 1000.0;
    let out = crate::pipeline::finish(&seq, step1, &clock, &mut |p| throttle.report(p))
        .map_err(js_err)?;
    Ok(out.result.to_json())
}

/// The frames a fit of `k` frames with `options` runs Steps 1–3 on (`key_frames::choose`
/// with `options.key_frames`): every frame, or for a long sequence its key frames.
#[wasm_bindgen]
pub fn key_frames(k: usize, options: JsValue) -> Result<Vec<u32>, JsError> {
    let opts = options_from_js(options)?;
    Ok(crate::key_frames::choose(k, opts.key_frames)
        .into_iter()
        .map(|t| t as u32)
        .collect())
}

/// A result fitted on the key frames `keys` of `frames` (JSON), extended to every frame:
/// the others tracked with its articulated model (`key_frames::extend_recorded`).
/// Returns the extended result's JSON.
#[wasm_bindgen]
pub fn extend_key_frames(
    frames: Array,
    names: Array,
    keys: Vec<u32>,
    result_json: &str,
    options: JsValue,
    on_progress: &Function,
) -> Result<String, JsError> {
    let seq = sequence_from_js(&frames, &names)?;
    let opts = options_from_js(options)?;
    let key = FitResult::from_json(result_json, "result").map_err(js_err)?;
    let keys: Vec<usize> = keys.into_iter().map(|t| t as usize).collect();
    let mut throttle = Throttle::new(on_progress);
    let clock = || js_sys::Date::now() / 1000.0;
    let (result, _) =
        crate::key_frames::extend_recorded(&seq, &keys, key, opts.seed, &clock, &mut |p| {
            throttle.report(p)
        })
        .map_err(js_err)?;
    Ok(result.to_json())
}

/// A fitted result (JSON) edited by hand (`edit::apply`): `edit` is
/// `{join: [[a, b, …], …], joint_types: [[part, "revolute"|"prismatic"], …]}` (either
/// may be left out), in the result's part numbers; the tree and joints are built again
/// on `frames` (the frames it was fitted to). Returns the edited result's JSON.
#[wasm_bindgen]
pub fn edit_model(
    frames: Array,
    names: Array,
    result_json: &str,
    edit: JsValue,
    on_progress: &Function,
) -> Result<String, JsError> {
    let seq = sequence_from_js(&frames, &names)?;
    let old = FitResult::from_json(result_json, "result").map_err(js_err)?;
    let edit: crate::edit::Edit = serde_wasm_bindgen::from_value(edit)
        .map_err(|e| JsError::new(&format!("invalid edit: {e}")))?;
    let mut throttle = Throttle::new(on_progress);
    let clock = || js_sys::Date::now() / 1000.0;
    let out = crate::edit::apply(&seq, &old, &edit, &clock, &mut |p| throttle.report(p))
        .map_err(js_err)?;
    Ok(out.result.to_json())
}

/// The core's second look (`pipeline::second_look`) at two finished fits, the best
/// candidate's and the runner-up's result JSON: `{runner, result}`, where `runner` says
/// whether the runner-up was kept and `result` is the kept result's JSON with the look
/// recorded in its info and notes (the best's unchanged when the look cannot be made).
#[wasm_bindgen]
pub fn second_look(best_json: &str, runner_json: &str) -> Result<JsValue, JsError> {
    let best = FitResult::from_json(best_json, "best candidate's result").map_err(js_err)?;
    let runner = FitResult::from_json(runner_json, "runner-up's result").map_err(js_err)?;
    let o = Object::new();
    let Some(look) = crate::pipeline::second_look(&best, &runner) else {
        set(&o, "runner", &JsValue::FALSE);
        set(&o, "result", &JsValue::from_str(best_json));
        return Ok(o.into());
    };
    let mut kept = if look.take_runner { runner } else { best };
    crate::pipeline::record_second_look(&mut kept, &look);
    set(&o, "runner", &JsValue::from_bool(look.take_runner));
    set(&o, "result", &JsValue::from_str(&kept.to_json()));
    Ok(o.into())
}

/// A second attempt at the whole fit when the finished result (JSON), fitted with
/// `options`, asks for one (`pipeline::retry_wanted`: balanced, full input, much of the
/// clouds unexplained): `{seed, unexplained}` (the seed to fit from, the first's share
/// of points unexplained), or `undefined`.
#[wasm_bindgen]
pub fn retry_seed(result_json: &str, options: JsValue) -> Result<JsValue, JsError> {
    let opts = options_from_js(options)?;
    let first = FitResult::from_json(result_json, "first attempt's result").map_err(js_err)?;
    let Some(seed) = crate::pipeline::retry_wanted(&first, &opts) else {
        return Ok(JsValue::UNDEFINED);
    };
    let share = crate::pipeline::unexplained_share(&first).unwrap_or(f64::NAN);
    let o = Object::new();
    // Seeds stay below 2⁵³ (`pipeline::retry_seed`), so a JS number holds them exactly.
    set(&o, "seed", &JsValue::from_f64(seed as f64));
    set(&o, "unexplained", &JsValue::from_f64(share));
    Ok(o.into())
}

/// The core's look at two attempts (`pipeline::retry_look`), the first fitted with
/// `options`, the second from `retry_seed`: `{second, result}`, where `second` says
/// whether the second attempt was kept and `result` is the kept result's JSON with the
/// look recorded in its info and notes (the first's unchanged when the look cannot be
/// made).
#[wasm_bindgen]
pub fn retry_look(
    first_json: &str,
    second_json: &str,
    options: JsValue,
) -> Result<JsValue, JsError> {
    let opts = options_from_js(options)?;
    let first = FitResult::from_json(first_json, "first attempt's result").map_err(js_err)?;
    let second = FitResult::from_json(second_json, "second attempt's result").map_err(js_err)?;
    let seeds = (opts.seed, crate::pipeline::retry_seed(opts.seed));
    let o = Object::new();
    let Some(look) = crate::pipeline::retry_look(&first, &second, seeds) else {
        set(&o, "second", &JsValue::FALSE);
        set(&o, "result", &JsValue::from_str(first_json));
        return Ok(o.into());
    };
    let mut kept = if look.take_second { second } else { first };
    crate::pipeline::record_retry(&mut kept, &look);
    set(&o, "second", &JsValue::from_bool(look.take_second));
    set(&o, "result", &JsValue::from_str(&kept.to_json()));
    Ok(o.into())
}

/// A third attempt at the whole fit when the result kept after the second (JSON),
/// fitted with `options`, asks for one (`pipeline::third_wanted`: balanced, full input,
/// still much of the clouds unexplained): `{unexplained}` (the kept result's share), or
/// `undefined`. The third attempt is fitted with `from_last_frame` set
/// (`pipeline::third_options`).
#[wasm_bindgen]
pub fn third_wanted(result_json: &str, options: JsValue) -> Result<JsValue, JsError> {
    let opts = options_from_js(options)?;
    let kept = FitResult::from_json(result_json, "kept attempt's result").map_err(js_err)?;
    if !crate::pipeline::third_wanted(&kept, &opts) {
        return Ok(JsValue::UNDEFINED);
    }
    let share = crate::pipeline::unexplained_share(&kept).unwrap_or(f64::NAN);
    let o = Object::new();
    set(&o, "unexplained", &JsValue::from_f64(share));
    Ok(o.into())
}

/// The core's look at the attempt kept after the second and the third
/// (`pipeline::third_look`): `{third, result}`, where `third` says whether the third
/// attempt was kept and `result` is the kept result's JSON with the look recorded (the
/// earlier one's unchanged when the look cannot be made).
#[wasm_bindgen]
pub fn third_look(kept_json: &str, third_json: &str) -> Result<JsValue, JsError> {
    let kept = FitResult::from_json(kept_json, "kept attempt's result").map_err(js_err)?;
    let third = FitResult::from_json(third_json, "third attempt's result").map_err(js_err)?;
    let o = Object::new();
    let Some(look) = crate::pipeline::third_look(&kept, &third) else {
        set(&o, "third", &JsValue::FALSE);
        set(&o, "result", &JsValue::from_str(kept_json));
        return Ok(o.into());
    };
    let (out, _) = crate::pipeline::apply_third_look(kept, third, &look, |r| r);
    set(&o, "third", &JsValue::from_bool(look.take_second));
    set(&o, "result", &JsValue::from_str(&out.to_json()));
    Ok(o.into())
}

/// The candidate the core's rule selects among `(m, loss)` pairs (lowest final
/// Chamfer, ties to the smaller m), so the page knows which worker goes on.
#[wasm_bindgen]
pub fn best_candidate(ms: Vec<u32>, losses: Vec<f64>) -> Result<u32, JsError> {
    ms.iter()
        .zip(&losses)
        .filter(|(_, l)| l.is_finite())
        .min_by(|a, b| a.1.total_cmp(b.1).then(a.0.cmp(b.0)))
        .map(|(&m, _)| m)
        .ok_or_else(|| JsError::new("no candidate finished with a finite loss"))
}

/// One more part count the page fits after its candidates `(m, loss)` (ordered by m)
/// finished, or `undefined`: the core's rule (`fit::select::extra_candidate`: Fast,
/// full input, the default range, its top failed). `occluded`: a candidate reported
/// that it fitted the frames as occluded; `default_range`: the range is the one
/// `default_part_range` gave for these frames.
#[wasm_bindgen]
pub fn extra_candidate(
    ms: Vec<u32>,
    losses: Vec<f64>,
    options: JsValue,
    occluded: bool,
    default_range: bool,
) -> Result<Option<u32>, JsError> {
    let opts = options_from_js(options)?;
    let cands: Vec<(usize, f64)> = ms.iter().map(|&m| m as usize).zip(losses).collect();
    Ok(
        crate::fit::select::extra_candidate(&cands, opts.quality, occluded, default_range)
            .map(|m| m as u32),
    )
}

/// Metrics of a result against ground truth (SPEC §5): `gt` is `gt.json` text,
/// `frames`/`labels` the observed points and their ground-truth part labels per frame
/// (the order of the result's labels). Returns `{mean_ri, canonical_ri,
/// reconstruction_error, flow_error, tree_edit_distance, reanimation_error, notes}`.
#[wasm_bindgen]
pub fn evaluate(
    result_json: &str,
    frames: Array,
    labels: Array,
    gt_json: &str,
) -> Result<JsValue, JsError> {
    let result = FitResult::from_json(result_json, "result").map_err(js_err)?;
    let gt = GroundTruth::from_json(gt_json, "gt.json").map_err(js_err)?;
    let mut frame_labels = Vec::with_capacity(labels.length() as usize);
    for (k, l) in labels.iter().enumerate() {
        let l: Uint32Array = l.dyn_into().map_err(|_| {
            JsError::new(&format!(
                "frame {k} has no ground-truth part labels: no metrics"
            ))
        })?;
        frame_labels.push(l.to_vec());
    }
    let c = result.canonical_frame;
    let flat: Float32Array = frames
        .get(c as u32)
        .dyn_into()
        .map_err(|_| JsError::new(&format!("the canonical frame {c} is missing")))?;
    let points = points_from_flat(&flat.to_vec(), "canonical frame")?;
    let canonical_labels = frame_labels
        .get(c)
        .ok_or_else(|| JsError::new(&format!("the canonical frame {c} has no labels")))?;
    let metrics = crate::eval::evaluate(&result, &gt, &points, canonical_labels, &frame_labels)
        .map_err(js_err)?;
    to_js(&metrics)
}

/// Names of the built-in examples, in menu order.
#[wasm_bindgen]
pub fn example_names() -> Vec<String> {
    synth::example_names()
        .iter()
        .map(|s| s.to_string())
        .collect()
}

/// One-line description of a built-in example (for tooltips).
#[wasm_bindgen]
pub fn example_description(name: &str) -> Result<String, JsError> {
    let kind: ObjectKind = name.parse().map_err(js_err)?;
    Ok(kind.describe().to_string())
}

/// Generates a built-in example: `{name, frames: [{name, points, labels}], gt}`
/// (`gt`: the ground truth as `gt.json` text, for the metrics).
#[wasm_bindgen]
pub fn generate_example(name: &str, seed: u64) -> Result<JsValue, JsError> {
    let kind: ObjectKind = name.parse().map_err(js_err)?;
    let opts = SynthOptions {
        seed,
        ..SynthOptions::new(kind)
    };
    let out = synth::generate(&opts).map_err(js_err)?;
    let o = Object::new();
    set(&o, "name", &JsValue::from_str(kind.name()));
    let frames = Array::new();
    for f in &out.sequence.frames {
        frames.push(&frame_js(f));
    }
    set(&o, "frames", &frames);
    set(&o, "gt", &JsValue::from_str(&synth::gt_json(&out)));
    Ok(o.into())
}

/// The video file of frames encoded by WebCodecs' `VideoEncoder` (`codec` its codec
/// string): MP4 for H.264 (`description`: the encoder's `decoderConfig.description`, the
/// avcC record), WebM for VP8 and VP9 (`description` unused). Frame i is
/// `data[offsets[i]..offsets[i + 1]]`, shown from `timestamps_us[i]`, a key frame where
/// `keys[i]` is 1; the video lasts `duration_us`. See `io::video`.
#[allow(clippy::too_many_arguments)]
#[wasm_bindgen]
pub fn video_file(
    codec: &str,
    description: &[u8],
    width: u32,
    height: u32,
    timestamps_us: &[f64],
    keys: &[u8],
    offsets: &[u32],
    data: &[u8],
    duration_us: f64,
) -> Result<Vec<u8>, JsError> {
    use crate::io::video::{mp4, webm, Codec, EncodedFrame, VideoTrack};
    let n = timestamps_us.len();
    if keys.len() != n || offsets.len() != n + 1 {
        return Err(JsError::new(&format!(
            "video: {n} frame times, {} key flags and {} offsets",
            keys.len(),
            offsets.len()
        )));
    }
    let us = |t: f64| {
        if t.is_finite() && t > 0.0 {
            t.round() as u64
        } else {
            0
        }
    };
    let mut frames = Vec::with_capacity(n);
    for i in 0..n {
        let (a, b) = (offsets[i] as usize, offsets[i + 1] as usize);
        let bytes = data
            .get(a..b)
            .ok_or_else(|| JsError::new(&format!("video: frame {i} lies outside the data")))?;
        frames.push(EncodedFrame {
            timestamp_us: us(timestamps_us[i]),
            key: keys[i] != 0,
            data: bytes,
        });
    }
    let track = VideoTrack {
        codec: Codec::from_webcodecs(codec).map_err(js_err)?,
        width,
        height,
    };
    match track.codec {
        Codec::H264 => mp4::mux(track, description, &frames, us(duration_us)),
        Codec::Vp8 | Codec::Vp9 => webm::mux(track, &frames, us(duration_us)),
    }
    .map_err(js_err)
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
    /// Points of the canonical frame carried by the file itself (`points`).
    canonical_points: Option<Vec<Vec3>>,
    /// `inv_poses[k][p]`: inverse of poses[k][p], to bring frame k back to frame c.
    inv_poses: Vec<Vec<DMat4>>,
}

#[wasm_bindgen]
impl Model {
    /// Opens a result JSON (format `gsart-result`, version 1). `file` names it in errors.
    pub fn from_json(text: &str, file: &str) -> Result<Model, JsError> {
        let result = FitResult::from_json(text, file).map_err(js_err)?;
        let c = result.canonical_frame;
        let canonical_points = match &result.points {
            Some(pts) if pts.len() == result.labels[c].len() => {
                Some(pts.iter().map(|p| Vec3::from_array(*p)).collect())
            }
            Some(pts) => {
                return Err(js_err(crate::Error::input(
                    file,
                    format!(
                        "`points` has {} entries but labels[{c}] has {}",
                        pts.len(),
                        result.labels[c].len()
                    ),
                )))
            }
            None => None,
        };
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

    /// The result JSON; with `with_points`, the canonical frame's points are included
    /// (key `points`) so the file opens on its own (`?model=URL`).
    pub fn to_json(&self, with_points: bool) -> String {
        let c = self.result.canonical_frame;
        let points = self.frame_points[c]
            .as_ref()
            .or(self.canonical_points.as_ref());
        match (with_points, points) {
            (true, Some(p)) if self.result.points.is_none() => {
                let mut r = self.result.clone();
                r.points = Some(p.iter().map(|v| v.to_array()).collect());
                r.to_json()
            }
            (false, _) if self.result.points.is_some() => {
                let mut r = self.result.clone();
                r.points = None;
                r.to_json()
            }
            _ => self.result.to_json(),
        }
    }

    /// URDF of the model and its files, as `[{name, bytes}]` (the URDF first, named
    /// `NAME.urdf`): one link per part with its convex hull as a mesh in `NAME_meshes/`
    /// (`geometry` "hull") or a bounding box ("box", the URDF alone); joints with axis,
    /// origin and limits.
    pub fn urdf_files(&self, name: &str, geometry: &str) -> Result<Array, JsError> {
        let (points, src) = self.source(self.result.canonical_frame)?;
        if src != self.result.canonical_frame {
            return Err(JsError::new("internal: canonical points missing"));
        }
        let geometry: crate::io::urdf::Geometry = geometry.parse().map_err(js_err)?;
        let parts = crate::io::urdf::canonical_part_points(&self.result, points);
        let export = crate::io::urdf::export(
            &self.result,
            &parts,
            name,
            geometry,
            &format!("{name}_meshes"),
        )
        .map_err(js_err)?;
        let files = Array::new();
        let file = |path: &str, bytes: &[u8]| {
            let o = Object::new();
            set(&o, "name", &JsValue::from_str(path));
            set(&o, "bytes", &Uint8Array::from(bytes));
            o
        };
        files.push(&file(&format!("{name}.urdf"), export.urdf.as_bytes()));
        for m in &export.meshes {
            files.push(&file(&m.path, &m.bytes));
        }
        Ok(files)
    }

    /// Frame k as a binary PLY with `x y z part` (the input points when loaded, else the
    /// canonical points moved to frame k by the fitted part poses).
    pub fn segmented_ply(&self, k: usize) -> Result<Uint8Array, JsError> {
        let (points, src) = self.source(k)?;
        let labels = &self.result.labels[src];
        let posed: Vec<Vec3> = if src == k {
            points.to_vec()
        } else {
            // Canonical points carried to frame k by the fitted part poses.
            let moves: Vec<glam::Mat4> = (0..self.result.parts)
                .map(|p| self.pose_of(k, p).unwrap_or(DMat4::IDENTITY).as_mat4())
                .collect();
            points
                .iter()
                .zip(labels)
                .map(|(x, &l)| moves[l as usize].transform_point3(*x))
                .collect()
        };
        let mut bytes = Vec::new();
        write_ply(&mut bytes, &posed, Some(labels), false)
            .map_err(|e| JsError::new(&format!("PLY export: {e}")))?;
        Ok(Uint8Array::from(bytes.as_slice()))
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

// ------------------------------------------------------------------ progress

/// Forwards the core's progress to a JS callback at most ~20 times a second (plus
/// every stage change and the last iteration), keeping the newest snapshot for the
/// next message sent.
struct Throttle<'a> {
    callback: &'a Function,
    last_sent: f64,
    last_stage: Option<Stage>,
    pending: Option<crate::pipeline::Snapshot>,
}

const MIN_INTERVAL_MS: f64 = 50.0;

impl<'a> Throttle<'a> {
    fn new(callback: &'a Function) -> Self {
        Throttle {
            callback,
            last_sent: f64::NEG_INFINITY,
            last_stage: None,
            pending: None,
        }
    }

    fn report(&mut self, p: &Progress) -> Control {
        let now = js_sys::Date::now();
        let stage_changed = self.last_stage != Some(p.stage);
        let last = p.total > 0 && p.iter + 1 >= p.total;
        if let Some(s) = &p.snapshot {
            self.pending = Some(s.clone());
        }
        if !(stage_changed || last || now - self.last_sent >= MIN_INTERVAL_MS) {
            return Control::Continue;
        }
        self.last_sent = now;
        self.last_stage = Some(p.stage);
        let snap = self.pending.take();
        let msg = progress_js(p, snap.as_ref());
        // A throwing callback must not abort the fit: log and go on.
        if let Err(e) = self.callback.call1(&JsValue::NULL, &msg) {
            web_sys::console::error_2(&JsValue::from_str("progress callback failed"), &e);
        }
        Control::Continue
    }
}

fn stage_name(s: Stage) -> &'static str {
    match s {
        Stage::Load => "load",
        Stage::Init => "init",
        Stage::Gaussians => "gaussians",
        Stage::Select => "select",
        Stage::Tree => "tree",
        Stage::Joints => "joints",
        Stage::Track => "track",
        Stage::Done => "done",
    }
}

/// `{stage, m, iter, total, losses: {name: value}, snapshot?: {frame, centers,
/// rotations, scales, labels}}` with fresh typed arrays the worker can transfer.
fn progress_js(p: &Progress, snap: Option<&crate::pipeline::Snapshot>) -> Object {
    let o = Object::new();
    set(&o, "stage", &JsValue::from_str(stage_name(p.stage)));
    set(
        &o,
        "m",
        &p.m.map_or(JsValue::NULL, |m| JsValue::from_f64(m as f64)),
    );
    set(&o, "iter", &JsValue::from_f64(p.iter as f64));
    set(&o, "total", &JsValue::from_f64(p.total as f64));
    let losses = Object::new();
    for (name, v) in &p.losses {
        set(&losses, name, &JsValue::from_f64(*v));
    }
    set(&o, "losses", &losses);
    if let Some(s) = snap {
        let so = Object::new();
        set(&so, "frame", &JsValue::from_f64(s.frame as f64));
        set(&so, "centers", &Float32Array::from(s.centers.as_slice()));
        set(
            &so,
            "rotations",
            &Float32Array::from(s.rotations.as_slice()),
        );
        set(&so, "scales", &Float32Array::from(s.scales.as_slice()));
        set(&so, "labels", &Uint32Array::from(s.labels.as_slice()));
        set(&o, "snapshot", &so);
    }
    o
}
