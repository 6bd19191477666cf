// The video export (www/js/video.js, src/io/video/): the fitted laptop's hinge swept
// through its range as an MP4, and its frames with the camera turning as a WebM, each
// played by Chromium's own <video> at the right length and size, its first frame the
// view and its later frames moving; the view's pose and camera come back afterwards;
// a recording can be cancelled; a browser without WebCodecs says so.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import { startServer, launch, newPage, waitLoaded } from './helpers.mjs';

let srv, browser, page, errors, context;
before(async () => {
  srv = await startServer();
  browser = await launch();
  ({ page, errors, context } = await newPage(browser, { width: 900, height: 560 }));
  await page.goto(`${srv.base}/?example=laptop&fit=1&quality=fast&parts=2..4`);
  await waitLoaded(page);
  await page.waitForFunction(() => /Done in/.test(document.querySelector('#fit-status').innerText), null, { timeout: 300_000 });
});
after(async () => { await context?.close(); await browser?.close(); srv?.server.close(); });

/** Records a video with the page's controls and returns its bytes and the status line. */
async function record(mode, format, turn) {
  await page.selectOption('#video-mode', mode);
  await page.selectOption('#video-format', format);
  await page.locator('#video-turn').setChecked(turn);
  const [dl] = await Promise.all([
    page.waitForEvent('download', { timeout: 300_000 }),
    page.locator('#btn-export-video').click(),
  ]);
  const bytes = fs.readFileSync(await dl.path());
  await page.waitForFunction(() => !document.body.classList.contains('recording'));
  return { name: dl.suggestedFilename(), bytes, status: await page.locator('#video-status').innerText() };
}

/**
 * Plays the WebM in a <video> of the page: its duration and size, and the RGBA of the
 * frames at `times` (seconds), decoded by Chromium.
 */
async function decode(bytes, type, times) {
  return page.evaluate(async ({ b64, type, times }) => {
    const blob = new Blob([Uint8Array.from(atob(b64), (c) => c.charCodeAt(0))], { type });
    const v = document.createElement('video');
    v.muted = true;
    v.preload = 'auto';
    v.src = URL.createObjectURL(blob);
    await new Promise((res, rej) => { v.onloadeddata = res; v.onerror = () => rej(new Error(`video error ${v.error?.code}: ${v.error?.message}`)); });
    const c = document.createElement('canvas');
    c.width = v.videoWidth; c.height = v.videoHeight;
    const g = c.getContext('2d', { willReadFrequently: true });
    const frames = [];
    for (const t of times) {
      v.currentTime = t;
      await new Promise((res) => { v.onseeked = res; });
      g.drawImage(v, 0, 0);
      frames.push(Array.from(g.getImageData(0, 0, c.width, c.height).data));
    }
    return { duration: v.duration, width: v.videoWidth, height: v.videoHeight, frames };
  }, { b64: bytes.toString('base64'), type, times });
}

/** Mean absolute difference of two RGBA images (RGB only), and the share of pixels off by more than 40. */
function diff(a, b) {
  let sum = 0, off = 0;
  for (let i = 0; i < a.length; i += 4) {
    const d = Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]);
    sum += d / 3;
    if (d / 3 > 40) off++;
  }
  return { mean: sum / (a.length / 4), share: off / (a.length / 4) };
}

/** The view rendered offscreen at the video's size (what the video's frames show). */
async function viewImage(w, h) {
  return page.evaluate(async ([w, h]) => Array.from(await window.gsart.state.view.viewer.render_offscreen_rgba(w, h)), [w, h]);
}

test('the hinge swept through its range is an MP4 that plays, starting from the view', { timeout: 300_000 }, async () => {
  const before = await page.evaluate(() => ({
    states: Array.from(window.gsart.state.states),
    cam: window.gsart.state.view.cameraState(),
    joints: window.gsart.state.model.joints().length,
    w: document.querySelector('#view').clientWidth,
    h: document.querySelector('#view').clientHeight,
  }));
  assert.ok(before.joints >= 1, 'the laptop has its hinge');
  const { name, bytes, status } = await record('joints', 'mp4', false);
  assert.equal(name, 'laptop_joints.mp4');
  assert.equal(bytes.subarray(4, 12).toString('latin1'), 'ftypisom', 'an MP4 file');
  const w = 2 * Math.floor(before.w / 2), h = 2 * Math.floor(before.h / 2);
  assert.match(status, new RegExp(`Saved a ${(2 * before.joints).toFixed(1)} s video, ${w} × ${h}`));
  // Everything is back as it was.
  const after = await page.evaluate(() => ({ states: Array.from(window.gsart.state.states), cam: window.gsart.state.view.cameraState() }));
  assert.deepEqual(after, { states: before.states, cam: before.cam });

  const v = await decode(bytes, 'video/mp4', [0, 0.5, 1.0]);
  assert.equal(v.width, w);
  assert.equal(v.height, h);
  assert.ok(Math.abs(v.duration - 2 * before.joints) < 0.05, `duration ${v.duration}`);
  // Frame 0 is the view as it was, with the moving joint's axis highlighted as when its
  // row is hovered (lossy: a small mean difference); a quarter and a half of the sweep
  // later the lid is elsewhere.
  await page.locator('.joint').first().hover();
  const view = await viewImage(w, h);
  await page.mouse.move(0, 0);
  const d0 = diff(v.frames[0], view);
  assert.ok(d0.mean < 6 && d0.share < 0.0015, `the first frame is the view: ${JSON.stringify(d0)}`);
  for (const f of [v.frames[1], v.frames[2]]) {
    const d = diff(f, v.frames[0]);
    assert.ok(d.share > 0.005, `the hinge moves in the video: ${JSON.stringify(d)}`);
  }
  assert.deepEqual(errors, []);
});

test('the frames with the camera turning as a WebM, and a cancelled recording', { timeout: 300_000 }, async () => {
  const k = await page.evaluate(() => window.gsart.state.model.frames());
  const cam = await page.evaluate(() => window.gsart.state.view.cameraState());
  const { name, bytes, status } = await record('frames', 'webm', true);
  assert.equal(name, 'laptop_frames.webm');
  assert.deepEqual([...bytes.subarray(0, 4)], [0x1a, 0x45, 0xdf, 0xa3], 'an EBML file');
  assert.match(status, new RegExp(`Saved a ${(0.4 * k).toFixed(1)} s video`));
  const v = await decode(bytes, 'video/webm', [0, 0.4 * k * 0.5]);
  assert.ok(Math.abs(v.duration - 0.4 * k) < 0.05, `duration ${v.duration}`);
  // Half-way the camera is half a turn round.
  assert.ok(diff(v.frames[1], v.frames[0]).share > 0.01, 'the camera turns');
  assert.equal(await page.evaluate(() => window.gsart.state.view.cameraState()), cam, 'the camera is put back');

  // Cancelled: no download, the page usable, the pose back.
  const states = await page.evaluate(() => Array.from(window.gsart.state.states));
  let downloaded = false;
  page.on('download', () => { downloaded = true; });
  await page.selectOption('#video-mode', 'together');
  await page.locator('#btn-export-video').click();
  await page.waitForFunction(() => /Recording .*: [1-9]\d* %/.test(document.querySelector('#video-status').innerText));
  assert.equal(await page.locator('#btn-export-video').innerText(), 'Cancel video');
  await page.locator('#btn-export-video').click();
  await page.waitForFunction(() => /cancelled/.test(document.querySelector('#video-status').innerText));
  await page.waitForTimeout(500);
  assert.equal(downloaded, false);
  assert.equal(await page.locator('#btn-export-video').innerText(), 'Save video');
  assert.deepEqual(await page.evaluate(() => Array.from(window.gsart.state.states)), states);

  // A browser without WebCodecs says so, and the page stays usable.
  await page.evaluate(() => { window.VideoEncoder = undefined; });
  await page.locator('#btn-export-video').click();
  await page.waitForFunction(() => /cannot encode video/.test(document.querySelector('#video-status').innerText));
  assert.equal(await page.evaluate(() => document.body.classList.contains('recording')), false);
  assert.equal(downloaded, false);
  assert.deepEqual(errors, []);
});
