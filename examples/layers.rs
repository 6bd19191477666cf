//! `geom::layers::layered_fraction` of every frame of some sequences (on a
//! deterministic subset of at most `--max N` points, default 1024, as the occlusion
//! rule uses it): min / median / max per sequence and the time per frame.
//!
//! Usage: `cargo run --release --example layers -- SEQ_DIR... [--max N]`

use gsart::geom::layers::layered_fraction;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut max = 1024;
    let mut dirs = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--max" {
            max = it.next().and_then(|v| v.parse().ok()).unwrap_or(max);
        } else {
            dirs.push(a.clone());
        }
    }
    for dir in dirs {
        let seq = match gsart::io::sequence::Sequence::from_dir(std::path::Path::new(&dir)) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("{dir}: {e}");
                continue;
            }
        };
        let t0 = std::time::Instant::now();
        let mut f: Vec<f64> = seq
            .frames
            .iter()
            .filter_map(|fr| {
                let step = fr.points.len().div_ceil(max).max(1);
                let pts: Vec<_> = fr.points.iter().step_by(step).copied().collect();
                layered_fraction(&pts)
            })
            .collect();
        let ms = t0.elapsed().as_secs_f64() * 1e3 / f.len().max(1) as f64;
        f.sort_by(|a, b| a.total_cmp(b));
        if let (Some(lo), Some(hi)) = (f.first(), f.last()) {
            println!(
                "{dir}: {lo:.3} {:.3} {hi:.3} ({ms:.0} ms per frame)",
                f[f.len() / 2]
            );
        }
    }
}
