// Smoke: the page opens an example from the URL, shows its points in the 3D view,
// names the backend, and logs no errors. Also the keyboard shortcuts.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { startServer, launch, newPage, waitLoaded, canvasStats, canvasPng, pixelDiff, shot } from './helpers.mjs';

let srv, browser;
before(async () => { srv = await startServer(); browser = await launch(); });
after(async () => { await browser?.close(); srv?.server.close(); });

test('?example=laptop loads, shows points, no console errors', async () => {
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/?example=laptop`);
  await waitLoaded(page);
  // The example's frames are listed with point counts.
  const rows = page.locator('#frame-list li');
  assert.ok(await rows.count() >= 2, 'the example lists at least 2 frames');
  assert.match(await rows.first().innerText(), /\d[\d,]* pts/);
  assert.equal(await page.locator('#frame-list .ferror').count(), 0);
  // Backend badge.
  const badge = (await page.locator('#backend').innerText()).trim();
  assert.ok(['WebGPU', 'WebGL2'].includes(badge), `backend badge says ${badge}`);
  // Points drawn: a clear share of the canvas is lit.
  await page.waitForTimeout(500);
  const st = await canvasStats(page);
  assert.ok(st.lit > 500, `expected lit pixels in the 3D view, got ${st.lit} of ${st.total}`);
  assert.equal(await page.locator('#btn-fit').isDisabled(), false, 'Fit is enabled with a loaded example');
  await shot(page, 'smoke-laptop');
  assert.deepEqual(errors, []);
  await context.close();
});

test('keyboard: arrows step frames, shift+arrows orbit, + zooms, ? opens the shortcuts, R keeps the object in view', async () => {
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/?example=laptop`);
  await waitLoaded(page);
  await page.locator('#view').focus();
  assert.equal((await page.locator('#frame-label').innerText()).trim().split(' ')[0], '1');
  const before = await canvasPng(page);
  await page.keyboard.press('ArrowRight');
  await page.keyboard.press('ArrowRight');
  assert.equal((await page.locator('#frame-label').innerText()).trim().split(' ')[0], '3');
  await page.waitForTimeout(300);
  const after = await canvasPng(page);
  assert.ok(await pixelDiff(page, before, after) > 50, 'another frame shows different pixels');
  await page.keyboard.press('ArrowLeft');
  assert.equal((await page.locator('#frame-label').innerText()).trim().split(' ')[0], '2');
  await page.keyboard.press('?');
  assert.equal(await page.locator('#help').isVisible(), true, '? opens the shortcut overlay');
  await shot(page, 'smoke-help');
  await page.keyboard.press('Escape');
  assert.equal(await page.locator('#help').isVisible(), false);
  // Orbit with the mouse, then R resets: the view changes and comes back.
  const box = await page.locator('#view').boundingBox();
  const c0 = await canvasPng(page);
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 160, box.y + box.height / 2 + 40, { steps: 8 });
  await page.mouse.up();
  await page.waitForTimeout(300);
  const c1 = await canvasPng(page);
  assert.ok(await pixelDiff(page, c0, c1) > 50, 'dragging orbits the camera');
  assert.match(await page.evaluate(() => location.hash), /cam=/, 'the camera is kept in the URL hash');
  // Keyboard camera: Shift+arrows orbit, + zooms; the frame does not change.
  const frameBefore = (await page.locator('#frame-label').innerText()).trim();
  await page.keyboard.press('Shift+ArrowRight');
  await page.keyboard.press('Shift+ArrowRight');
  await page.waitForTimeout(300);
  const c2 = await canvasPng(page);
  assert.ok(await pixelDiff(page, c1, c2) > 50, 'Shift+arrows orbit the camera');
  assert.equal((await page.locator('#frame-label').innerText()).trim(), frameBefore);
  await page.keyboard.press('+');
  await page.waitForTimeout(300);
  assert.ok(await pixelDiff(page, c2, await canvasPng(page)) > 50, '+ zooms');
  await page.keyboard.press('r');
  await page.waitForTimeout(300);
  const st = await canvasStats(page);
  assert.ok(st.lit > 500, 'after R the object is in view');
  assert.deepEqual(errors, []);
  await context.close();
});

test('a page without any graphics backend says so clearly', async () => {
  const { page, context } = await newPage(browser);
  await page.addInitScript(() => {
    Object.defineProperty(navigator, 'gpu', { value: undefined });
    const orig = HTMLCanvasElement.prototype.getContext;
    HTMLCanvasElement.prototype.getContext = function (kind, ...rest) {
      if (kind === 'webgl2' || kind === 'webgl' || kind === 'webgpu') return null;
      return orig.call(this, kind, ...rest);
    };
  });
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  const msg = page.locator('#view-message');
  assert.equal(await msg.isVisible(), true);
  assert.match(await msg.innerText(), /neither WebGPU nor WebGL2/);
  assert.match(await page.locator('#backend').innerText(), /no 3D/);
  await shot(page, 'smoke-no-backend');
  await context.close();
});

test('clicking an example chip loads it and puts it in the URL', async () => {
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  assert.equal(await page.locator('#empty-hint').isVisible(), true, 'an empty page invites a drop');
  await page.getByLabel('Example cabinet').click();
  await page.waitForFunction(() => /cabinet \(example\)/.test(document.querySelector('#sequence-summary').innerText));
  assert.match(page.url(), /[?&]example=cabinet/);
  assert.equal(await page.locator('#empty-hint').isVisible(), false);
  await page.waitForTimeout(300);
  assert.ok((await canvasStats(page)).lit > 500);
  assert.deepEqual(errors, []);
  await context.close();
});

test('narrow screens stack the view above the panel', async () => {
  const { page, errors, context } = await newPage(browser, { width: 420, height: 860 });
  await page.goto(`${srv.base}/?example=laptop`);
  await waitLoaded(page);
  const view = await page.locator('#view').boundingBox();
  const panel = await page.locator('.panel').boundingBox();
  assert.ok(panel.y >= view.y + view.height - 1, 'the panel is below the view');
  assert.ok(view.width >= 400, 'the view spans the width');
  await shot(page, 'smoke-narrow');
  assert.deepEqual(errors, []);
  await context.close();
});
