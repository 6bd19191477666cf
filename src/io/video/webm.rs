//! WebM for VP8 and VP9 video: the EBML header and a `Segment` with `SeekHead`,
//! `Info` (with the duration), `Tracks`, `Cluster`s of `SimpleBlock`s (a cluster per key
//! frame) and `Cues` pointing at every cluster that starts with a key frame — the subset
//! of Matroska WebM players read (Matroska and WebM specifications).

use super::{check, Codec, EncodedFrame, VideoTrack, WRITER};
use crate::error::{Error, Result};

/// Matroska's codec ID.
fn codec_id(codec: Codec) -> Result<&'static str> {
    match codec {
        Codec::Vp8 => Ok("V_VP8"),
        Codec::Vp9 => Ok("V_VP9"),
        Codec::H264 => Err(Error::InvalidArgument(
            "video: H.264 goes in MP4 here, not WebM".into(),
        )),
    }
}

// Element IDs (with their marker bits, as the specification writes them).
const EBML: u32 = 0x1A45_DFA3;
const EBML_VERSION: u32 = 0x4286;
const EBML_READ_VERSION: u32 = 0x42F7;
const EBML_MAX_ID_LENGTH: u32 = 0x42F2;
const EBML_MAX_SIZE_LENGTH: u32 = 0x42F3;
const DOC_TYPE: u32 = 0x4282;
const DOC_TYPE_VERSION: u32 = 0x4287;
const DOC_TYPE_READ_VERSION: u32 = 0x4285;
const SEGMENT: u32 = 0x1853_8067;
const SEEK_HEAD: u32 = 0x114D_9B74;
const SEEK: u32 = 0x4DBB;
const SEEK_ID: u32 = 0x53AB;
const SEEK_POSITION: u32 = 0x53AC;
const INFO: u32 = 0x1549_A966;
const TIMESTAMP_SCALE: u32 = 0x2A_D7B1;
const DURATION: u32 = 0x4489;
const MUXING_APP: u32 = 0x4D80;
const WRITING_APP: u32 = 0x5741;
const TRACKS: u32 = 0x1654_AE6B;
const TRACK_ENTRY: u32 = 0xAE;
const TRACK_NUMBER: u32 = 0xD7;
const TRACK_UID: u32 = 0x73C5;
const TRACK_TYPE: u32 = 0x83;
const FLAG_LACING: u32 = 0x9C;
const CODEC_ID: u32 = 0x86;
const VIDEO: u32 = 0xE0;
const PIXEL_WIDTH: u32 = 0xB0;
const PIXEL_HEIGHT: u32 = 0xBA;
const CLUSTER: u32 = 0x1F43_B675;
const TIMESTAMP: u32 = 0xE7;
const SIMPLE_BLOCK: u32 = 0xA3;
const CUES: u32 = 0x1C53_BB6B;
const CUE_POINT: u32 = 0xBB;
const CUE_TIME: u32 = 0xB3;
const CUE_TRACK_POSITIONS: u32 = 0xB7;
const CUE_TRACK: u32 = 0xF7;
const CUE_CLUSTER_POSITION: u32 = 0xF1;

/// Timestamps are in milliseconds (`TimestampScale` 10⁶ ns), WebM's usual unit.
const NS_PER_TICK: u64 = 1_000_000;
/// A `SimpleBlock`'s time is a signed 16-bit offset from its cluster's.
const MAX_BLOCK_OFFSET_MS: u64 = i16::MAX as u64;

/// The WebM file of `frames` (in presentation order, the first a key frame) on `track`,
/// lasting `duration_us` (the last frame is shown until then).
pub fn mux(track: VideoTrack, frames: &[EncodedFrame], duration_us: u64) -> Result<Vec<u8>> {
    check(track, frames, duration_us)?;
    let codec = codec_id(track.codec)?;
    let ms = |us: u64| (us + 500) / 1000;

    // Clusters: a new one at every key frame (so each is a seek point) and wherever a
    // block would be more than i16::MAX ms after its cluster's start.
    let mut clusters: Vec<(u64, bool, Vec<u8>)> = Vec::new(); // (time ms, starts with key, body)
    for f in frames {
        let t = ms(f.timestamp_us);
        let start_new = match clusters.last() {
            None => true,
            Some((t0, _, _)) => f.key || t - t0 > MAX_BLOCK_OFFSET_MS,
        };
        if start_new {
            let mut body = Vec::new();
            uint_element(&mut body, TIMESTAMP, t);
            clusters.push((t, f.key, body));
        }
        let Some((t0, _, body)) = clusters.last_mut() else {
            unreachable!("a cluster was pushed above");
        };
        // The frame's bytes are copied here and once more into the file, not per level.
        header(body, SIMPLE_BLOCK, 4 + f.data.len() as u64);
        body.push(0x81); // track number 1 as a one-byte vint
        body.extend_from_slice(&((t - *t0) as i16).to_be_bytes());
        body.push(if f.key { 0x80 } else { 0x00 });
        body.extend_from_slice(f.data);
    }

    let mut info = Vec::new();
    {
        let mut b = Vec::new();
        uint_element(&mut b, TIMESTAMP_SCALE, NS_PER_TICK);
        element(
            &mut b,
            DURATION,
            &(duration_us as f64 / 1000.0).to_be_bytes(),
        );
        element(&mut b, MUXING_APP, WRITER.as_bytes());
        element(&mut b, WRITING_APP, WRITER.as_bytes());
        element(&mut info, INFO, &b);
    }
    let mut tracks = Vec::new();
    {
        let mut video = Vec::new();
        uint_element(&mut video, PIXEL_WIDTH, u64::from(track.width));
        uint_element(&mut video, PIXEL_HEIGHT, u64::from(track.height));
        let mut entry = Vec::new();
        uint_element(&mut entry, TRACK_NUMBER, 1);
        uint_element(&mut entry, TRACK_UID, 1);
        uint_element(&mut entry, TRACK_TYPE, 1); // video
        uint_element(&mut entry, FLAG_LACING, 0);
        element(&mut entry, CODEC_ID, codec.as_bytes());
        element(&mut entry, VIDEO, &video);
        let mut b = Vec::new();
        element(&mut b, TRACK_ENTRY, &entry);
        element(&mut tracks, TRACKS, &b);
    }

    // Positions are relative to the start of the Segment's data. The SeekHead's
    // positions are written in 8 bytes, so its length does not depend on them.
    let seek_head = |positions: [u64; 3]| {
        let mut b = Vec::new();
        for (id, pos) in [INFO, TRACKS, CUES].into_iter().zip(positions) {
            let mut seek = Vec::new();
            element(&mut seek, SEEK_ID, &id_bytes(id));
            element(&mut seek, SEEK_POSITION, &pos.to_be_bytes());
            element(&mut b, SEEK, &seek);
        }
        let mut el = Vec::new();
        element(&mut el, SEEK_HEAD, &b);
        el
    };
    let head_len = seek_head([0; 3]).len() as u64;
    let info_pos = head_len;
    let tracks_pos = info_pos + info.len() as u64;
    let mut pos = tracks_pos + tracks.len() as u64;
    let mut cues_body = Vec::new();
    for (t, key, body) in &clusters {
        if *key {
            let mut tp = Vec::new();
            uint_element(&mut tp, CUE_TRACK, 1);
            uint_element(&mut tp, CUE_CLUSTER_POSITION, pos);
            let mut cp = Vec::new();
            uint_element(&mut cp, CUE_TIME, *t);
            element(&mut cp, CUE_TRACK_POSITIONS, &tp);
            element(&mut cues_body, CUE_POINT, &cp);
        }
        pos += element_len(CLUSTER, body.len() as u64);
    }
    let cues_pos = pos;
    let mut cues = Vec::new();
    element(&mut cues, CUES, &cues_body);

    let head = seek_head([info_pos, tracks_pos, cues_pos]);
    let segment_len = cues_pos + cues.len() as u64;
    let mut out = Vec::with_capacity(segment_len as usize + 64);
    {
        let mut b = Vec::new();
        uint_element(&mut b, EBML_VERSION, 1);
        uint_element(&mut b, EBML_READ_VERSION, 1);
        uint_element(&mut b, EBML_MAX_ID_LENGTH, 4);
        uint_element(&mut b, EBML_MAX_SIZE_LENGTH, 8);
        element(&mut b, DOC_TYPE, b"webm");
        uint_element(&mut b, DOC_TYPE_VERSION, 4);
        uint_element(&mut b, DOC_TYPE_READ_VERSION, 2);
        element(&mut out, EBML, &b);
    }
    header(&mut out, SEGMENT, segment_len);
    let segment_start = out.len();
    for part in [&head, &info, &tracks] {
        out.extend_from_slice(part);
    }
    for (_, _, body) in &clusters {
        header(&mut out, CLUSTER, body.len() as u64);
        out.extend_from_slice(body);
    }
    out.extend_from_slice(&cues);
    debug_assert_eq!((out.len() - segment_start) as u64, segment_len);
    Ok(out)
}

/// An element ID's bytes: the ID as written, without leading zero bytes.
fn id_bytes(id: u32) -> Vec<u8> {
    let b = id.to_be_bytes();
    let skip = b.iter().take_while(|&&x| x == 0).count().min(3);
    b[skip..].to_vec()
}

/// An element's data size as an EBML variable-length integer, in the fewest bytes (the
/// all-ones value of each length is reserved for "unknown").
fn push_size(out: &mut Vec<u8>, size: u64) {
    let len = size_len(size);
    let marked = size | (1u64 << (7 * len));
    out.extend_from_slice(&marked.to_be_bytes()[8 - len as usize..]);
}

/// Bytes of `size` as an EBML variable-length integer ([`push_size`]).
fn size_len(size: u64) -> u32 {
    (1..=8u32)
        .find(|&n| size < (1u64 << (7 * n)) - 1)
        .unwrap_or(8)
}

/// An element's ID and data size; its `size` bytes of data follow.
fn header(out: &mut Vec<u8>, id: u32, size: u64) {
    out.extend_from_slice(&id_bytes(id));
    push_size(out, size);
}

/// The length of an element with `size` bytes of data.
fn element_len(id: u32, size: u64) -> u64 {
    (id_bytes(id).len() as u32 + size_len(size)) as u64 + size
}

fn element(out: &mut Vec<u8>, id: u32, data: &[u8]) {
    header(out, id, data.len() as u64);
    out.extend_from_slice(data);
}

/// An unsigned-integer element in the fewest bytes (at least one).
fn uint_element(out: &mut Vec<u8>, id: u32, v: u64) {
    let b = v.to_be_bytes();
    let skip = b.iter().take_while(|&&x| x == 0).count().min(7);
    element(out, id, &b[skip..]);
}

#[cfg(test)]
mod tests {
    use super::super::tests::{frames, sample};
    use super::*;

    /// A minimal EBML reader for the tests: (id, data) of each element in `b`.
    fn children(mut b: &[u8]) -> Vec<(u32, &[u8])> {
        let mut out = Vec::new();
        while !b.is_empty() {
            let id_len = b[0].leading_zeros() as usize + 1;
            let id = b[..id_len]
                .iter()
                .fold(0u32, |a, &x| (a << 8) | u32::from(x));
            b = &b[id_len..];
            let size_len = b[0].leading_zeros() as usize + 1;
            let mut size = u64::from(b[0]) & ((1u64 << (8 - size_len)) - 1);
            for &x in &b[1..size_len] {
                size = (size << 8) | u64::from(x);
            }
            b = &b[size_len..];
            let (data, rest) = b.split_at(size as usize);
            out.push((id, data));
            b = rest;
        }
        out
    }

    fn find<'a>(els: &[(u32, &'a [u8])], id: u32) -> Vec<&'a [u8]> {
        els.iter().filter(|e| e.0 == id).map(|e| e.1).collect()
    }

    fn uint(b: &[u8]) -> u64 {
        b.iter().fold(0, |a, &x| (a << 8) | u64::from(x))
    }

    const TRACK: VideoTrack = VideoTrack {
        codec: Codec::Vp9,
        width: 640,
        height: 360,
    };

    #[test]
    fn sizes_are_minimal_vints() {
        let enc = |s| {
            let mut v = Vec::new();
            push_size(&mut v, s);
            v
        };
        assert_eq!(enc(0), [0x80]);
        assert_eq!(enc(126), [0xFE]);
        // 127 is the one-byte "unknown size": two bytes.
        assert_eq!(enc(127), [0x40, 0x7F]);
        assert_eq!(enc(300), [0x41, 0x2C]);
        assert_eq!(enc(1 << 20), [0x30, 0x00, 0x00]);
        assert_eq!(enc((1 << 21) - 1), [0x10, 0x1F, 0xFF, 0xFF]);
        assert_eq!(id_bytes(0xA3), [0xA3]);
        assert_eq!(id_bytes(SEGMENT), [0x18, 0x53, 0x80, 0x67]);
    }

    #[test]
    fn the_file_reads_back_frame_for_frame_with_cues_at_its_key_frames() {
        // 40 s at 30 fps with a key frame every 2 s: 20 clusters, each under i16::MAX ms.
        let s = sample(1200, 60, 33_333);
        let duration = 1200 * 33_333;
        let webm = mux(TRACK, &frames(&s), duration).unwrap();

        let top = children(&webm);
        assert_eq!(top.len(), 2);
        let head = children(top[0].1);
        assert_eq!(find(&head, DOC_TYPE), [b"webm"]);
        assert_eq!(top[1].0, SEGMENT);
        let seg_data = top[1].1;
        let seg = children(seg_data);

        // The SeekHead points at Info, Tracks and Cues.
        let seeks = children(find(&seg, SEEK_HEAD)[0]);
        for (id, data) in seeks {
            assert_eq!(id, SEEK);
            let s = children(data);
            let target = uint(find(&s, SEEK_ID)[0]) as u32;
            let pos = uint(find(&s, SEEK_POSITION)[0]) as usize;
            assert_eq!(children(&seg_data[pos..])[0].0, target);
        }

        let info = children(find(&seg, INFO)[0]);
        assert_eq!(uint(find(&info, TIMESTAMP_SCALE)[0]), 1_000_000);
        let dur = f64::from_be_bytes(find(&info, DURATION)[0].try_into().unwrap());
        assert!((dur - 39_999.6).abs() < 1e-6, "{dur}");

        let tracks = children(find(&seg, TRACKS)[0]);
        let entry = children(find(&tracks, TRACK_ENTRY)[0]);
        assert_eq!(find(&entry, CODEC_ID), [b"V_VP9"]);
        let video = children(find(&entry, VIDEO)[0]);
        assert_eq!(uint(find(&video, PIXEL_WIDTH)[0]), 640);
        assert_eq!(uint(find(&video, PIXEL_HEIGHT)[0]), 360);

        // Every frame comes back with its time (to the millisecond), key flag and bytes.
        let clusters = find(&seg, CLUSTER);
        assert_eq!(clusters.len(), 20);
        let mut got = Vec::new();
        for c in &clusters {
            let els = children(c);
            let t0 = uint(find(&els, TIMESTAMP)[0]) as i64;
            for b in find(&els, SIMPLE_BLOCK) {
                assert_eq!(b[0], 0x81);
                let dt = i16::from_be_bytes([b[1], b[2]]) as i64;
                got.push(((t0 + dt) as u64, b[3] & 0x80 != 0, b[4..].to_vec()));
            }
        }
        assert_eq!(got.len(), s.len());
        for (g, e) in got.iter().zip(&s) {
            assert_eq!(g.0, (e.0 + 500) / 1000);
            assert_eq!((g.1, &g.2), (e.1, &e.2));
        }

        // One cue per cluster, at its time, pointing at it.
        let cues = find(&seg, CUES);
        let points = find(&children(cues[0]), CUE_POINT);
        assert_eq!(points.len(), 20);
        for (i, p) in points.iter().enumerate() {
            let els = children(p);
            assert_eq!(uint(find(&els, CUE_TIME)[0]), i as u64 * 2000);
            let tp = children(find(&els, CUE_TRACK_POSITIONS)[0]);
            let pos = uint(find(&tp, CUE_CLUSTER_POSITION)[0]) as usize;
            let at = children(&seg_data[pos..]);
            assert_eq!(at[0].0, CLUSTER);
            assert_eq!(at[0].1, clusters[i]);
        }
    }

    #[test]
    fn a_long_stretch_without_key_frames_is_split_into_clusters() {
        // One key frame, then 70 s of delta frames at 10 fps: blocks stay within i16 ms.
        let s = sample(700, 10_000, 100_000);
        let webm = mux(TRACK, &frames(&s), 70_000_000).unwrap();
        let seg = children(children(&webm)[1].1);
        let clusters = find(&seg, CLUSTER);
        assert_eq!(clusters.len(), 3);
        let points = find(&children(find(&seg, CUES)[0]), CUE_POINT);
        assert_eq!(
            points.len(),
            1,
            "only the key frame's cluster is a seek point"
        );
    }

    #[test]
    fn h264_is_refused() {
        let s = sample(3, 1, 1000);
        let h264 = VideoTrack {
            codec: Codec::H264,
            ..TRACK
        };
        assert!(mux(h264, &frames(&s), 3000).is_err());
        assert!(mux(TRACK, &frames(&s), 2000).is_err(), "checked like MP4");
    }
}
