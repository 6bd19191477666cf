// Times a whole fit of a bench-dev sequence in the real page (headless Chromium, wasm
// in Web Workers): load the frames through the file input, pick a quality, fit, and
// report the wall time and the metrics the page shows. A benchmark, not a test.
// Usage: node bench/page-fit.mjs [SEQ_DIR] [fast|balanced|paper]   (after `npm run build`)
import fs from 'node:fs';
import path from 'node:path';
import { startServer, launch, newPage, waitLoaded, benchDev } from '../tests/page/helpers.mjs';

const seq = process.argv[2] ?? path.join(benchDev() ?? '../shared/bench-dev', 'full', 'finger_edu_00');
const quality = process.argv[3] ?? 'fast';
const srv = await startServer();
const browser = await launch();
try {
  const { page } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  const files = fs.readdirSync(seq).filter((f) => /\.ply$/.test(f) || f === 'gt.json').map((f) => path.join(seq, f));
  await page.locator('#file-input').setInputFiles(files);
  await page.waitForFunction(() => document.querySelectorAll('#frame-list li[data-index]').length >= 2);
  await page.locator(`label:has(input[value=${quality}])`).click();
  const workers = await page.evaluate(() => Math.min(navigator.hardwareConcurrency || 2, 8));
  const t0 = Date.now();
  await page.locator('#btn-fit').click();
  await page.waitForSelector('#explore:not([hidden])', { timeout: 60 * 60_000 });
  const seconds = (Date.now() - t0) / 1000;
  const summary = await page.locator('#explore').innerText();
  const metrics = await page.locator('#metrics').innerText().catch(() => '');
  const status = await page.locator('#fit-status').innerText();
  console.log(JSON.stringify({ sequence: seq, quality, workers, seconds, status, summary: summary.split('\n').slice(0, 3), metrics }, null, 1));
} finally {
  await browser.close();
  srv.server.close();
}
