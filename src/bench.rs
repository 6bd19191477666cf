//! `gsart bench`: times the pipeline on the reference workloads of SPEC §7 ("robot":
//! 10 frames × 4096 points, m 10–15; "object": 4 × 512, m 3–7, both procedural objects
//! with ground truth) and on sequence folders, and reports per stage wall time, ms per
//! Step-1 iteration, iterations, accuracy and peak memory. Native only (it reads the
//! wall clock); the wasm timing runs the same pipeline from the bench page.

use std::path::PathBuf;
use std::time::Instant;

use serde::Serialize;

use crate::io::gt::GroundTruth;
use crate::io::sequence::{gt_path, Sequence};
use crate::pipeline::{self, Control, FitOptions, Progress};
use crate::synth::{generate, ObjectKind, SynthOptions};
use crate::{Error, Result};

/// One benchmarked run.
#[derive(Debug, Clone, Serialize)]
pub struct BenchRow {
    pub name: String,
    pub frames: usize,
    pub points: usize,
    pub parts_range: (usize, usize),
    pub chosen_m: usize,
    /// Median over candidates of (candidate seconds / its iterations).
    pub ms_per_iter: f64,
    pub iterations: usize,
    /// Whole fits done: 2 when the pipeline fitted again from another seed
    /// (`pipeline::retry_wanted`), 3 when it then fitted from the last frame too
    /// (`pipeline::third_wanted`); the times then cover every attempt.
    pub attempts: usize,
    pub step1_s: f64,
    pub kinematics_s: f64,
    pub total_s: f64,
    pub mean_ri: Option<f64>,
    pub reconstruction_error: Option<f64>,
    pub flow_error: Option<f64>,
    pub tree_edit_distance: Option<usize>,
    pub reanimation_error: Option<f64>,
    /// Ground-truth joints within issue #4's bar (right type, axis ≤ 5°, pivot ≤ 2;
    /// `eval::joint_error`), and all ground-truth joints.
    pub joints_within_bar: Option<(usize, usize)>,
}

#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub quality: String,
    pub threads: usize,
    pub rows: Vec<BenchRow>,
    /// Peak resident memory of the process (VmHWM), MiB, when the OS tells it.
    pub peak_memory_mib: Option<f64>,
}

impl BenchReport {
    /// A Markdown table (what the README's tables are made from).
    pub fn table(&self) -> String {
        let f = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
        let mut s = format!(
            "quality {}, {} threads, peak memory {}\n\n| run | K×N | m range | m | ms/iter | iters | step 1 s | steps 2–3 s | total s | mean RI | recon | flow | TED | re-anim | joints in the bar |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
            self.quality,
            self.threads,
            self.peak_memory_mib.map_or("n/a".into(), |m| format!("{m:.0} MiB"))
        );
        for r in &self.rows {
            s += &format!(
                "| {}{} | {}×{} | {}–{} | {} | {:.2} | {} | {:.1} | {:.1} | {:.1} | {} | {} | {} | {} | {} | {} |\n",
                r.name,
                match r.attempts {
                    2 => " (fitted twice)",
                    3 => " (fitted three times)",
                    _ => "",
                },
                r.frames,
                r.points,
                r.parts_range.0,
                r.parts_range.1,
                r.chosen_m,
                r.ms_per_iter,
                r.iterations,
                r.step1_s,
                r.kinematics_s,
                r.total_s,
                f(r.mean_ri),
                f(r.reconstruction_error),
                f(r.flow_error),
                r.tree_edit_distance.map_or("–".into(), |t| t.to_string()),
                f(r.reanimation_error),
                r.joints_within_bar
                    .map_or("–".into(), |(w, n)| format!("{w} of {n}")),
            );
        }
        s
    }
}

fn peak_memory_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// Fits one sequence (with ground truth when given) and times it.
pub fn run_one(
    name: &str,
    seq: &Sequence,
    gt: Option<&GroundTruth>,
    opts: &FitOptions,
) -> Result<BenchRow> {
    let t0 = Instant::now();
    let quiet = |_: &Progress| Control::Continue;
    let out = pipeline::fit(seq, opts, &quiet)?;
    let total_s = t0.elapsed().as_secs_f64();
    let info = out.result.info.clone().unwrap_or_default();
    // A second attempt's Step 1 counts too (`info.retry.step1_seconds`: both attempts'),
    // and a third's (`info.third.step1_seconds`).
    let retry_step1 = info["retry"]["step1_seconds"]
        .as_array()
        .map(|a| a.iter().map(|v| v.as_f64().unwrap_or(0.0)).sum::<f64>());
    let third_step1 = info["third"]["step1_seconds"].as_f64();
    let attempts = match (retry_step1, third_step1) {
        (Some(_), Some(_)) => 3,
        (Some(_), None) => 2,
        _ => 1,
    };
    let step1_s = retry_step1
        .or_else(|| info["step1_seconds"].as_f64())
        .map(|s| s + third_step1.unwrap_or(0.0))
        .unwrap_or(f64::NAN);
    let mut per_iter: Vec<f64> = info["candidates_timing"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|c| Some(c[1].as_f64()? * 1e3 / c[2].as_f64()?.max(1.0)))
                .collect()
        })
        .unwrap_or_default();
    per_iter.sort_by(f64::total_cmp);
    let ms_per_iter = per_iter
        .get(per_iter.len() / 2)
        .copied()
        .unwrap_or(f64::NAN);
    let metrics = match gt {
        Some(gt) => Some(pipeline::evaluate(&out.result, seq, gt)?),
        None => None,
    };
    let range = opts
        .parts
        .unwrap_or_else(|| pipeline::default_part_range(seq));
    Ok(BenchRow {
        name: name.to_string(),
        frames: seq.frames.len(),
        points: seq.frames.iter().map(|f| f.points.len()).max().unwrap_or(0),
        parts_range: range,
        chosen_m: info["m"].as_u64().unwrap_or(0) as usize,
        ms_per_iter,
        iterations: info["iterations"].as_u64().unwrap_or(0) as usize,
        attempts,
        step1_s,
        kinematics_s: total_s - step1_s,
        total_s,
        mean_ri: metrics.as_ref().map(|m| m.mean_ri),
        reconstruction_error: metrics.as_ref().map(|m| m.reconstruction_error),
        flow_error: metrics.as_ref().map(|m| m.flow_error),
        tree_edit_distance: metrics.as_ref().and_then(|m| m.tree_edit_distance),
        reanimation_error: metrics.as_ref().and_then(|m| m.reanimation_error),
        joints_within_bar: metrics
            .as_ref()
            .and_then(|m| m.joints.as_ref())
            .map(|j| (j.within_bar, j.joints)),
    })
}

/// The reference workloads by name, then the given sequence folders.
pub fn run(workloads: &[String], seqs: &[PathBuf], opts: &FitOptions) -> Result<BenchReport> {
    let mut names: Vec<String> = workloads.to_vec();
    if names.is_empty() && seqs.is_empty() {
        names = vec!["robot".into(), "object".into()];
    }
    let mut rows = Vec::new();
    for w in &names {
        let (kind, frames, points, parts) = match w.as_str() {
            "robot" => (ObjectKind::Quadruped, 10, 4096, (10, 15)),
            "object" => (ObjectKind::Laptop, 4, 512, (3, 7)),
            other => {
                return Err(Error::InvalidArgument(format!(
                    "unknown workload '{other}' (expected robot or object)"
                )))
            }
        };
        let mut so = SynthOptions::new(kind);
        so.frames = frames;
        so.points = points;
        let s = generate(&so)?;
        let mut o = opts.clone();
        o.parts = Some(opts.parts.unwrap_or(parts));
        let label = format!("{w} ({})", kind.name());
        rows.push(run_one(&label, &s.sequence, Some(&s.gt), &o)?);
        eprintln!("bench: {label} done");
    }
    for dir in seqs {
        let seq = Sequence::from_dir(dir)?;
        let gt = match gt_path(dir) {
            Some(p) => {
                let text = std::fs::read_to_string(&p)
                    .map_err(|e| Error::io(p.display().to_string(), e))?;
                Some(GroundTruth::from_json(&text, &p.display().to_string())?)
            }
            None => None,
        };
        let label = dir
            .components()
            .rev()
            .take(2)
            .map(|c| c.as_os_str().to_string_lossy().to_string())
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect::<Vec<_>>()
            .join("/");
        rows.push(run_one(&label, &seq, gt.as_ref(), opts)?);
        eprintln!("bench: {label} done");
    }
    Ok(BenchReport {
        quality: format!("{:?}", opts.quality).to_lowercase(),
        threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        rows,
        peak_memory_mib: peak_memory_mib(),
    })
}

/// `gsart bench --step1-only`: [`crate::bench_step1::run`] timed with the wall clock,
/// on this thread only (one candidate never spawns threads), for the wasm-vs-native
/// comparison (`bench/wasm-vs-native.mjs`).
pub fn step1_native(
    workload: &str,
    m: usize,
    iters: usize,
    seed: u64,
) -> Result<crate::bench_step1::Step1Bench> {
    let start = Instant::now();
    let clock = move || start.elapsed().as_secs_f64() * 1e3;
    crate::bench_step1::run(workload, m, iters, seed, &clock)
}
