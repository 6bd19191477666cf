// The viewer draws on both backends: WebGPU (default where available) and WebGL2
// (forced with ?backend=webgl2, as on browsers without WebGPU). Pixel check on each.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { startServer, launch, newPage, waitLoaded, canvasStats, shot } from './helpers.mjs';

let srv, browser;
before(async () => { srv = await startServer(); browser = await launch(); });
after(async () => { await browser?.close(); srv?.server.close(); });

for (const [query, expected] of [['', 'WebGPU'], ['&backend=webgl2', 'WebGL2']]) {
  test(`draws points with ${expected}`, async () => {
    const { page, errors, context } = await newPage(browser);
    await page.goto(`${srv.base}/?example=arm${query}`);
    await waitLoaded(page);
    assert.equal((await page.locator('#backend').innerText()).trim(), expected);
    await page.waitForTimeout(500);
    const st = await canvasStats(page);
    assert.ok(st.lit > 500, `${expected}: expected lit pixels, got ${st.lit}`);
    // Screenshot export works on this backend and is not blank.
    const [dl] = await Promise.all([page.waitForEvent('download'), page.locator('#btn-screenshot').click()]);
    assert.match(dl.suggestedFilename(), /\.png$/);
    const file = await dl.path();
    const png = (await import('node:fs')).readFileSync(file);
    assert.ok(png.length > 2000, 'the PNG has content');
    const lit = await page.evaluate(async (b64) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const c = document.createElement('canvas');
      c.width = img.width; c.height = img.height;
      const g = c.getContext('2d');
      g.drawImage(img, 0, 0);
      const d = g.getImageData(0, 0, c.width, c.height).data;
      let n = 0;
      for (let i = 0; i < d.length; i += 4) if (d[i] + d[i + 1] + d[i + 2] > 210) n++;
      return n;
    }, png.toString('base64'));
    assert.ok(lit > 500, `the exported PNG shows the points (${lit} lit pixels)`);
    await shot(page, `backend-${expected.toLowerCase()}`);
    assert.deepEqual(errors, []);
    await context.close();
  });
}
