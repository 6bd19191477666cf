//! MP4 for H.264 video, the file slides, editors and phones play: `ftyp`, then `moov`
//! (written first, so a player can start before the whole file has arrived) with one
//! video track whose sample table lists every frame's time, size, offset and whether it
//! is a key frame, then `mdat` with the frames (ISO/IEC 14496-12 and 14496-15). The
//! frames are H.264 in "avc" form (length-prefixed NAL units, WebCodecs'
//! `avc: {format: 'avc'}`), and `avcc` is the decoder configuration record WebCodecs
//! gives with the first key frame (`decoderConfig.description`).

use super::{check, Codec, EncodedFrame, VideoTrack, WRITER};
use crate::error::{Error, Result};

/// The movie's time unit (ms), and the track's: 90 kHz, video's usual clock, in which
/// 30 fps is a whole 3000 ticks.
const MOVIE_TIMESCALE: u64 = 1000;
const TRACK_TIMESCALE: u64 = 90_000;

/// The MP4 file of `frames` (in presentation order, the first a key frame) on `track`
/// (H.264) with the decoder configuration `avcc`, lasting `duration_us` (the last frame
/// is shown until then).
pub fn mux(
    track: VideoTrack,
    avcc: &[u8],
    frames: &[EncodedFrame],
    duration_us: u64,
) -> Result<Vec<u8>> {
    check(track, frames, duration_us)?;
    if track.codec != Codec::H264 {
        return Err(Error::InvalidArgument(
            "video: MP4 holds H.264 here (VP8 and VP9 go in WebM)".into(),
        ));
    }
    // An AVCDecoderConfigurationRecord starts with version 1 and holds at least its
    // 6-byte header, a sequence and a picture parameter set count.
    if avcc.len() < 7 || avcc[0] != 1 {
        return Err(Error::InvalidArgument(
            "video: the H.264 decoder configuration (avcC) is missing or not version 1".into(),
        ));
    }
    let data_len: u64 = frames.iter().map(|f| f.data.len() as u64).sum();

    let ticks = |us: u64| (u128::from(us) * u128::from(TRACK_TIMESCALE) / 1_000_000) as u64;
    // Sample durations, run-length coded; the last lasts until the end.
    let mut deltas: Vec<(u32, u32)> = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let next = frames.get(i + 1).map_or(duration_us, |g| g.timestamp_us);
        let d = u32::try_from(ticks(next) - ticks(f.timestamp_us))
            .map_err(|_| Error::InvalidArgument("video: a frame lasts over 13 hours".into()))?;
        match deltas.last_mut() {
            Some((n, last)) if *last == d => *n += 1,
            _ => deltas.push((1, d)),
        }
    }
    let track_duration = u32::try_from(ticks(duration_us))
        .map_err(|_| Error::InvalidArgument("video: longer than 13 hours".into()))?;
    let movie_duration = (duration_us * MOVIE_TIMESCALE).div_ceil(1_000_000) as u32;

    // One chunk per frame: `stco` holds each frame's offset in the file, which follows
    // `moov`; the offsets are fixed-width, so `moov`'s length does not depend on them.
    let build_moov = |first_offset: u64| -> Result<Vec<u8>> {
        let mut offsets = Vec::with_capacity(frames.len());
        let mut at = first_offset;
        for f in frames {
            offsets
                .push(u32::try_from(at).map_err(|_| {
                    Error::InvalidArgument("video: the MP4 would pass 4 GB".into())
                })?);
            at += f.data.len() as u64;
        }
        let stbl = boxed(
            b"stbl",
            &[
                stsd(track, avcc),
                full_box(b"stts", 0, 0, &table(&deltas, |(n, d)| [n, d])),
                full_box(
                    b"stss",
                    0,
                    0,
                    &table(
                        &frames
                            .iter()
                            .enumerate()
                            .filter(|(_, f)| f.key)
                            .map(|(i, _)| i as u32 + 1)
                            .collect::<Vec<_>>(),
                        |n| [n],
                    ),
                ),
                // One entry: from chunk 1 on, one sample a chunk, sample entry 1.
                full_box(
                    b"stsc",
                    0,
                    0,
                    &table(&[(1u32, 1u32, 1u32)], |(a, b, c)| [a, b, c]),
                ),
                full_box(b"stsz", 0, 0, &{
                    let mut b = be32(0); // sizes differ: one per sample follows
                    b.extend(be32(frames.len() as u32));
                    for f in frames {
                        b.extend(be32(f.data.len() as u32));
                    }
                    b
                }),
                full_box(b"stco", 0, 0, &table(&offsets, |o| [o])),
            ]
            .concat(),
        );
        let dinf = boxed(
            b"dinf",
            &full_box(
                b"dref",
                0,
                0,
                &[be32(1), full_box(b"url ", 0, 1, &[])].concat(),
            ),
        );
        let minf = boxed(
            b"minf",
            &[full_box(b"vmhd", 0, 1, &[0u8; 8]), dinf, stbl].concat(),
        );
        let mut hdlr = be32(0);
        hdlr.extend(b"vide");
        hdlr.extend([0u8; 12]);
        hdlr.extend(b"VideoHandler\0");
        let mut mdhd = [
            be32(0),
            be32(0),
            be32(TRACK_TIMESCALE as u32),
            be32(track_duration),
        ]
        .concat();
        mdhd.extend(0x55C4u16.to_be_bytes()); // language "und", packed ISO-639-2
        mdhd.extend([0u8; 2]);
        let mdia = boxed(
            b"mdia",
            &[
                full_box(b"mdhd", 0, 0, &mdhd),
                full_box(b"hdlr", 0, 0, &hdlr),
                minf,
            ]
            .concat(),
        );
        let mut tkhd = [be32(0), be32(0), be32(1), be32(0), be32(movie_duration)].concat();
        tkhd.extend([0u8; 8]); // reserved
        tkhd.extend([0u8; 8]); // layer, alternate group, volume, reserved
        tkhd.extend(MATRIX.iter().flat_map(|v| v.to_be_bytes()));
        tkhd.extend(be32(track.width << 16));
        tkhd.extend(be32(track.height << 16));
        // Enabled, in the movie, in the preview.
        let trak = boxed(b"trak", &[full_box(b"tkhd", 0, 7, &tkhd), mdia].concat());
        let mut mvhd = [
            be32(0),
            be32(0),
            be32(MOVIE_TIMESCALE as u32),
            be32(movie_duration),
        ]
        .concat();
        mvhd.extend(be32(0x0001_0000)); // rate 1.0
        mvhd.extend(0x0100u16.to_be_bytes()); // volume 1.0
        mvhd.extend([0u8; 10]);
        mvhd.extend(MATRIX.iter().flat_map(|v| v.to_be_bytes()));
        mvhd.extend([0u8; 24]); // pre_defined
        mvhd.extend(be32(2)); // next track ID
        Ok(boxed(
            b"moov",
            &[full_box(b"mvhd", 0, 0, &mvhd), trak].concat(),
        ))
    };
    let mut ftyp = b"isom".to_vec();
    ftyp.extend(be32(0x200));
    for brand in [b"isom", b"iso2", b"avc1", b"mp41"] {
        ftyp.extend(brand);
    }
    let ftyp = boxed(b"ftyp", &ftyp);
    let moov_len = build_moov(0)?.len() as u64;
    let mdat_header = if data_len + 8 > u64::from(u32::MAX) {
        16
    } else {
        8
    };
    let moov = build_moov(ftyp.len() as u64 + moov_len + mdat_header)?;
    debug_assert_eq!(moov.len() as u64, moov_len);

    let mut out = Vec::with_capacity((ftyp.len() + moov.len()) + (mdat_header + data_len) as usize);
    out.extend(ftyp);
    out.extend(moov);
    if mdat_header == 16 {
        out.extend(be32(1));
        out.extend(b"mdat");
        out.extend((data_len + 16).to_be_bytes());
    } else {
        out.extend(be32((data_len + 8) as u32));
        out.extend(b"mdat");
    }
    for f in frames {
        out.extend_from_slice(f.data);
    }
    Ok(out)
}

/// The unity transformation matrix of `mvhd` and `tkhd` (16.16 and 2.30 fixed point).
const MATRIX: [u32; 9] = [0x0001_0000, 0, 0, 0, 0x0001_0000, 0, 0, 0, 0x4000_0000];

fn be32(v: u32) -> Vec<u8> {
    v.to_be_bytes().to_vec()
}

fn boxed(kind: &[u8; 4], body: &[u8]) -> Vec<u8> {
    let mut out = be32(8 + body.len() as u32);
    out.extend(kind);
    out.extend_from_slice(body);
    out
}

fn full_box(kind: &[u8; 4], version: u8, flags: u32, body: &[u8]) -> Vec<u8> {
    let mut b = vec![version];
    b.extend(&flags.to_be_bytes()[1..]);
    b.extend_from_slice(body);
    boxed(kind, &b)
}

/// An entry count and the entries, each a few big-endian u32s.
fn table<T: Copy, const N: usize>(entries: &[T], row: impl Fn(T) -> [u32; N]) -> Vec<u8> {
    let mut b = be32(entries.len() as u32);
    for &e in entries {
        for v in row(e) {
            b.extend(be32(v));
        }
    }
    b
}

/// The sample description: one `avc1` visual sample entry with its `avcC`.
fn stsd(track: VideoTrack, avcc: &[u8]) -> Vec<u8> {
    let mut e = vec![0u8; 6]; // reserved
    e.extend(1u16.to_be_bytes()); // data reference index
    e.extend([0u8; 16]); // pre_defined, reserved
    e.extend((track.width as u16).to_be_bytes());
    e.extend((track.height as u16).to_be_bytes());
    e.extend(be32(0x0048_0000)); // 72 dpi
    e.extend(be32(0x0048_0000));
    e.extend(be32(0));
    e.extend(1u16.to_be_bytes()); // one frame per sample
    let mut name = [0u8; 32];
    let n = WRITER.len().min(31);
    name[0] = n as u8;
    name[1..=n].copy_from_slice(&WRITER.as_bytes()[..n]);
    e.extend(name);
    e.extend(0x0018u16.to_be_bytes()); // depth: colour, no alpha
    e.extend((-1i16).to_be_bytes());
    e.extend(boxed(b"avcC", avcc));
    full_box(b"stsd", 0, 0, &[be32(1), boxed(b"avc1", &e)].concat())
}

#[cfg(test)]
mod tests {
    use super::super::tests::{frames, sample};
    use super::*;

    /// (type, body) of each box in `b`.
    fn boxes(mut b: &[u8]) -> Vec<([u8; 4], &[u8])> {
        let mut out = Vec::new();
        while b.len() >= 8 {
            let size = u32::from_be_bytes(b[..4].try_into().unwrap()) as usize;
            let kind: [u8; 4] = b[4..8].try_into().unwrap();
            out.push((kind, &b[8..size]));
            b = &b[size..];
        }
        assert!(b.is_empty(), "boxes fill their parent exactly");
        out
    }

    fn get<'a>(bs: &[([u8; 4], &'a [u8])], kind: &[u8; 4]) -> &'a [u8] {
        bs.iter()
            .find(|b| &b.0 == kind)
            .unwrap_or_else(|| panic!("no {}", String::from_utf8_lossy(kind)))
            .1
    }

    fn u32s(b: &[u8]) -> Vec<u32> {
        b.chunks(4)
            .map(|c| u32::from_be_bytes(c.try_into().unwrap()))
            .collect()
    }

    const TRACK: VideoTrack = VideoTrack {
        codec: Codec::H264,
        width: 640,
        height: 360,
    };
    const AVCC: [u8; 11] = [1, 0x64, 0, 0x33, 0xFF, 0xE1, 0, 1, 0x67, 1, 0x68];

    #[test]
    fn the_sample_table_gives_back_every_frame() {
        // 10 s at 30 fps (33 333 µs apart), a key frame every 60.
        let s = sample(300, 60, 33_333);
        let mp4 = mux(TRACK, &AVCC, &frames(&s), 10_000_000).unwrap();
        let top = boxes(&mp4);
        assert_eq!(
            top.iter().map(|b| b.0).collect::<Vec<_>>(),
            [*b"ftyp", *b"moov", *b"mdat"]
        );
        let moov = boxes(get(&top, b"moov"));
        let mvhd = get(&moov, b"mvhd");
        assert_eq!(u32s(&mvhd[12..20]), [1000, 10_000], "10 s in ms");
        let trak = boxes(get(&moov, b"trak"));
        let tkhd = get(&trak, b"tkhd");
        assert_eq!(u32s(&tkhd[76..84]), [640 << 16, 360 << 16]);
        let mdia = boxes(get(&trak, b"mdia"));
        assert_eq!(u32s(&get(&mdia, b"mdhd")[12..20]), [90_000, 900_000]);
        assert_eq!(&get(&mdia, b"hdlr")[8..12], b"vide");
        let minf = boxes(get(&mdia, b"minf"));
        let stbl = boxes(get(&minf, b"stbl"));

        // The sample entry carries the size and the avcC as given.
        let stsd = get(&stbl, b"stsd");
        let entry = boxes(&stsd[8..]);
        assert_eq!(&entry[0].0, b"avc1");
        let avc1 = entry[0].1;
        assert_eq!(u16::from_be_bytes([avc1[24], avc1[25]]), 640);
        assert_eq!(u16::from_be_bytes([avc1[26], avc1[27]]), 360);
        assert_eq!(boxes(&avc1[78..]), [(*b"avcC", &AVCC[..])]);

        // Times: each frame's start, in 90 kHz ticks, comes back from the deltas.
        let stts = u32s(&get(&stbl, b"stts")[4..]);
        let mut starts = Vec::new();
        let mut t = 0u64;
        for run in stts[1..].chunks(2) {
            for _ in 0..run[0] {
                starts.push(t);
                t += u64::from(run[1]);
            }
        }
        assert_eq!(t, 900_000, "the deltas add up to the duration");
        for (got, e) in starts.iter().zip(&s) {
            assert_eq!(*got, e.0 * 90_000 / 1_000_000);
        }
        assert_eq!(starts.len(), s.len());

        // Key frames, sizes, offsets: each sample is its frame's bytes in the file.
        let stss = u32s(&get(&stbl, b"stss")[4..]);
        assert_eq!(stss[0], 5);
        assert_eq!(stss[1..], [1, 61, 121, 181, 241]);
        let stsz = u32s(&get(&stbl, b"stsz")[4..]);
        assert_eq!(stsz[..2], [0, 300]);
        let stco = u32s(&get(&stbl, b"stco")[4..]);
        assert_eq!(stco[0], 300);
        for (i, e) in s.iter().enumerate() {
            let (at, len) = (stco[i + 1] as usize, stsz[i + 2] as usize);
            assert_eq!(&mp4[at..at + len], &e.2[..], "frame {i}");
        }
        assert_eq!(
            u32s(&get(&stbl, b"stsc")[4..]),
            [1, 1, 1, 1],
            "one sample a chunk"
        );
    }

    #[test]
    fn only_h264_with_its_configuration_goes_in() {
        let s = sample(3, 1, 1000);
        let vp9 = VideoTrack {
            codec: Codec::Vp9,
            ..TRACK
        };
        assert!(mux(vp9, &AVCC, &frames(&s), 3000).is_err());
        assert!(mux(TRACK, &[], &frames(&s), 3000).is_err());
        assert!(mux(TRACK, &[0, 1, 2, 3, 4, 5, 6], &frames(&s), 3000).is_err());
        assert!(
            mux(TRACK, &AVCC, &frames(&s), 2000).is_err(),
            "checked like WebM"
        );
    }
}
