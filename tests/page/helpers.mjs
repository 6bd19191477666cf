// Shared setup of the page tests: serves www/ on 127.0.0.1 (a free port) and
// launches the system Chromium through playwright-core (never a downloaded browser),
// with SwiftShader flags so WebGPU and WebGL2 both work without a GPU.
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';
import { listen } from '../../scripts/serve.mjs';

export const ROOT = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..', '..');
export const ARTIFACTS = path.join(ROOT, 'test-artifacts');
fs.mkdirSync(ARTIFACTS, { recursive: true });

/** bench-dev: `../shared/bench-dev` relative to the repo root (CI), or /work/shared/bench-dev. */
export function benchDev() {
  const candidates = [process.env.GSART_BENCH_DEV, path.join(ROOT, '..', 'shared', 'bench-dev'), '/work/shared/bench-dev'];
  return candidates.find((p) => p && fs.existsSync(path.join(p, 'full'))) ?? null;
}

const CHROMIUM = process.env.CHROMIUM_PATH || '/usr/bin/chromium';
const ARGS = [
  '--no-sandbox', '--no-first-run', '--disable-background-networking', '--disable-component-update',
  '--disable-sync', '--disable-quic',
  '--enable-unsafe-webgpu', '--enable-features=Vulkan', '--use-vulkan=swiftshader', '--use-angle=swiftshader',
];

export async function startServer() {
  if (!fs.existsSync(path.join(ROOT, 'www', 'pkg', 'gsart_bg.wasm'))) {
    throw new Error('www/pkg is missing: run `npm run build` before the page tests');
  }
  const server = await listen(0);
  const { port } = server.address();
  return { server, base: `http://127.0.0.1:${port}` };
}

export async function launch() {
  return chromium.launch({ executablePath: CHROMIUM, headless: true, args: ARGS });
}

/**
 * A new page that records console errors and page errors (tests assert there are none).
 * Downloads are accepted.
 */
export async function newPage(browser, { width = 1280, height = 800 } = {}) {
  const context = await browser.newContext({ viewport: { width, height }, acceptDownloads: true, deviceScaleFactor: 1 });
  const page = await context.newPage();
  const errors = [];
  page.on('console', (msg) => { if (msg.type() === 'error') errors.push(`console: ${msg.text()}`); });
  page.on('pageerror', (err) => errors.push(`pageerror: ${err.message}`));
  page.on('requestfailed', (req) => errors.push(`requestfailed: ${req.url()} ${req.failure()?.errorText}`));
  return { context, page, errors };
}

/** Waits until the app finished its start-up (wasm loaded, viewer created, URL params handled). */
export async function waitLoaded(page, timeout = 120_000) {
  await page.waitForFunction(() => document.body.dataset.loaded === '1', null, { timeout });
}

/**
 * Statistics of the 3D canvas pixels: how many differ from the background.
 * Reads the canvas through a screenshot (works for WebGPU and WebGL2 canvases).
 */
export async function canvasStats(page, selector = '#view') {
  const png = await page.locator(selector).screenshot();
  return page.evaluate(async (b64) => {
    const img = new Image();
    img.src = `data:image/png;base64,${b64}`;
    await img.decode();
    const c = document.createElement('canvas');
    c.width = img.width; c.height = img.height;
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    const d = g.getImageData(0, 0, c.width, c.height).data;
    // The background is a dark gradient; points and Gaussians are bright or saturated.
    let lit = 0, sum = 0;
    const hist = new Map();
    for (let i = 0; i < d.length; i += 4) {
      const r = d[i], gg = d[i + 1], b = d[i + 2];
      const lum = 0.299 * r + 0.587 * gg + 0.114 * b;
      const sat = Math.max(r, gg, b) - Math.min(r, gg, b);
      if (lum > 70 || sat > 60) lit++;
      sum += lum;
      const key = ((r >> 4) << 8) | ((gg >> 4) << 4) | (b >> 4);
      hist.set(key, (hist.get(key) || 0) + 1);
    }
    return { lit, total: d.length / 4, mean: sum / (d.length / 4), colors: hist.size };
  }, png.toString('base64'));
}

/** A PNG screenshot of the 3D canvas (works for WebGPU and WebGL2 canvases). */
export async function canvasPng(page, selector = '#view') {
  return page.locator(selector).screenshot();
}

/** Number of pixels that differ (any channel by more than `tol`) between two PNGs of equal size. */
export async function pixelDiff(page, pngA, pngB, tol = 24) {
  return page.evaluate(async ([a, b, t]) => {
    const decode = async (b64) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const c = document.createElement('canvas');
      c.width = img.width; c.height = img.height;
      const g = c.getContext('2d');
      g.drawImage(img, 0, 0);
      return g.getImageData(0, 0, c.width, c.height);
    };
    const A = await decode(a), B = await decode(b);
    if (A.width !== B.width || A.height !== B.height) return A.width * A.height;
    let n = 0;
    for (let i = 0; i < A.data.length; i += 4) {
      if (Math.abs(A.data[i] - B.data[i]) > t || Math.abs(A.data[i + 1] - B.data[i + 1]) > t
        || Math.abs(A.data[i + 2] - B.data[i + 2]) > t) n++;
    }
    return n;
  }, [pngA.toString('base64'), pngB.toString('base64'), tol]);
}

export async function shot(page, name) {
  const file = path.join(ARTIFACTS, `${name}.png`);
  await page.screenshot({ path: file });
  return file;
}

/** The entries of a stored (uncompressed) zip, as the page writes them: [{name, bytes}]. */
export function unzipStored(buf) {
  const out = [];
  let o = 0;
  while (o + 30 <= buf.length && buf.readUInt32LE(o) === 0x04034b50) {
    const method = buf.readUInt16LE(o + 8);
    if (method !== 0) throw new Error(`zip entry at ${o}: method ${method}, not stored`);
    const size = buf.readUInt32LE(o + 18);
    const nameLen = buf.readUInt16LE(o + 26);
    const extraLen = buf.readUInt16LE(o + 28);
    const name = buf.subarray(o + 30, o + 30 + nameLen).toString('utf8');
    const start = o + 30 + nameLen + extraLen;
    out.push({ name, bytes: buf.subarray(start, start + size) });
    o = start + size;
  }
  return out;
}
