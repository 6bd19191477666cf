//! Containers for the page's video export: the browser encodes each frame (WebCodecs'
//! `VideoEncoder`, at an exact timestamp) and the core writes the file around the
//! encoded frames — WebM for VP8/VP9 ([`webm`]), MP4 for H.264 ([`mp4`]).
//!
//! A browser can encode video but not write a file a player seeks in: `MediaRecorder`
//! gives a WebM with no duration and no seek index, paced by the wall clock, so a slow
//! renderer gives an uneven video. Here every frame is known before a byte is written:
//! sizes are exact, the duration is in the header, and every key frame is a seek point.
//! No crate fits: the `webm` crate wraps C++ libwebm, which does not build for
//! `wasm32-unknown-unknown`; the `mp4` crate could write the MP4 but comes with a reader
//! and its own dependencies for what is about 200 lines here, and writes no WebM. The
//! subset of each container written here is a few boxes or elements.

pub mod mp4;
pub mod webm;

use crate::error::{Error, Result};

/// The codec of the encoded frames, from WebCodecs' codec string.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    Vp8,
    Vp9,
    H264,
}

impl Codec {
    /// From a WebCodecs codec string (`vp8`, `vp09.00.10.08`, `avc1.640033`, ...).
    pub fn from_webcodecs(codec: &str) -> Result<Codec> {
        let c = codec.trim().to_ascii_lowercase();
        if c == "vp8" {
            Ok(Codec::Vp8)
        } else if c == "vp9" || c.starts_with("vp09.") {
            Ok(Codec::Vp9)
        } else if c.starts_with("avc1.") || c.starts_with("avc3.") {
            Ok(Codec::H264)
        } else {
            Err(Error::InvalidArgument(format!(
                "video codec {codec:?}: the export writes VP8, VP9 or H.264"
            )))
        }
    }
}

/// One encoded frame: its presentation time in microseconds (as WebCodecs gives it),
/// whether it is a key frame, and its bitstream.
#[derive(Clone, Debug)]
pub struct EncodedFrame<'a> {
    pub timestamp_us: u64,
    pub key: bool,
    pub data: &'a [u8],
}

/// The video track: its codec and size in pixels.
#[derive(Clone, Copy, Debug)]
pub struct VideoTrack {
    pub codec: Codec,
    pub width: u32,
    pub height: u32,
}

/// Checks what both containers need: a sensible size, frames in presentation order
/// starting with a key frame (codecs here have no reordering), none empty, and a
/// duration that does not end before the last frame.
fn check(track: VideoTrack, frames: &[EncodedFrame], duration_us: u64) -> Result<()> {
    let bad = |problem: String| Err(Error::InvalidArgument(format!("video: {problem}")));
    if track.width == 0 || track.height == 0 || track.width > 16384 || track.height > 16384 {
        return bad(format!("a {}×{} frame", track.width, track.height));
    }
    let Some(first) = frames.first() else {
        return bad("no frames".into());
    };
    if !first.key {
        return bad("the first frame is not a key frame".into());
    }
    if let Some(w) = frames
        .windows(2)
        .find(|w| w[1].timestamp_us <= w[0].timestamp_us)
    {
        return bad(format!(
            "frame times do not increase ({} µs after {} µs)",
            w[1].timestamp_us, w[0].timestamp_us
        ));
    }
    if frames.iter().any(|f| f.data.is_empty()) {
        return bad("an empty frame".into());
    }
    let last_us = frames.last().map_or(0, |f| f.timestamp_us);
    if duration_us <= last_us {
        return bad(format!(
            "the duration ({duration_us} µs) ends before the last frame ({last_us} µs) is shown"
        ));
    }
    Ok(())
}

/// The name both containers give the writing application.
const WRITER: &str = concat!("gsart ", env!("CARGO_PKG_VERSION"));

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` frames `step_us` apart, a key frame every `key_every`, of varied lengths.
    pub(super) fn sample(n: usize, key_every: usize, step_us: u64) -> Vec<(u64, bool, Vec<u8>)> {
        (0..n)
            .map(|i| {
                let len = 1 + (i * 37) % 300;
                let data = (0..len).map(|j| (i * 7 + j) as u8).collect();
                (i as u64 * step_us, i % key_every == 0, data)
            })
            .collect()
    }

    pub(super) fn frames(s: &[(u64, bool, Vec<u8>)]) -> Vec<EncodedFrame<'_>> {
        s.iter()
            .map(|(t, key, data)| EncodedFrame {
                timestamp_us: *t,
                key: *key,
                data,
            })
            .collect()
    }

    #[test]
    fn unusable_frames_are_refused() {
        let track = VideoTrack {
            codec: Codec::Vp9,
            width: 64,
            height: 48,
        };
        let s = sample(3, 1, 1000);
        assert!(check(track, &frames(&s), 3000).is_ok());
        let mut bad = frames(&s);
        bad[0].key = false;
        assert!(check(track, &bad, 3000).is_err());
        let mut bad = frames(&s);
        bad[2].timestamp_us = 1000;
        assert!(check(track, &bad, 3000).is_err(), "two frames at one time");
        assert!(
            check(track, &frames(&s), 2000).is_err(),
            "the last frame never shown"
        );
        assert!(check(track, &[], 1000).is_err());
        let empty: [u8; 0] = [];
        let bad = [EncodedFrame {
            timestamp_us: 0,
            key: true,
            data: &empty,
        }];
        assert!(check(track, &bad, 1000).is_err());
        let tiny = VideoTrack { width: 0, ..track };
        assert!(check(tiny, &frames(&s), 3000).is_err());
    }

    #[test]
    fn codecs_are_read_from_webcodecs_strings() {
        assert_eq!(Codec::from_webcodecs("vp09.00.10.08").unwrap(), Codec::Vp9);
        assert_eq!(Codec::from_webcodecs("vp8").unwrap(), Codec::Vp8);
        assert_eq!(Codec::from_webcodecs("avc1.640033").unwrap(), Codec::H264);
        assert!(Codec::from_webcodecs("av01.0.04M.08").is_err());
    }
}
