// The video export: renders the view frame by frame offscreen (the same renderer as the
// PNG), encodes each frame with WebCodecs' VideoEncoder at an exact timestamp — H.264
// for MP4, VP9 (or VP8) for WebM — and has the core write the file around the chunks
// (`video_file`, src/io/video/), with its duration and seek points. Recording is not
// paced by the clock, so a slow machine gives the same video, only later.

export const FPS = 30;
/** A key frame every two seconds: what players seek to. */
const KEY_EVERY = 2 * FPS;
/** The longest side of the video; a larger view is scaled down. */
const MAX_SIDE = 1920;
/**
 * The containers and the codecs tried for each, best first. H.264 High at level 5.1
 * covers 1920 × 1920; Main and Baseline are for encoders without High.
 */
const FORMATS = {
  mp4: { label: 'MP4 (H.264)', type: 'video/mp4', codecs: ['avc1.640033', 'avc1.4d0033', 'avc1.420033'], extra: { avc: { format: 'avc' } } },
  webm: { label: 'WebM (VP9)', type: 'video/webm', codecs: ['vp09.00.51.08', 'vp8'], extra: {} },
};

export class VideoUnsupported extends Error {}

/** The video's size for a view of `w`×`h` device pixels: even (4:2:0), at most MAX_SIDE. */
export function videoSize(w, h) {
  const s = Math.min(1, MAX_SIDE / Math.max(w, h, 1));
  const even = (x) => Math.max(2, 2 * Math.floor((x * s) / 2));
  return [even(w), even(h)];
}

/** The first encoder configuration of `format` this browser supports at this size. */
async function pickCodec(format, width, height, bitrate) {
  if (typeof VideoEncoder !== 'function' || typeof VideoFrame !== 'function') {
    throw new VideoUnsupported('This browser cannot encode video (it has no WebCodecs VideoEncoder).');
  }
  const f = FORMATS[format];
  for (const codec of f.codecs) {
    const config = { codec, width, height, bitrate, framerate: FPS, latencyMode: 'quality', ...f.extra };
    try {
      const { supported } = await VideoEncoder.isConfigSupported(config);
      if (supported) return config;
    } catch { /* try the next */ }
  }
  const other = Object.keys(FORMATS).filter((k) => k !== format).map((k) => FORMATS[k].label).join(' or ');
  throw new VideoUnsupported(`This browser cannot encode ${f.label} at ${width} × ${height}: choose ${other}.`);
}

/**
 * Records `frames` video frames: before frame i, `pose(i)` sets the scene and returns a
 * key that is equal for equal scenes (a frame held for several video frames is
 * rendered once); `turn` radians of camera turn are added before every frame.
 * `onProgress(done, total)` is called per frame. Resolves to the file's Blob; rejects with
 * an AbortError when `signal` aborts (checked before the scene is touched). `format`
 * is a key of FORMATS.
 */
export async function recordVideo({ wasm, viewer, format = 'mp4', width, height, frames, pose, turn = 0, onProgress, signal }) {
  const bitrate = Math.round(Math.min(12e6, Math.max(1e6, width * height * FPS * 0.12)));
  const config = await pickCodec(format, width, height, bitrate);
  const chunks = [];
  let failure = null, description = new Uint8Array(0);
  const encoder = new VideoEncoder({
    output: (chunk, meta) => {
      // H.264's decoder configuration (avcC) comes with the first key frame.
      if (meta?.decoderConfig?.description && !description.length) {
        const d = meta.decoderConfig.description;
        description = ArrayBuffer.isView(d) ? new Uint8Array(d.buffer, d.byteOffset, d.byteLength).slice() : new Uint8Array(d).slice();
      }
      const bytes = new Uint8Array(chunk.byteLength);
      chunk.copyTo(bytes);
      chunks.push({ t: chunk.timestamp, key: chunk.type === 'key', bytes });
    },
    error: (e) => { failure = e; },
  });
  const aborted = () => signal?.aborted || failure;
  try {
    encoder.configure(config);
    const step = 1e6 / FPS;
    let lastKey, rgba = null;
    for (let i = 0; i < frames; i++) {
      if (aborted()) break;
      const key = pose(i);
      if (turn) viewer.turn(turn);
      if (!rgba || turn || key !== lastKey) rgba = await viewer.render_offscreen_rgba(width, height);
      lastKey = key;
      if (aborted()) break;
      const frame = new VideoFrame(rgba, {
        format: 'RGBA', codedWidth: width, codedHeight: height,
        timestamp: Math.round(i * step), duration: Math.round(step),
      });
      encoder.encode(frame, { keyFrame: i % KEY_EVERY === 0 });
      frame.close();
      // Keep a few frames in flight, not the whole video.
      while (encoder.encodeQueueSize > 4 && !aborted()) await new Promise((r) => setTimeout(r, 5));
      onProgress?.(i + 1, frames);
    }
    if (signal?.aborted) throw new DOMException('The video was cancelled.', 'AbortError');
    if (!failure) await encoder.flush();
    if (failure) throw new Error(`The video encoder failed: ${failure.message ?? failure}`);
  } finally {
    if (encoder.state !== 'closed') encoder.close();
  }
  chunks.sort((a, b) => a.t - b.t);
  const offsets = new Uint32Array(chunks.length + 1);
  chunks.forEach((c, i) => { offsets[i + 1] = offsets[i] + c.bytes.length; });
  const data = new Uint8Array(offsets[chunks.length]);
  chunks.forEach((c, i) => data.set(c.bytes, offsets[i]));
  const file = wasm.video_file(
    config.codec, description, width, height,
    Float64Array.from(chunks, (c) => c.t), Uint8Array.from(chunks, (c) => (c.key ? 1 : 0)),
    offsets, data, Math.round(frames * 1e6 / FPS),
  );
  return new Blob([file], { type: FORMATS[format].type });
}
