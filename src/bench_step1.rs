//! The Step-1 iteration benchmark shared by native and wasm: generates a SPEC §7
//! reference workload and fits ONE candidate part count with a fixed iteration count
//! through `pipeline::fit_step1_single` (what each page worker runs), timing it with a
//! clock the caller passes (`Instant` natively, `performance.now()` in the browser).
//! `gsart bench --step1-only` and the wasm export `bench_step1` both call [`run`], so the
//! two measurements do the same work; the result also carries the final Chamfer and a
//! hash of the labels, which must be bit-identical native vs wasm for the same seed.

use serde::Serialize;

use crate::pipeline::{self, Control, FitOptions, Progress, Quality, Stage};
use crate::synth::{generate, ObjectKind, SynthOptions};
use crate::{Error, Result};

/// One timed Step-1 candidate. Times in milliseconds.
#[derive(Debug, Clone, Serialize)]
pub struct Step1Bench {
    pub workload: String,
    pub object: String,
    pub frames: usize,
    pub points: usize,
    pub m: usize,
    pub seed: u64,
    /// Main-loop iterations run (each = one MLE+sep step and one transfer step).
    pub iterations: usize,
    /// Whole `fit_step1_single` call.
    pub ms_total: f64,
    /// Preparation (working clouds, occlusion detection, scene flow) up to the first
    /// warm-up report.
    pub ms_prepare: f64,
    /// Warm-up on frame 0 and per-frame pose initialisation.
    pub ms_warmup_init: f64,
    /// Main loop from the end of iteration 0 to the end of the last iteration.
    pub ms_loop: f64,
    /// `ms_loop / (iterations − 1)`: the cost of one Step-1 iteration.
    pub ms_per_iter: f64,
    /// Model-selection Chamfer and labels of the working clouds after the loop.
    pub ms_finish: f64,
    /// Model-selection Chamfer (full precision: compare native vs wasm exactly).
    pub final_chamfer: f64,
    /// FNV-1a of every working-point label, hex (a u64 does not fit a JS number).
    pub labels_hash: String,
    /// FNV-1a of the generated input points' f32 bits, hex: tells whether a native vs
    /// wasm difference starts in the data or in the fit.
    pub input_hash: String,
}

/// The reference workloads of SPEC §7: (object, frames, points per frame).
pub fn workload(name: &str) -> Result<(ObjectKind, usize, usize)> {
    match name {
        "robot" => Ok((ObjectKind::Quadruped, 10, 4096)),
        "object" => Ok((ObjectKind::Laptop, 4, 512)),
        other => Err(Error::InvalidArgument(format!(
            "unknown workload '{other}' (expected robot or object)"
        ))),
    }
}

/// A part count in the middle of the workload's SPEC range (robot 10–15, object 3–7).
pub fn default_m(name: &str) -> Result<usize> {
    match name {
        "robot" => Ok(12),
        "object" => Ok(5),
        other => Err(Error::InvalidArgument(format!(
            "unknown workload '{other}' (expected robot or object)"
        ))),
    }
}

fn fnv1a(words: impl Iterator<Item = u32>) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for w in words {
        for b in w.to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// Generates `workload` (procedural object, synthesis seed `seed`) and fits candidate
/// `m` for `iters` main-loop iterations (Fast preset, so the EMD switch sits at the
/// same fraction of the run as in a Fast fit; fit seed `seed`). `now_ms` is a
/// monotonic clock in milliseconds. Generation is not timed.
pub fn run(
    workload_name: &str,
    m: usize,
    iters: usize,
    seed: u64,
    now_ms: &dyn Fn() -> f64,
) -> Result<Step1Bench> {
    if iters < 2 {
        return Err(Error::InvalidArgument(format!(
            "iterations {iters}: need at least 2 to time the loop"
        )));
    }
    let (kind, frames, points) = workload(workload_name)?;
    let mut so = SynthOptions::new(kind);
    so.frames = frames;
    so.points = points;
    so.seed = seed;
    let synth = generate(&so)?;
    let opts = FitOptions {
        parts: Some((m, m)),
        quality: Quality::Fast,
        iters: Some(iters),
        seed,
        ..FitOptions::default()
    };
    // Stage boundaries from the progress reports (every 10 iterations, plus the last).
    let mut first_init: Option<f64> = None;
    let mut first_loop: Option<(f64, usize)> = None;
    let mut last_loop: Option<(f64, usize)> = None;
    let t0 = now_ms();
    let mut cb = |p: &Progress| {
        let t = now_ms();
        match p.stage {
            Stage::Init if first_init.is_none() => first_init = Some(t),
            Stage::Gaussians => {
                if first_loop.is_none() {
                    first_loop = Some((t, p.iter));
                }
                last_loop = Some((t, p.iter));
            }
            _ => {}
        }
        Control::Continue
    };
    let r = pipeline::fit_step1_single(&synth.sequence, m, &opts, &mut cb)?;
    let t_end = now_ms();
    let (Some((t_a, it_a)), Some((t_b, it_b))) = (first_loop, last_loop) else {
        return Err(Error::InvalidArgument(
            "Step 1 reported no main-loop progress".into(),
        ));
    };
    let t_init = first_init.unwrap_or(t0);
    let span = it_b.saturating_sub(it_a).max(1);
    Ok(Step1Bench {
        workload: workload_name.to_string(),
        object: kind.name().to_string(),
        frames,
        points,
        m,
        seed,
        iterations: r.iterations,
        ms_total: t_end - t0,
        ms_prepare: t_init - t0,
        ms_warmup_init: t_a - t_init,
        ms_loop: t_b - t_a,
        ms_per_iter: (t_b - t_a) / span as f64,
        ms_finish: t_end - t_b,
        final_chamfer: r.final_chamfer,
        labels_hash: format!("{:016x}", fnv1a(r.labels.iter().flatten().copied())),
        input_hash: format!(
            "{:016x}",
            fnv1a(synth.sequence.frames.iter().flat_map(|f| {
                f.points
                    .iter()
                    .flat_map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
            }))
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn object_workload_is_deterministic_and_timed() {
        let start = std::time::Instant::now();
        let clock = move || start.elapsed().as_secs_f64() * 1e3;
        let a = run("object", 3, 12, 1, &clock).unwrap();
        let b = run("object", 3, 12, 1, &clock).unwrap();
        assert_eq!(a.iterations, 12);
        assert_eq!(a.final_chamfer.to_bits(), b.final_chamfer.to_bits());
        assert_eq!(a.labels_hash, b.labels_hash);
        assert!(a.ms_per_iter > 0.0 && a.ms_loop <= a.ms_total);
        assert!(a.ms_prepare >= 0.0 && a.ms_warmup_init >= 0.0 && a.ms_finish >= 0.0);
    }

    #[test]
    fn bad_arguments_are_errors() {
        let clock = || 0.0;
        assert!(run("car", 3, 10, 0, &clock).is_err());
        assert!(run("object", 3, 1, 0, &clock).is_err());
        assert!(default_m("car").is_err());
    }
}
