//! The `gsart` command line: a thin layer over the core (`fit`, `eval`, `synth`,
//! `articulate`, `bench`). Every error is printed as one line naming the file and the
//! problem, with exit code 1 (2 for usage errors, by clap).

#[cfg(not(target_arch = "wasm32"))]
mod cli {
    use std::io::Write;
    use std::path::{Path, PathBuf};
    use std::time::Instant;

    use clap::{Parser, Subcommand};
    use gsart::io::gt::GroundTruth;
    use gsart::io::result::FitResult;
    use gsart::io::sequence::{gt_path, Sequence};
    use gsart::io::urdf::Geometry;
    use gsart::pipeline::{self, Control, FitOptions, Occlusion, Progress, Quality, Stage};
    use gsart::{Error, Result};

    #[derive(Parser)]
    #[command(
        name = "gsart",
        version,
        about = "Articulated models from point-cloud sequences (GSArt)"
    )]
    struct Cli {
        #[command(subcommand)]
        command: Command,
    }

    #[derive(Subcommand)]
    enum Command {
        /// Fit an articulated model to a sequence (a folder of frames, or frame files:
        /// PLY, PCD, NumPy .npy/.npz, OBJ, .xyz/.csv/.txt).
        Fit {
            /// A sequence folder, or frame files in natural filename order (one .npy/.npz
            /// may hold the whole sequence).
            #[arg(required = true)]
            input: Vec<PathBuf>,
            /// Range of Gaussian counts to try, e.g. `10..15` or `8` (default: from the data).
            #[arg(long)]
            parts: Option<String>,
            /// Step-1 iterations per candidate (overrides the quality preset).
            #[arg(long)]
            iters: Option<usize>,
            /// Quality preset: fast (the two ends of the part range, every part count
            /// on occluded input; two motion re-segmentation rounds with a lighter
            /// pose search after them, a short polish), balanced (every part count,
            /// three rounds) or paper (the paper's iteration counts).
            #[arg(long, default_value = "balanced")]
            quality: String,
            /// Occlusion handling: auto, on or off.
            #[arg(long, default_value = "auto")]
            occlusion: String,
            #[arg(long, default_value_t = 0)]
            seed: u64,
            /// Step-1 fits per candidate part count, each from its own seed, keeping
            /// the lowest final Chamfer (default: the quality preset's).
            #[arg(long)]
            restarts: Option<usize>,
            /// Start the Gaussians on a medial-axis estimate of the cloud (Laplacian
            /// contraction, as the paper does on dense clouds) instead of on its
            /// points; full input only. Measured worse on bench-dev, better on thin
            /// procedural links (README, "Initialisation").
            #[arg(long)]
            medial_init: bool,
            /// Frames larger than this are downsampled for the fit.
            #[arg(long, default_value_t = 4096)]
            working_size: usize,
            /// Sequences of more frames than this are fitted on this many key frames,
            /// spread evenly, and the frames between them tracked with the articulated
            /// model (much faster on long sequences); 0 fits every frame.
            #[arg(long, default_value_t = gsart::key_frames::DEFAULT_KEY_FRAMES)]
            key_frames: usize,
            #[command(flatten)]
            outputs: OutputArgs,
        },
        /// Edit a fitted model by hand: join parts into one (e.g. the two pieces of a
        /// link, or a joint that should not be there: its child and its parent), choose
        /// a joint's type or the root, then build the tree and the joints again on the
        /// sequence it was fitted to.
        Edit {
            /// The result to edit (JSON from `gsart fit`, the page or another tool).
            result: PathBuf,
            /// The sequence the result was fitted to: a folder, or its frame files.
            #[arg(required = true)]
            input: Vec<PathBuf>,
            /// Parts to join, by their numbers in RESULT, e.g. `--join 3,5`; repeat for
            /// more groups (overlapping groups make one part). Without it, Steps 2–3 are
            /// simply done again on RESULT's segmentation and poses.
            #[arg(long, value_name = "A,B[,...]")]
            join: Vec<String>,
            /// Give the joint whose child is part P (by its number in RESULT) this type,
            /// e.g. `--joint-type 5=prismatic`; repeat for more joints.
            #[arg(long, value_name = "P=revolute|prismatic")]
            joint_type: Vec<String>,
            /// Make part P (by its number in RESULT) the root: the URDF's base link.
            #[arg(long, value_name = "P")]
            root: Option<usize>,
            /// The joint whose child is part P moves on its own: undo a coupling the fit
            /// found (`mimic`, the URDF's `<mimic>`); repeat for more joints.
            #[arg(long, value_name = "P")]
            unlink: Vec<usize>,
            #[command(flatten)]
            outputs: OutputArgs,
        },
        /// Metrics of a result against a sequence folder's ground truth (gt.json), as JSON.
        Eval { result: PathBuf, seq_dir: PathBuf },
        /// Write a sequence folder's ground truth (gt.json + labelled frames) as a result
        /// file: view it in the page, or check `eval` (it scores RI 1, errors 0, TED 0).
        Truth {
            seq_dir: PathBuf,
            #[arg(long)]
            out: PathBuf,
            /// Canonical frame of the written result.
            #[arg(long, default_value_t = 0)]
            canonical: usize,
        },
        /// Generate a procedural articulated object in the benchmark format.
        Synth {
            /// laptop, cabinet, arm, hand, quadruped, or `all`.
            kind: String,
            /// Output folder (for `all`: one sub-folder per object).
            #[arg(long)]
            out: PathBuf,
            #[arg(long, default_value_t = 10)]
            frames: usize,
            /// Points per frame (default: the object's own default).
            #[arg(long)]
            points: Option<usize>,
            #[arg(long, default_value_t = 3)]
            heldout: usize,
            /// Keep only the points visible from a random camera per frame.
            #[arg(long)]
            occluded: bool,
            /// Sensor noise: σ of a normal offset per axis, as a fraction of the
            /// object's longest side (a depth camera: about 0.002).
            #[arg(long, default_value_t = 0.0)]
            noise: f64,
            /// Share of each frame's points thrown 5–15 % of the object's size off the
            /// surface (flying pixels).
            #[arg(long, default_value_t = 0.0)]
            outliers: f64,
            /// Turn the whole object this many degrees a frame about the vertical axis
            /// through its centre, as on a turntable (the poses turn with it).
            #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
            turn: f64,
            /// Put the whole object in a random orientation (drawn from the seed, uniform
            /// over rotations) before normalising it, as the benchmark generator's
            /// `random_rotation`.
            #[arg(long)]
            random_rotation: bool,
            #[arg(long, default_value_t = 0)]
            seed: u64,
        },
        /// Re-pose a fitted model with joint states and write the points as PLY.
        Articulate {
            result: PathBuf,
            /// Joint states in the order of the result's `joints`, comma separated (a
            /// model with coupled joints, `mimic`, takes the leaders' alone too).
            #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
            states: Vec<f64>,
            /// Use this frame's root motion (default: the canonical frame).
            #[arg(long)]
            frame: Option<usize>,
            #[arg(long)]
            out: PathBuf,
        },
        /// Benchmark the pipeline on the reference workloads (and optionally sequence folders).
        Bench {
            /// Workloads: robot, object (default both).
            #[arg(long, value_delimiter = ',')]
            workload: Vec<String>,
            /// Extra sequence folders to fit and evaluate (e.g. ../shared/bench-dev/full/*).
            #[arg(long, num_args = 1..)]
            seq: Vec<PathBuf>,
            #[arg(long, default_value = "balanced")]
            quality: String,
            #[arg(long)]
            iters: Option<usize>,
            /// Write the report as JSON here too.
            #[arg(long)]
            json: Option<PathBuf>,
            /// Only time Step 1 of one candidate per workload (what one page worker runs),
            /// on this thread, printing one JSON line each: the native side of
            /// `bench/wasm-vs-native.mjs`. Uses --iters (default 300), --m, --seed.
            #[arg(long)]
            step1_only: bool,
            /// Candidate part count for --step1-only (default: robot 12, object 5).
            #[arg(long)]
            m: Option<usize>,
            #[arg(long, default_value_t = 0)]
            seed: u64,
        },
    }

    /// What `fit` and `edit` write.
    #[derive(clap::Args)]
    struct OutputArgs {
        /// Where to write the result JSON.
        #[arg(long)]
        out: PathBuf,
        /// Also write the segmented frames (PLY with `part`) into this folder.
        #[arg(long)]
        ply_out: Option<PathBuf>,
        /// Also write a URDF of the model. With hull geometry its link meshes (binary
        /// STL) go into a folder beside it, named after it (`model.urdf` →
        /// `model_meshes/`).
        #[arg(long)]
        urdf: Option<PathBuf>,
        /// The URDF links' geometry: each part's convex hull as a mesh, with the solid
        /// hull's inertia, or a bounding box (one file, no meshes).
        #[arg(long, default_value = "hull", value_parser = ["hull", "box"])]
        urdf_geometry: String,
        /// Also write Steps 2–3's report (merges, pair costs, root, tree, joint
        /// residuals, refinement, timings) as JSON, to see why a tree came out as it did.
        #[arg(long)]
        report: Option<PathBuf>,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
    }

    impl OutputArgs {
        /// The outputs, with the URDF geometry parsed.
        fn outputs(&self) -> Result<Outputs<'_>> {
            let geometry = self.urdf_geometry.parse::<Geometry>()?;
            Ok(Outputs {
                out: &self.out,
                ply_out: self.ply_out.as_deref(),
                urdf: self.urdf.as_deref().map(|p| (p, geometry)),
                report: self.report.as_deref(),
            })
        }
    }

    pub fn main() -> i32 {
        let cli = Cli::parse();
        let r = match cli.command {
            Command::Fit {
                input,
                parts,
                iters,
                quality,
                occlusion,
                seed,
                restarts,
                medial_init,
                working_size,
                key_frames,
                outputs,
            } => parse_options(
                parts.as_deref(),
                iters,
                &quality,
                &occlusion,
                seed,
                working_size,
            )
            .and_then(|opts| with_restarts(opts, restarts))
            .and_then(|opts| {
                if key_frames == 1 {
                    return Err(Error::InvalidArgument(
                        "--key-frames must be 0 (every frame) or at least 2".into(),
                    ));
                }
                Ok(FitOptions {
                    medial_init,
                    key_frames,
                    ..opts
                })
            })
            .and_then(|opts| fit(&input, &opts, &outputs.outputs()?, outputs.quiet)),
            Command::Edit {
                result,
                input,
                join,
                joint_type,
                root,
                unlink,
                outputs,
            } => parse_edit(&join, &joint_type, root, unlink)
                .and_then(|e| edit(&result, &input, &e, &outputs.outputs()?, outputs.quiet)),
            Command::Eval { result, seq_dir } => eval(&result, &seq_dir),
            Command::Truth {
                seq_dir,
                out,
                canonical,
            } => truth(&seq_dir, &out, canonical),
            Command::Synth {
                kind,
                out,
                frames,
                points,
                heldout,
                occluded,
                noise,
                outliers,
                turn,
                random_rotation,
                seed,
            } => {
                // The settings every object gets; `points` defaults per object.
                let base = gsart::synth::SynthOptions {
                    frames,
                    heldout,
                    occluded,
                    noise,
                    outliers,
                    turn,
                    random_rotation,
                    seed,
                    ..Default::default()
                };
                synth(&kind, &out, points, &base)
            }
            Command::Articulate {
                result,
                states,
                frame,
                out,
            } => articulate(&result, &states, frame, &out),
            Command::Bench {
                workload,
                iters,
                step1_only: true,
                m,
                seed,
                ..
            } => bench_step1(&workload, m, iters.unwrap_or(300), seed),
            Command::Bench {
                workload,
                seq,
                quality,
                iters,
                json,
                seed,
                ..
            } => parse_options(None, iters, &quality, "auto", seed, 4096)
                .and_then(|opts| bench(&workload, &seq, &opts, json.as_deref())),
        };
        match r {
            Ok(()) => 0,
            Err(e) => {
                eprintln!("gsart: {e}");
                1
            }
        }
    }

    /// `--restarts N` (N ≥ 1) on top of the parsed options.
    fn with_restarts(opts: FitOptions, restarts: Option<usize>) -> Result<FitOptions> {
        use gsart::fit::select::{restarts_allowed, MAX_RESTARTS};
        match restarts {
            Some(n) if !restarts_allowed(n) => Err(Error::InvalidArgument(format!(
                "--restarts {n}: expected 1 to {MAX_RESTARTS}"
            ))),
            _ => Ok(FitOptions { restarts, ..opts }),
        }
    }

    fn parse_options(
        parts: Option<&str>,
        iters: Option<usize>,
        quality: &str,
        occlusion: &str,
        seed: u64,
        working_size: usize,
    ) -> Result<FitOptions> {
        let bad = |m: String| Error::InvalidArgument(m);
        let quality = match quality {
            "fast" => Quality::Fast,
            "balanced" => Quality::Balanced,
            "paper" => Quality::Paper,
            q => {
                return Err(bad(format!(
                    "--quality {q}: expected fast, balanced or paper"
                )))
            }
        };
        let occlusion = match occlusion {
            "auto" => Occlusion::Auto,
            "on" => Occlusion::On,
            "off" => Occlusion::Off,
            o => return Err(bad(format!("--occlusion {o}: expected auto, on or off"))),
        };
        let parts = match parts {
            None => None,
            Some(s) => {
                let num = |t: &str| {
                    t.trim().parse::<usize>().map_err(|_| {
                        bad(format!(
                            "--parts {s}: expected a count like 8 or a range like 10..15"
                        ))
                    })
                };
                let (a, b) = match s.split_once("..") {
                    Some((a, b)) => (num(a)?, num(b.trim_start_matches('='))?),
                    None => (num(s)?, num(s)?),
                };
                if a < 2 || b < a || b > 64 {
                    return Err(bad(format!("--parts {s}: need 2 ≤ A ≤ B ≤ 64")));
                }
                Some((a, b))
            }
        };
        if working_size < 16 {
            return Err(bad("--working-size must be at least 16".into()));
        }
        Ok(FitOptions {
            parts,
            quality,
            iters,
            occlusion,
            seed,
            working_size,
            restarts: None,
            medial_init: false,
            from_last_frame: false,
            key_frames: gsart::key_frames::DEFAULT_KEY_FRAMES,
        })
    }

    /// Sequence folder or file list → frames, plus the ground truth when a folder has one.
    fn load(input: &[PathBuf]) -> Result<(Sequence, Option<GroundTruth>)> {
        if input.len() == 1 && input[0].is_dir() {
            let seq = Sequence::from_dir(&input[0])?;
            let gt = match gt_path(&input[0]) {
                Some(p) => Some(read_gt(&p)?),
                None => None,
            };
            Ok((seq, gt))
        } else {
            for p in input {
                if p.is_dir() {
                    return Err(Error::input(
                        p.display().to_string(),
                        "give either one sequence folder or a list of frame files",
                    ));
                }
            }
            Ok((Sequence::from_files(input)?, None))
        }
    }

    fn read_text(p: &Path) -> Result<String> {
        std::fs::read_to_string(p).map_err(|e| Error::io(p.display().to_string(), e))
    }

    /// Fails before a long run (a fit, a bench) when its output `p` (given as `flag`)
    /// cannot be written, instead of after it: a folder that does not exist, a path
    /// that is a folder, a folder without write permission (probed by creating the
    /// file and removing it again when it did not exist).
    fn check_writable(flag: &str, p: &Path) -> Result<()> {
        let name = p.display().to_string();
        if p.is_dir() {
            return Err(Error::input(
                name,
                format!("{flag} is a folder; it needs a file name"),
            ));
        }
        if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            if !dir.is_dir() {
                return Err(Error::input(
                    name,
                    format!("{flag}: the folder {} does not exist", dir.display()),
                ));
            }
        }
        let existed = p.exists();
        std::fs::OpenOptions::new()
            .append(true)
            .create(true)
            .open(p)
            .map_err(|e| Error::io(format!("{name} ({flag})"), e))?;
        if !existed {
            let _ = std::fs::remove_file(p);
        }
        Ok(())
    }

    fn write_text(p: &Path, text: &str) -> Result<()> {
        std::fs::write(p, text).map_err(|e| Error::io(p.display().to_string(), e))
    }

    fn read_gt(p: &Path) -> Result<GroundTruth> {
        GroundTruth::from_json(&read_text(p)?, &p.display().to_string())
    }

    /// "1 joint", "2 joints".
    fn count(n: usize, what: &str) -> String {
        format!("{n} {what}{}", if n == 1 { "" } else { "s" })
    }

    fn read_result(p: &Path) -> Result<FitResult> {
        FitResult::from_json(&read_text(p)?, &p.display().to_string())
    }

    /// Step 1's progress over all its candidates (part counts fitted side by side on
    /// the threads): how far each has got, so the bar shows the whole of Step 1 rather
    /// than whichever candidate reported last.
    #[derive(Default)]
    struct Step1Progress {
        /// The part counts to fit (more join if model selection adds one).
        ms: Vec<usize>,
        /// Per part count that has reported: how far it has got.
        cands: std::collections::BTreeMap<usize, Candidate>,
        /// Share of a candidate's time spent before its main loop (warm-up and pose
        /// search), taken from the first candidate to finish; a half until then. It
        /// depends on the preset and the input (about 0.7 on bench-dev, balanced).
        init_share: Option<f64>,
    }

    /// Share of the warm-up in the time before a candidate's main loop (the rest is the
    /// pose search).
    const WARMUP_SHARE: f64 = 0.1;

    /// One candidate's progress: the warm-up and pose search (`init`), then the main
    /// loop (`main`), each a fraction that never decreases; when it started and when
    /// its main loop started, to learn `Step1Progress::init_share`.
    struct Candidate {
        init: f64,
        main: f64,
        started: Instant,
        main_started: Option<Instant>,
    }

    impl Step1Progress {
        fn new(ms: Vec<usize>) -> Self {
            Step1Progress {
                ms,
                ..Default::default()
            }
        }

        /// Records a Step-1 report `p` of candidate `m` at `now`; whether it finished
        /// that candidate (the bar then redraws whatever its rate).
        fn update(&mut self, m: usize, p: &Progress, now: Instant) -> bool {
            if !self.ms.contains(&m) {
                self.ms.push(m);
            }
            let f = (p.iter + 1).min(p.total) as f64 / p.total.max(1) as f64;
            // Before the main loop: the warm-up reports its losses, the pose search
            // that follows (most of the time) reports none.
            let f = match (p.stage, p.losses.is_empty()) {
                (Stage::Init, false) => WARMUP_SHARE * f,
                (Stage::Init, true) => WARMUP_SHARE + (1.0 - WARMUP_SHARE) * f,
                _ => f,
            };
            let c = self.cands.entry(m).or_insert(Candidate {
                init: 0.0,
                main: 0.0,
                started: now,
                main_started: None,
            });
            if p.stage == Stage::Init {
                c.init = c.init.max(f);
                return false;
            }
            c.init = 1.0;
            let was_done = c.main >= 1.0;
            c.main = c.main.max(f);
            let main_started = *c.main_started.get_or_insert(now);
            if c.main >= 1.0 && self.init_share.is_none() {
                let whole = now.duration_since(c.started).as_secs_f64();
                let init = main_started.duration_since(c.started).as_secs_f64();
                if whole > 0.0 {
                    self.init_share = Some(init / whole);
                }
            }
            c.main >= 1.0 && !was_done
        }

        /// Fraction of Step 1 done over every candidate.
        fn fraction(&self) -> f64 {
            let share = self.init_share.unwrap_or(0.5);
            let sum: f64 = self
                .cands
                .values()
                .map(|c| share * c.init + (1.0 - share) * c.main)
                .sum();
            sum / self.ms.len().max(1) as f64
        }

        /// "2/6 part counts done, m = 12, 13 running".
        fn summary(&self) -> String {
            let finished = self.cands.values().filter(|c| c.main >= 1.0).count();
            let running: Vec<String> = self
                .cands
                .iter()
                .filter(|(_, c)| c.main < 1.0)
                .map(|(m, _)| m.to_string())
                .collect();
            let mut s = format!("{finished}/{} part counts done", self.ms.len());
            if !running.is_empty() {
                s += &format!(", m = {} running", running.join(", "));
            }
            s
        }
    }

    /// How many passes the tree and the joint refinement of Steps 2–3 have begun: they
    /// run again for the runner-up, the symmetry repair and the joint sweeps, each from
    /// iteration 0, so the bar names the pass instead of seeming to go back.
    #[derive(Default)]
    struct Passes {
        /// The last report of either stage: (stage, iteration).
        last: Option<(Stage, usize)>,
        tree: usize,
        joints: usize,
    }

    impl Passes {
        /// Records report `p`; the pass of its stage it belongs to (0 for other stages).
        fn update(&mut self, p: &Progress) -> usize {
            let n = match p.stage {
                Stage::Tree => &mut self.tree,
                Stage::Joints => &mut self.joints,
                _ => return 0,
            };
            if !matches!(self.last, Some((s, i)) if s == p.stage && p.iter >= i) {
                *n += 1;
            }
            self.last = Some((p.stage, p.iter));
            *n
        }
    }

    /// A one-line terminal progress bar (stderr), redrawn at most ~10 times a second,
    /// with a line of its own when the pipeline starts the whole fit again.
    struct Bar {
        quiet: bool,
        last: Option<Instant>,
        start: Instant,
        /// The attempt running (`pipeline::fit` may fit again: a second attempt, a third).
        attempt: usize,
        /// Steps 2–3 have reported since Step 1 last did.
        finishing: bool,
        /// The part counts Step 1 fits, and how far each has got in this attempt.
        step1: Step1Progress,
        /// Passes of Steps 2–3's stages in this attempt.
        passes: Passes,
    }

    impl Bar {
        fn new(quiet: bool, ms: Vec<usize>) -> Self {
            Bar {
                quiet,
                last: None,
                start: Instant::now(),
                attempt: 1,
                finishing: false,
                step1: Step1Progress::new(ms),
                passes: Passes::default(),
            }
        }
        fn show(&mut self, p: &Progress) {
            if self.quiet {
                return;
            }
            // Step 1 after Steps 2–3 is only ever a new attempt of the whole fit.
            let step1 = matches!(p.stage, Stage::Init | Stage::Gaussians);
            if step1 && self.finishing {
                self.attempt += 1;
                self.step1 = Step1Progress::new(std::mem::take(&mut self.step1.ms));
                self.passes = Passes::default();
                eprintln!(
                    "\r\x1b[Kattempt {}: the model so far leaves much of the clouds unexplained, so the whole fit is done again (the notes at the end say which attempt is kept)",
                    self.attempt
                );
            }
            if step1 {
                self.finishing = false;
            } else if matches!(p.stage, Stage::Tree | Stage::Joints) {
                self.finishing = true;
            }
            let pass = self.passes.update(p);
            let now = Instant::now();
            // The candidate a Step-1 report is about.
            let cand = p.m.filter(|_| step1);
            let finished = cand.is_some_and(|m| self.step1.update(m, p, now));
            let done = p.stage == Stage::Done;
            if !done
                && !finished
                && self
                    .last
                    .is_some_and(|t| now.duration_since(t).as_millis() < 100)
            {
                return;
            }
            self.last = Some(now);
            let losses: Vec<String> = p
                .losses
                .iter()
                .take(3)
                .map(|(k, v)| format!("{k} {v:.4}"))
                .collect();
            let elapsed = self.start.elapsed().as_secs_f64();
            let line = if let Some(m) = cand {
                // The whole of Step 1; the losses are those of the candidate that
                // reported last.
                let losses = if losses.is_empty() {
                    String::new()
                } else {
                    format!("  m={m}: {}", losses.join("  "))
                };
                format!(
                    "{:>11} {}  {}  {elapsed:>6.1}s{losses}",
                    "step 1",
                    bar_of(self.step1.fraction()),
                    self.step1.summary()
                )
            } else {
                let frac = if p.total > 0 {
                    p.iter as f64 / p.total as f64
                } else {
                    0.0
                };
                let name = format!("{:?}", p.stage).to_lowercase();
                let name = if pass > 1 {
                    format!("{name} ({pass})")
                } else {
                    name
                };
                format!(
                    "{name:>11} {} {:>5}/{:<5} {elapsed:>6.1}s  {}",
                    bar_of(frac),
                    p.iter,
                    p.total,
                    losses.join("  ")
                )
            };
            eprint!("\r\x1b[K{line}");
            if done {
                eprintln!();
            }
            let _ = std::io::stderr().flush();
        }
    }

    /// `[#####-----]`, 30 wide.
    fn bar_of(frac: f64) -> String {
        let width = 30;
        let filled = ((frac.clamp(0.0, 1.0) * width as f64) as usize).min(width);
        format!("[{}{}]", "#".repeat(filled), "-".repeat(width - filled))
    }

    /// Where `fit` and `edit` write: the result, and optionally the segmented frames, a
    /// URDF and Steps 2–3's report.
    struct Outputs<'a> {
        out: &'a Path,
        ply_out: Option<&'a Path>,
        urdf: Option<(&'a Path, Geometry)>,
        report: Option<&'a Path>,
    }

    impl Outputs<'_> {
        /// Fails before the work when an output cannot be written.
        fn check(&self) -> Result<()> {
            check_writable("--out", self.out)?;
            for (flag, path) in [
                ("--urdf", self.urdf.map(|u| u.0)),
                ("--report", self.report),
            ] {
                if let Some(p) = path {
                    check_writable(flag, p)?;
                }
            }
            if let Some(dir) = self.ply_out {
                std::fs::create_dir_all(dir)
                    .map_err(|e| Error::io(format!("{} (--ply-out)", dir.display()), e))?;
            }
            Ok(())
        }

        /// Writes what a finished fit or edit produced, and prints its notes and, with
        /// ground truth, its metrics.
        fn write(
            &self,
            seq: &Sequence,
            output: &pipeline::FitOutput,
            gt: Option<&GroundTruth>,
            t0: Instant,
        ) -> Result<()> {
            for note in &output.notes {
                eprintln!("note: {note}");
            }
            let result = &output.result;
            write_text(self.out, &result.to_json())?;
            let joints = result.joints.as_ref().map_or(0, |j| j.len());
            eprintln!(
                "wrote {} ({}, {}) in {:.1} s",
                self.out.display(),
                count(result.parts, "part"),
                count(joints, "joint"),
                t0.elapsed().as_secs_f64()
            );
            if let Some(dir) = self.ply_out {
                for (k, frame) in seq.frames.iter().enumerate() {
                    let stem = gsart::io::cloud_file::frame_stem(&frame.name);
                    let path = dir.join(format!("{stem}_parts.ply"));
                    let mut buf = Vec::new();
                    gsart::io::ply::write_ply(
                        &mut buf,
                        &frame.points,
                        Some(&result.labels[k]),
                        false,
                    )
                    .map_err(|e| Error::io(path.display().to_string(), e))?;
                    std::fs::write(&path, buf)
                        .map_err(|e| Error::io(path.display().to_string(), e))?;
                }
                eprintln!(
                    "wrote {} segmented frames to {}",
                    seq.frames.len(),
                    dir.display()
                );
            }
            if let Some(path) = self.report {
                let text = serde_json::to_string_pretty(&output.kin)
                    .map_err(|e| Error::InvalidArgument(format!("report: {e}")))?;
                write_text(path, &text)?;
                eprintln!("wrote {}", path.display());
            }
            if let Some((path, geometry)) = self.urdf {
                write_urdf(result, seq, path, geometry)?;
            }
            if let Some(gt) = gt {
                let m = pipeline::evaluate(result, seq, gt)?;
                eprintln!("metrics: {}", m.summary());
            }
            Ok(())
        }
    }

    fn fit(input: &[PathBuf], opts: &FitOptions, outputs: &Outputs, quiet: bool) -> Result<()> {
        let t0 = Instant::now();
        outputs.check()?;
        let (seq, gt) = load(input)?;
        // The part counts Step 1 will fit, for the bar (the fit reports any error).
        let ms = gsart::fit::select::candidates(&seq, opts).unwrap_or_default();
        let bar = std::sync::Mutex::new(Bar::new(quiet, ms));
        let cb = |p: &Progress| {
            if let Ok(mut b) = bar.lock() {
                b.show(p);
            }
            Control::Continue
        };
        let output = pipeline::fit(&seq, opts, &cb)?;
        if !quiet {
            eprintln!();
        }
        outputs.write(&seq, &output, gt.as_ref(), t0)
    }

    /// `--join 3,5 --join 7,8 --joint-type 2=prismatic --root 4 --unlink 2` → the edit.
    fn parse_edit(
        joins: &[String],
        types: &[String],
        root: Option<usize>,
        unlink: Vec<usize>,
    ) -> Result<gsart::edit::Edit> {
        use gsart::io::gt::JointType;
        let joint_types = types
            .iter()
            .map(|t| {
                let bad = || {
                    Error::InvalidArgument(format!(
                        "--joint-type {t}: expected PART=revolute or PART=prismatic, e.g. 5=prismatic"
                    ))
                };
                let (p, jt) = t.split_once('=').ok_or_else(bad)?;
                let p = p.trim().parse::<usize>().map_err(|_| bad())?;
                let jt = match jt.trim() {
                    "revolute" => JointType::Revolute,
                    "prismatic" => JointType::Prismatic,
                    _ => return Err(bad()),
                };
                Ok((p, jt))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(gsart::edit::Edit {
            join: parse_joins(joins)?,
            joint_types,
            root,
            unlink,
        })
    }

    /// `--join 3,5 --join 7,8` → `[[3, 5], [7, 8]]`.
    fn parse_joins(joins: &[String]) -> Result<Vec<Vec<usize>>> {
        joins
            .iter()
            .map(|j| {
                j.split(',')
                    .map(|t| {
                        t.trim().parse::<usize>().map_err(|_| {
                            Error::InvalidArgument(format!(
                                "--join {j}: expected part numbers like 3,5"
                            ))
                        })
                    })
                    .collect()
            })
            .collect()
    }

    fn edit(
        result: &Path,
        input: &[PathBuf],
        e: &gsart::edit::Edit,
        outputs: &Outputs,
        quiet: bool,
    ) -> Result<()> {
        let t0 = Instant::now();
        outputs.check()?;
        if e.only_unlinks() && outputs.report.is_some() {
            return Err(Error::InvalidArgument(
                "--report: an edit that only unlinks joints does not build the tree and the joints again, so it has no report".into(),
            ));
        }
        let old = read_result(result)?;
        let (seq, gt) = load(input)?;
        let mut bar = Bar::new(quiet, Vec::new());
        let clock = move || t0.elapsed().as_secs_f64();
        let output = gsart::edit::apply(&seq, &old, e, &clock, &mut |p| {
            bar.show(p);
            Control::Continue
        })?;
        if !quiet {
            eprintln!();
        }
        eprintln!(
            "{} → {}",
            count(old.parts, "part"),
            count(output.result.parts, "part")
        );
        outputs.write(&seq, &output, gt.as_ref(), t0)
    }

    /// The URDF at `path` and, with hull geometry, its meshes in `STEM_meshes/` beside it.
    fn write_urdf(
        result: &FitResult,
        seq: &Sequence,
        path: &Path,
        geometry: Geometry,
    ) -> Result<()> {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_else(|| "model".into());
        let mesh_dir = format!("{stem}_meshes");
        let export = pipeline::urdf(result, seq, "gsart_model", geometry, &mesh_dir)?;
        let folder = path.parent().unwrap_or(Path::new(""));
        if !export.meshes.is_empty() {
            let dir = folder.join(&mesh_dir);
            std::fs::create_dir_all(&dir)
                .map_err(|e| Error::io(format!("{} (--urdf meshes)", dir.display()), e))?;
        }
        for mesh in &export.meshes {
            let file = folder.join(&mesh.path);
            std::fs::write(&file, &mesh.bytes)
                .map_err(|e| Error::io(file.display().to_string(), e))?;
        }
        write_text(path, &export.urdf)?;
        if export.meshes.is_empty() {
            eprintln!("wrote {}", path.display());
        } else {
            eprintln!(
                "wrote {} and {} link meshes in {}",
                path.display(),
                export.meshes.len(),
                folder.join(&mesh_dir).display()
            );
        }
        Ok(())
    }

    fn eval(result: &Path, seq_dir: &Path) -> Result<()> {
        let result = read_result(result)?;
        let seq = Sequence::from_dir(seq_dir)?;
        let gt_file = gt_path(seq_dir).ok_or_else(|| {
            Error::input(seq_dir.display().to_string(), "no gt.json in this folder")
        })?;
        let gt = read_gt(&gt_file)?;
        let m = pipeline::evaluate(&result, &seq, &gt)?;
        print_out(&serde_json::to_string_pretty(&m).unwrap_or_default())
    }

    /// Writes a line to standard output. A reader that closed the pipe early
    /// (`gsart eval … | head`) is no error: the rest is simply not wanted (`println!`
    /// would panic there).
    fn print_out(text: &str) -> Result<()> {
        use std::io::Write;
        match writeln!(std::io::stdout().lock(), "{text}") {
            Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
                Err(Error::io("standard output", e))
            }
            _ => Ok(()),
        }
    }

    fn truth(seq_dir: &Path, out: &Path, canonical: usize) -> Result<()> {
        let seq = Sequence::from_dir(seq_dir)?;
        let gt_file = gt_path(seq_dir).ok_or_else(|| {
            Error::input(seq_dir.display().to_string(), "no gt.json in this folder")
        })?;
        let gt = read_gt(&gt_file)?;
        let mut labels = Vec::with_capacity(seq.frames.len());
        for f in &seq.frames {
            labels.push(f.labels.clone().ok_or_else(|| {
                Error::input(
                    &f.name,
                    "no `part`/`label` property: cannot write the ground truth",
                )
            })?);
        }
        let mut result = FitResult::from_ground_truth(&gt, labels, canonical)?;
        let c = result.canonical_frame;
        result.points = Some(seq.frames[c].points.iter().map(|p| p.to_array()).collect());
        write_text(out, &result.to_json())?;
        eprintln!(
            "wrote {} (ground truth, {} parts)",
            out.display(),
            result.parts
        );
        Ok(())
    }

    fn synth(
        kind: &str,
        out: &Path,
        points: Option<usize>,
        base: &gsart::synth::SynthOptions,
    ) -> Result<()> {
        use gsart::synth::{example_names, generate, write_sequence_dir, ObjectKind, SynthOptions};
        let kinds: Vec<ObjectKind> = if kind == "all" {
            example_names()
                .iter()
                .map(|n| n.parse())
                .collect::<Result<_>>()?
        } else {
            vec![kind.parse()?]
        };
        for k in kinds {
            let o = SynthOptions {
                kind: k,
                points: points.unwrap_or(k.default_points()),
                ..base.clone()
            };
            let generated = generate(&o)?;
            let dir = if kind == "all" {
                out.join(k.name())
            } else {
                out.to_path_buf()
            };
            write_sequence_dir(&generated, &dir)?;
            eprintln!(
                "wrote {} ({} frames, {} parts) to {}",
                k.name(),
                generated.sequence.frames.len(),
                generated.gt.num_parts,
                dir.display()
            );
        }
        Ok(())
    }

    fn articulate(result: &Path, states: &[f64], frame: Option<usize>, out: &Path) -> Result<()> {
        let name = result.display().to_string();
        let result = read_result(result)?;
        let points = pipeline::articulate(&result, states, frame).map_err(|e| match e {
            Error::InvalidArgument(m) => Error::input(&name, m),
            e => e,
        })?;
        let labels = &result.labels[result.canonical_frame];
        let mut buf = Vec::new();
        gsart::io::ply::write_ply(&mut buf, &points, Some(labels), false)
            .map_err(|e| Error::io(out.display().to_string(), e))?;
        std::fs::write(out, buf).map_err(|e| Error::io(out.display().to_string(), e))?;
        eprintln!("wrote {} points to {}", points.len(), out.display());
        Ok(())
    }

    fn bench(
        workloads: &[String],
        seqs: &[PathBuf],
        opts: &FitOptions,
        json: Option<&Path>,
    ) -> Result<()> {
        if let Some(p) = json {
            check_writable("--json", p)?;
        }
        let report = gsart::bench::run(workloads, seqs, opts)?;
        print_out(&report.table())?;
        if let Some(p) = json {
            write_text(
                p,
                &serde_json::to_string_pretty(&report).unwrap_or_default(),
            )?;
        }
        Ok(())
    }

    fn bench_step1(workloads: &[String], m: Option<usize>, iters: usize, seed: u64) -> Result<()> {
        let all = ["robot".to_string(), "object".to_string()];
        let names = if workloads.is_empty() {
            &all[..]
        } else {
            workloads
        };
        for w in names {
            let m = match m {
                Some(m) => m,
                None => gsart::bench_step1::default_m(w)?,
            };
            let r = gsart::bench::step1_native(w, m, iters, seed)?;
            let line = serde_json::to_string(&r)
                .map_err(|e| Error::InvalidArgument(format!("internal: {e}")))?;
            print_out(&line)?;
        }
        Ok(())
    }

    #[cfg(test)]
    mod tests {
        use super::*;
        use std::time::Duration;

        fn report(stage: Stage, iter: usize, total: usize, warmup: bool) -> Progress {
            Progress {
                stage,
                m: None,
                iter,
                total,
                losses: if warmup {
                    vec![("mle".into(), -1.0)]
                } else {
                    Vec::new()
                },
                snapshot: None,
            }
        }

        #[test]
        fn step1_progress_covers_every_part_count() {
            let t0 = Instant::now();
            let at = |s: u64| t0 + Duration::from_secs(s);
            let mut p = Step1Progress::new(vec![10, 11]);
            assert_eq!(p.fraction(), 0.0);
            assert_eq!(p.summary(), "0/2 part counts done");
            // m = 10: warm-up, pose search, then its main loop; nothing finishes before
            // the main loop's last report.
            assert!(!p.update(10, &report(Stage::Init, 59, 60, true), at(0)));
            let after_warmup = p.fraction();
            assert!((after_warmup - 0.5 * WARMUP_SHARE / 2.0).abs() < 1e-12);
            assert!(!p.update(10, &report(Stage::Init, 9, 20, false), at(3)));
            // The search starts at 0 after the warm-up ended at 1: never backwards.
            assert!(p.fraction() > after_warmup);
            assert!(!p.update(10, &report(Stage::Gaussians, 0, 100, false), at(6)));
            assert_eq!(p.summary(), "0/2 part counts done, m = 10 running");
            assert!(p.update(10, &report(Stage::Gaussians, 99, 100, false), at(8)));
            assert!(!p.update(10, &report(Stage::Gaussians, 99, 100, false), at(8)));
            // The first candidate to finish spent 6 of its 8 s before its main loop.
            assert_eq!(p.init_share, Some(0.75));
            assert_eq!(p.fraction(), 0.5);
            assert_eq!(p.summary(), "1/2 part counts done");
            // A part count model selection adds joins the list.
            p.update(20, &report(Stage::Gaussians, 49, 100, false), at(9));
            assert_eq!(p.summary(), "1/3 part counts done, m = 20 running");
            let f = p.fraction();
            assert!((f - (1.0 + 0.75 + 0.25 * 0.5) / 3.0).abs() < 1e-12, "{f}");
            p.update(11, &report(Stage::Gaussians, 99, 100, false), at(10));
            p.update(20, &report(Stage::Gaussians, 99, 100, false), at(11));
            assert_eq!(p.fraction(), 1.0);
            assert_eq!(p.summary(), "3/3 part counts done");
        }

        #[test]
        fn passes_count_each_stage_from_its_start() {
            let mut p = Passes::default();
            let seq = [
                (Stage::Tree, 0, 1),
                (Stage::Tree, 2, 1),
                (Stage::Joints, 0, 1),
                (Stage::Joints, 150, 1),
                (Stage::Tree, 2, 2), // the runner-up's tree, reported from its end
                (Stage::Joints, 25, 2),
                (Stage::Joints, 199, 2),
                (Stage::Joints, 0, 3), // a sweep's refinement
                (Stage::Done, 0, 0),
                (Stage::Joints, 50, 3), // a pass goes on past another stage's report
            ];
            for (stage, iter, want) in seq {
                assert_eq!(
                    p.update(&report(stage, iter, 200, false)),
                    want,
                    "{stage:?} {iter}"
                );
            }
        }

        #[test]
        fn the_bar_is_clamped() {
            assert_eq!(bar_of(-1.0), format!("[{}]", "-".repeat(30)));
            assert_eq!(
                bar_of(0.5),
                format!("[{}{}]", "#".repeat(15), "-".repeat(15))
            );
            assert_eq!(bar_of(2.0), format!("[{}]", "#".repeat(30)));
        }
    }
}

#[cfg(not(target_arch = "wasm32"))]
fn main() {
    std::process::exit(cli::main());
}

#[cfg(target_arch = "wasm32")]
fn main() {}
