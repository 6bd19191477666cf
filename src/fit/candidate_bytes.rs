//! A Step-1 candidate ([`Step1Result`]) as bytes, and back, bit for bit.
//!
//! The page fits its candidate part counts in Web Workers, each keeping its
//! candidates in its own wasm memory, and finishes the best and the runner-up of
//! model selection (Steps 2–3 on both, for the second look) side by side. When one
//! worker holds both, the runner-up is copied to the other worker with these bytes,
//! so the two finishes run in parallel as they do natively instead of one after the
//! other. Every float travels as its bits (a JSON number could round an `f32` on
//! the way back, and cannot hold a NaN), so the finish from the copy is the finish
//! from the original to the last bit.
//!
//! Layout: the magic `GSC1`, then the fields in declaration order, little-endian;
//! lengths and `usize` values as `u64`, booleans and option tags as one byte.

use super::gaussians::GaussianModel;
use super::whole_motion::WholeMotion;
use super::{Step1Result, Timings};
use crate::normalisation::Normalisation;
use crate::{Error, Result};
use glam::{DMat4, DVec3};

const MAGIC: &[u8; 4] = b"GSC1";

/// Where decoding errors say the bytes came from.
const SOURCE: &str = "Step-1 candidate bytes";

/// Encodes `r` (see the module docs for the layout).
pub fn to_bytes(r: &Step1Result) -> Vec<u8> {
    let mut w = Writer(Vec::with_capacity(encoded_size_hint(r)));
    w.0.extend_from_slice(MAGIC);
    w.model(&r.model);
    w.f64(r.norm.center.x);
    w.f64(r.norm.center.y);
    w.f64(r.norm.center.z);
    w.f64(r.norm.scale);
    w.u32_lists(&r.labels);
    w.u32_lists(&r.working);
    w.f64(r.final_chamfer);
    w.bool(r.occlusion_used);
    w.usize(r.canonical);
    w.usize(r.iterations);
    w.usize(r.m);
    w.usize(r.candidates.len());
    for &(m, loss) in &r.candidates {
        w.usize(m);
        w.f64(loss);
    }
    w.usize(r.restarts);
    w.option(r.medial_init.as_ref(), |w, &b| w.bool(b));
    w.usize(r.held_still);
    w.f64(r.timings.total_s);
    w.usize(r.timings.per_candidate.len());
    for &(m, s, it) in &r.timings.per_candidate {
        w.usize(m);
        w.f64(s);
        w.usize(it);
    }
    w.option(r.segmenter.as_ref(), |w, g| w.model(g));
    w.option(r.whole.as_ref(), |w, whole| {
        w.usize(whole.motions.len());
        for m in &whole.motions {
            for v in m.to_cols_array() {
                w.f64(v);
            }
        }
        w.f64(whole.agree_still);
        w.f64(whole.agree_moved);
    });
    w.0
}

/// Decodes bytes written by [`to_bytes`]; an error (never a panic) for anything
/// else, truncated or trailing bytes included.
pub fn from_bytes(bytes: &[u8]) -> Result<Step1Result> {
    let mut r = Reader { bytes, at: 0 };
    if r.take(MAGIC.len())? != MAGIC {
        return Err(Error::input(SOURCE, "not a Step-1 candidate (bad magic)"));
    }
    let model = r.model()?;
    let center = DVec3::new(r.f64()?, r.f64()?, r.f64()?);
    let norm = Normalisation {
        center,
        scale: r.f64()?,
    };
    let labels = r.u32_lists()?;
    let working = r.u32_lists()?;
    let final_chamfer = r.f64()?;
    let occlusion_used = r.bool()?;
    let canonical = r.usize()?;
    let iterations = r.usize()?;
    let m = r.usize()?;
    let n = r.len(16)?;
    let mut candidates = Vec::with_capacity(n);
    for _ in 0..n {
        candidates.push((r.usize()?, r.f64()?));
    }
    let restarts = r.usize()?;
    let medial_init = r.option(|r| r.bool())?;
    let held_still = r.usize()?;
    let total_s = r.f64()?;
    let n = r.len(24)?;
    let mut per_candidate = Vec::with_capacity(n);
    for _ in 0..n {
        per_candidate.push((r.usize()?, r.f64()?, r.usize()?));
    }
    let segmenter = r.option(|r| r.model())?;
    let whole = r.option(|r| {
        let n = r.len(128)?;
        let mut motions = Vec::with_capacity(n);
        for _ in 0..n {
            let mut a = [0.0; 16];
            for v in &mut a {
                *v = r.f64()?;
            }
            motions.push(DMat4::from_cols_array(&a));
        }
        Ok(WholeMotion {
            motions,
            agree_still: r.f64()?,
            agree_moved: r.f64()?,
        })
    })?;
    if r.at != bytes.len() {
        return Err(Error::input(
            SOURCE,
            format!("{} bytes left over", bytes.len() - r.at),
        ));
    }
    Ok(Step1Result {
        model,
        norm,
        labels,
        working,
        final_chamfer,
        occlusion_used,
        canonical,
        iterations,
        m,
        candidates,
        restarts,
        medial_init,
        held_still,
        timings: Timings {
            total_s,
            per_candidate,
        },
        segmenter,
        whole,
    })
}

/// Bytes [`to_bytes`] will write, about (so it allocates once).
fn encoded_size_hint(r: &Step1Result) -> usize {
    let model = |g: &GaussianModel| {
        32 + 4 * (3 * g.log_scale.len() + 6 * g.rot6d.len() + 3 * g.center.len())
    };
    let lists = |l: &[Vec<u32>]| 8 + l.iter().map(|v| 8 + 4 * v.len()).sum::<usize>();
    256 + model(&r.model)
        + r.segmenter.as_ref().map_or(0, model)
        + lists(&r.labels)
        + lists(&r.working)
        + 16 * r.candidates.len()
        + 24 * r.timings.per_candidate.len()
        + r.whole.as_ref().map_or(0, |w| 24 + 128 * w.motions.len())
}

struct Writer(Vec<u8>);

impl Writer {
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn usize(&mut self, v: usize) {
        self.0.extend_from_slice(&(v as u64).to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.u32(v.to_bits());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_bits().to_le_bytes());
    }
    fn bool(&mut self, v: bool) {
        self.0.push(u8::from(v));
    }
    fn option<T>(&mut self, v: Option<&T>, put: impl FnOnce(&mut Self, &T)) {
        self.bool(v.is_some());
        if let Some(v) = v {
            put(self, v);
        }
    }
    fn f32s(&mut self, v: &[f32]) {
        for &x in v {
            self.f32(x);
        }
    }
    fn model(&mut self, g: &GaussianModel) {
        self.usize(g.m);
        self.usize(g.frames);
        self.usize(g.log_scale.len());
        for s in &g.log_scale {
            self.f32s(s);
        }
        self.usize(g.rot6d.len());
        for r in &g.rot6d {
            self.f32s(r);
        }
        self.usize(g.center.len());
        for c in &g.center {
            self.f32s(c);
        }
    }
    fn u32_lists(&mut self, l: &[Vec<u32>]) {
        self.usize(l.len());
        for v in l {
            self.usize(v.len());
            for &x in v {
                self.u32(x);
            }
        }
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8]> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| Error::input(SOURCE, format!("truncated at byte {}", self.at)))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N]> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    fn usize(&mut self) -> Result<usize> {
        let v = u64::from_le_bytes(self.array()?);
        usize::try_from(v).map_err(|_| Error::input(SOURCE, format!("value {v} too large")))
    }
    /// A count of items of `item` bytes each, checked against the bytes left so a
    /// corrupt count cannot ask for a huge allocation.
    fn len(&mut self, item: usize) -> Result<usize> {
        let n = self.usize()?;
        let left = self.bytes.len() - self.at;
        if n.checked_mul(item).is_none_or(|b| b > left) {
            return Err(Error::input(
                SOURCE,
                format!("a count of {n} at byte {} exceeds the bytes left", self.at),
            ));
        }
        Ok(n)
    }
    fn f32(&mut self) -> Result<f32> {
        Ok(f32::from_bits(self.u32()?))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_bits(u64::from_le_bytes(self.array()?)))
    }
    fn bool(&mut self) -> Result<bool> {
        match self.take(1)?[0] {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(Error::input(
                SOURCE,
                format!("byte {} is {b}, not a boolean", self.at - 1),
            )),
        }
    }
    fn option<T>(&mut self, get: impl FnOnce(&mut Self) -> Result<T>) -> Result<Option<T>> {
        Ok(if self.bool()? { Some(get(self)?) } else { None })
    }
    fn f32_array<const N: usize>(&mut self) -> Result<[f32; N]> {
        let mut a = [0f32; N];
        for x in &mut a {
            *x = self.f32()?;
        }
        Ok(a)
    }
    fn f32_arrays<const N: usize>(&mut self) -> Result<Vec<[f32; N]>> {
        let n = self.len(4 * N)?;
        (0..n).map(|_| self.f32_array()).collect()
    }
    fn model(&mut self) -> Result<GaussianModel> {
        let m = self.usize()?;
        let frames = self.usize()?;
        let log_scale = self.f32_arrays()?;
        let rot6d = self.f32_arrays()?;
        let center = self.f32_arrays()?;
        let per_frame = m.checked_mul(frames);
        if log_scale.len() != m || per_frame != Some(rot6d.len()) || per_frame != Some(center.len())
        {
            return Err(Error::input(
                SOURCE,
                format!(
                    "a model of {m} Gaussians over {frames} frames has {} scales, {} rotations and {} centres",
                    log_scale.len(),
                    rot6d.len(),
                    center.len()
                ),
            ));
        }
        Ok(GaussianModel {
            m,
            frames,
            log_scale,
            rot6d,
            center,
        })
    }
    fn u32_lists(&mut self) -> Result<Vec<Vec<u32>>> {
        let n = self.len(8)?;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let k = self.len(4)?;
            let mut v = Vec::with_capacity(k);
            for _ in 0..k {
                v.push(self.u32()?);
            }
            out.push(v);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{Control, FitOptions, Occlusion, Quality};
    use crate::synth::{generate, ObjectKind, SynthOptions};

    fn candidate(occluded: bool) -> (crate::io::sequence::Sequence, Step1Result) {
        let seq = generate(&SynthOptions {
            frames: 4,
            // Occluded frames show about half their points; the segmenting copy needs
            // the search, which needs `select::OCCLUDED_SEARCH_MIN_POINTS` of them.
            points: if occluded { 1536 } else { 512 },
            heldout: 0,
            occluded,
            ..SynthOptions::new(ObjectKind::Laptop)
        })
        .expect("synth")
        .sequence;
        let opts = FitOptions {
            quality: Quality::Fast,
            iters: Some(40),
            occlusion: if occluded {
                Occlusion::On
            } else {
                Occlusion::Off
            },
            ..FitOptions::default()
        };
        let r = crate::pipeline::fit_step1_single(&seq, 3, &opts, &mut |_| Control::Continue)
            .expect("candidate");
        (seq, r)
    }

    /// Every field comes back with the same bits, on full and occluded input (which
    /// carries the segmenting copy), and Steps 2–3 from the copy give the same result.
    #[test]
    fn a_candidate_comes_back_bit_for_bit_and_finishes_the_same() {
        for occluded in [false, true] {
            let (seq, r) = candidate(occluded);
            assert_eq!(r.segmenter.is_some(), occluded);
            let bytes = to_bytes(&r);
            let back = from_bytes(&bytes).expect("decodes");
            assert_eq!(to_bytes(&back), bytes);
            assert_eq!(back.model, r.model);
            assert_eq!(back.segmenter, r.segmenter);
            assert_eq!(back.labels, r.labels);
            assert_eq!(back.working, r.working);
            assert_eq!(back.norm, r.norm);
            assert_eq!(back.final_chamfer.to_bits(), r.final_chamfer.to_bits());
            assert_eq!(back.timings, r.timings);
            assert_eq!(
                (back.m, back.canonical, back.iterations, back.held_still),
                (r.m, r.canonical, r.iterations, r.held_still)
            );
            let finish = |s: Step1Result| {
                crate::pipeline::finish(&seq, s, &|| 0.0, &mut |_| Control::Continue)
                    .expect("finish")
                    .result
                    .to_json()
            };
            assert_eq!(finish(back), finish(r), "occluded {occluded}");
        }
    }

    /// Values JSON would bend: NaN and infinite losses, an `f32` with every mantissa
    /// bit set, the options' other arms.
    #[test]
    fn odd_values_survive() {
        let (_, mut r) = candidate(false);
        r.final_chamfer = f64::NAN;
        r.candidates = vec![(3, f64::INFINITY), (4, -0.0), (5, f64::from_bits(1))];
        r.model.center[0][0] = f32::from_bits(0x3fff_ffff);
        r.medial_init = Some(true);
        r.timings.per_candidate = vec![(3, 1.5, 40)];
        let back = from_bytes(&to_bytes(&r)).expect("decodes");
        assert!(back.final_chamfer.is_nan());
        let bits = |c: &[(usize, f64)]| c.iter().map(|p| (p.0, p.1.to_bits())).collect::<Vec<_>>();
        assert_eq!(bits(&back.candidates), bits(&r.candidates));
        assert_eq!(back.model.center[0][0].to_bits(), 0x3fff_ffff);
        assert_eq!(back.medial_init, Some(true));
        assert_eq!(back.timings, r.timings);
        // The whole object's motion (`whole_motion`), when there is one.
        r.whole = Some(WholeMotion {
            motions: vec![DMat4::IDENTITY, DMat4::from_rotation_z(0.3)],
            agree_still: 0.1,
            agree_moved: f64::from_bits(3),
        });
        let bytes = to_bytes(&r);
        let back = from_bytes(&bytes).expect("decodes");
        assert_eq!(back.whole, r.whole);
        assert_eq!(to_bytes(&back), bytes);
        assert!(from_bytes(&bytes[..bytes.len() - 1]).is_err());
    }

    /// Anything but the whole encoding is an error, never a panic or a huge
    /// allocation: every truncation, a trailing byte, a wrong magic, a corrupt count,
    /// a model whose sizes disagree.
    #[test]
    fn damaged_bytes_are_errors() {
        let (_, r) = candidate(true);
        let bytes = to_bytes(&r);
        for n in (0..bytes.len()).step_by(7).chain([bytes.len() - 1]) {
            let e = from_bytes(&bytes[..n]).expect_err("truncated");
            assert!(e.to_string().starts_with(SOURCE), "{e}");
        }
        let mut long = bytes.clone();
        long.push(0);
        assert!(from_bytes(&long)
            .expect_err("trailing")
            .to_string()
            .contains("1 bytes left over"));
        let mut magic = bytes.clone();
        magic[0] = b'X';
        assert!(from_bytes(&magic).is_err());
        // The model's scale count (after magic, m and frames) set huge.
        let mut count = bytes.clone();
        count[20..28].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(from_bytes(&count)
            .expect_err("count")
            .to_string()
            .contains("exceeds the bytes left"));
        // m one larger than the scales sent.
        let mut m = bytes.clone();
        m[4..12].copy_from_slice(&((r.model.m + 1) as u64).to_le_bytes());
        assert!(from_bytes(&m)
            .expect_err("sizes")
            .to_string()
            .contains("Gaussians over"));
    }
}
