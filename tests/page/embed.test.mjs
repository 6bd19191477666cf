// Embed mode (`?embed=1`, www/js/embed.js): the page as an interactive figure in another
// page's iframe. An example fitted in place shows only the view, the timeline and the
// card (the fit's progress, then the joints' sliders); `play=1` plays the frames; a shared
// model in a real iframe opens without scrolling its host page; `play=joints` and
// `play=together` move the joints until a slider is touched; errors show over the view;
// the full page's "Embed code" gives an iframe that opens the same model, or, for an
// example fitted on the page, one that fits it again with the same settings to the same
// result.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { startServer, launch, newPage, waitLoaded, canvasStats, canvasPng, pixelDiff, shot } from './helpers.mjs';

let srv, browser;
before(async () => { srv = await startServer(); browser = await launch(); });
after(async () => { await browser?.close(); srv?.server.close(); });

let modelJson = null; // the fitted laptop's result, shared by the later tests

/** Serves `text` as /shared/model.json to every page of the context (iframes too). */
async function serveModel(context, text) {
  // Match on the path: a glob would also match the page URL, whose query names the model.
  await context.route((url) => url.pathname === '/shared/model.json', (r) => r.fulfill({ body: text, contentType: 'application/json' }));
}

const visible = (page, sel) => page.locator(sel).isVisible();

/** What the page copies goes to `window.copied` (headless Chromium has no clipboard to read). */
async function recordClipboard(page) {
  await page.addInitScript(() => {
    window.copied = [];
    Object.defineProperty(navigator, 'clipboard', { value: { writeText: async (s) => { window.copied.push(s); } } });
  });
}

/** The src of the iframe the page copied last ("Embed code"). */
async function copiedIframeSrc(page) {
  await page.waitForFunction(() => window.copied.length >= 1);
  const code = await page.evaluate(() => window.copied.at(-1));
  const src = code.match(/^<iframe src="([^"]+)"/)?.[1]?.replace(/&amp;/g, '&');
  assert.ok(src, `an iframe: ${code}`);
  return src;
}

test('an example fitted in an embedded figure shows the view, the timeline and its joints only', { timeout: 600_000 }, async () => {
  const { page, errors, context } = await newPage(browser, { width: 720, height: 480 });
  // The link's fit settings (settings.js) keep the test short: the laptop has 2 parts.
  await page.goto(`${srv.base}/?example=laptop&fit=1&embed=1&play=1&quality=fast&parts=2..4`);
  await waitLoaded(page);
  assert.equal(await visible(page, '.topbar'), false, 'no top bar');
  assert.equal(await visible(page, '.panel'), false, 'no panel');
  const box = await page.locator('#view').boundingBox();
  assert.deepEqual([box.x, box.y, box.width, box.height], [0, 0, 720, 480], 'the view fills the frame');
  // While the fit runs, the card holds its progress and its Cancel button.
  await page.waitForFunction(() => /Fitting/.test(document.querySelector('#embed-toggle').textContent));
  assert.equal(await visible(page, '#btn-cancel'), true);
  assert.equal(await visible(page, '#stage-list'), true);
  await page.waitForFunction(() => /^Joints/.test(document.querySelector('#embed-toggle').textContent), null, { timeout: 540_000 });
  const notes = await page.evaluate(() => window.gsart.state.model.info().notes.join('\n'));
  assert.match(notes, /m = \d of \[2, 4\]/, 'the fit tried the link\'s part counts');
  const njoints = await page.evaluate(() => window.gsart.state.model.joints().length);
  assert.ok(njoints >= 1, 'the laptop has its hinge');
  assert.equal(await page.locator('#embed-toggle').textContent(), `Joints (${njoints})`);
  assert.equal(await page.locator('#embed-card input[type=range]').count(), njoints);
  assert.equal(await visible(page, '#stage-list'), false, 'the progress is gone');
  assert.equal(await visible(page, '#timeline'), true);
  // play=1: the fitted model's frames play.
  assert.equal(await page.locator('#btn-play').getAttribute('aria-label'), 'Pause');
  const k0 = await page.evaluate(() => window.gsart.state.current);
  await page.waitForFunction((k) => window.gsart.state.current !== k, k0);
  // A slider stops the play (which would put the frame's states back) and re-poses.
  const slider = page.locator('#embed-card input[type=range]').first();
  await slider.evaluate((el) => { el.value = el.min; el.dispatchEvent(new Event('input', { bubbles: true })); });
  assert.equal(await page.locator('#btn-play').getAttribute('aria-label'), 'Play');
  await page.waitForTimeout(500);
  const a = await canvasPng(page);
  await slider.evaluate((el) => { el.value = el.max; el.dispatchEvent(new Event('input', { bubbles: true })); });
  await page.waitForTimeout(500);
  assert.ok(await pixelDiff(page, a, await canvasPng(page)) > 100, 'the slider re-poses the model');
  await shot(page, 'embed-example');
  // The link opens the same example in the full page.
  const href = new URL(await page.locator('#embed-open').getAttribute('href'));
  assert.equal(href.searchParams.get('example'), 'laptop');
  assert.equal(href.searchParams.get('fit'), '1');
  assert.equal(href.searchParams.get('quality'), 'fast');
  assert.equal(href.searchParams.get('embed'), null);
  modelJson = await page.evaluate(() => window.gsart.state.model.to_json(true));
  assert.deepEqual(errors, []);
  await context.close();
});

test('a shared model in an iframe opens with its sliders and leaves the host page where it was', { timeout: 120_000 }, async (t) => {
  if (!modelJson) { t.skip('needs the fitted model of the previous test'); return; }
  const { page, errors, context } = await newPage(browser, { width: 900, height: 700 });
  await serveModel(context, modelJson);
  // A host page taller than the window, the figure below the fold (a small one, so its
  // card starts folded).
  await context.route((url) => url.pathname === '/host.html', (r) => r.fulfill({
    contentType: 'text/html',
    body: '<!doctype html><body style="margin:0"><div style="height:1500px">Paper text</div>'
      + '<iframe src="/?model=/shared/model.json&embed=1&title=Figure%203" width="420" height="300" style="border:0"></iframe>'
      + '<div style="height:1500px"></div></body>',
  }));
  await page.goto(`${srv.base}/host.html`);
  const frame = page.frames().find((f) => f !== page.mainFrame());
  await frame.waitForFunction(() => document.body.dataset.loaded === '1', null, { timeout: 60_000 });
  await frame.waitForSelector('#embed-card.has-result');
  await page.waitForTimeout(500);
  assert.equal(await page.evaluate(() => window.scrollY), 0, 'opening the model does not scroll the host page');
  assert.equal(await frame.locator('#hud-title').textContent(), 'Figure 3', 'the link\'s title');
  // Folded in a small figure; one click shows the sliders.
  assert.equal(await frame.locator('#embed-toggle').getAttribute('aria-expanded'), 'false');
  assert.equal(await frame.locator('#joint-list').isVisible(), false);
  await page.evaluate(() => window.scrollTo(0, 1300));
  await frame.locator('#embed-toggle').click();
  assert.equal(await frame.locator('#embed-toggle').getAttribute('aria-expanded'), 'true');
  assert.ok(await frame.locator('#joint-list input[type=range]').first().isVisible());
  assert.ok((await canvasStats(frame)).lit > 500, 'the figure shows the model');
  assert.deepEqual(errors, []);
  await context.close();
});

test('an embedded figure says what is wrong over the view', async () => {
  const { page, context } = await newPage(browser, { width: 600, height: 400 });
  await page.goto(`${srv.base}/?model=/missing/model.json&embed=1`);
  await waitLoaded(page);
  assert.equal(await visible(page, '#view-message'), true);
  const text = await page.locator('#view-message').innerText();
  assert.match(text, /Could not open the model/);
  assert.match(text, /missing\/model\.json: HTTP 404/);
  await page.goto(`${srv.base}/?example=drawer&embed=1`);
  await waitLoaded(page);
  assert.match(await page.locator('#view-message').innerText(), /Could not generate the example[\s\S]*drawer/);
  await page.goto(`${srv.base}/?embed=1`);
  await waitLoaded(page);
  assert.match(await page.locator('#view-message').innerText(), /needs \?model=URL/);
  assert.equal(await visible(page, '#embed-card'), false);
  // A link's setting that cannot be used is named, and the form keeps its default.
  await page.goto(`${srv.base}/?example=laptop&quality=best&seed=4`);
  await waitLoaded(page);
  assert.match(await page.locator('#toast').innerText(), /Ignored in the link: quality=best: use fast, balanced, paper/);
  assert.equal(await page.locator('input[name=quality]:checked').getAttribute('value'), 'balanced');
  assert.equal(await page.locator('#seed').inputValue(), '4');
  await context.close();
});

test('the full page gives the embed code of a shared model', { timeout: 120_000 }, async (t) => {
  if (!modelJson) { t.skip('needs the fitted model of the first test'); return; }
  const { page, errors, context } = await newPage(browser);
  await serveModel(context, modelJson);
  await recordClipboard(page);
  await page.goto(`${srv.base}/?model=/shared/model.json`);
  await waitLoaded(page);
  await page.waitForSelector('#explore:not([hidden])');
  await page.locator('#btn-embed').click();
  const src = await copiedIframeSrc(page);
  const url = new URL(src);
  assert.equal(url.searchParams.get('embed'), '1');
  assert.equal(url.searchParams.get('model'), `${srv.base}/shared/model.json`);
  assert.match(url.hash, /cam=/, 'the camera comes along');
  // The code opens the model as a figure.
  await page.goto(src);
  await waitLoaded(page);
  await page.waitForSelector('#embed-card.has-result');
  assert.equal(await visible(page, '.panel'), false);
  assert.deepEqual(errors, []);
  await context.close();
});

test('play=joints and play=together move the joints in a figure until a slider is touched', { timeout: 120_000 }, async (t) => {
  if (!modelJson) { t.skip('needs the fitted model of the first test'); return; }
  const { page, errors, context } = await newPage(browser, { width: 640, height: 480 });
  await serveModel(context, modelJson);
  const statesOf = () => page.evaluate(() => Array.from(window.gsart.state.states));
  for (const mode of ['joints', 'together']) {
    await page.goto(`${srv.base}/?model=/shared/model.json&embed=1&play=${mode}`);
    await waitLoaded(page);
    await page.waitForSelector('#embed-card.has-result');
    const frameStates = await page.evaluate(() => Array.from(window.gsart.state.frameStates));
    assert.equal(await page.locator('#btn-play').getAttribute('aria-label'), 'Pause', `${mode} plays`);
    const k = await page.evaluate(() => window.gsart.state.current);
    // The states move through the joints' ranges; the frame stays.
    const seen = [];
    for (let i = 0; i < 6; i++) { await page.waitForTimeout(250); seen.push(await statesOf()); }
    const child = await page.evaluate(() => window.gsart.state.model.joints()[0].child);
    const values = new Set(seen.map((s) => s[child].toFixed(4)));
    assert.ok(values.size >= 4, `${mode}: the first joint moves (${[...values]})`);
    assert.ok(seen.some((s) => Math.abs(s[child] - frameStates[child]) > 0.05), `${mode}: away from the frame's state`);
    assert.equal(await page.evaluate(() => window.gsart.state.current), k);
    // One joint at a time is highlighted, as when hovered; all at once, none.
    const hot = () => page.evaluate(() => window.gsart.state.hot);
    assert.equal(await hot(), mode === 'joints' ? child : -1);
    // A slider stops it where the slider puts it.
    const slider = page.locator('#embed-card input[type=range]').first();
    await slider.evaluate((el) => { el.value = el.min; el.dispatchEvent(new Event('input', { bubbles: true })); });
    assert.equal(await page.locator('#btn-play').getAttribute('aria-label'), 'Play');
    const held = await statesOf();
    await page.waitForTimeout(400);
    assert.deepEqual(await statesOf(), held, `${mode}: stopped`);
    assert.equal(await hot(), -1, 'the highlight goes with the play');
  }
  assert.deepEqual(errors, []);
  await context.close();
});

test('a model opened from a file is saved for its figure, whose code leaves its address to fill in', { timeout: 120_000 }, async (t) => {
  if (!modelJson) { t.skip('needs the fitted model of the first test'); return; }
  const { page, errors, context } = await newPage(browser);
  await recordClipboard(page);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  await page.locator('#file-input').setInputFiles({ name: 'figure.gsart.json', mimeType: 'application/json', buffer: Buffer.from(modelJson) });
  await page.waitForSelector('#explore:not([hidden])');
  const [dl] = await Promise.all([page.waitForEvent('download'), page.locator('#btn-embed').click()]);
  assert.equal(dl.suggestedFilename(), 'figure.gsart.json', 'the result JSON, named once');
  const src = await copiedIframeSrc(page);
  assert.match(src, /\?model=https:\/\/YOUR\.HOST\/PATH\/figure\.gsart\.json&embed=1#cam=/, 'a readable place-holder');
  assert.match(await page.locator('#toast').innerText(), /Saved figure\.gsart\.json: put it online/);
  assert.deepEqual(errors, []);
  await context.close();
});

test('an example fitted on the page embeds as a figure that fits it again to the same result', { timeout: 600_000 }, async () => {
  const { page, errors, context } = await newPage(browser);
  await recordClipboard(page);
  await page.goto(`${srv.base}/?example=laptop`);
  await waitLoaded(page);
  // Settings changed after the example was generated (with seed 0).
  await page.locator('label:has(input[value=fast])').click();
  await page.getByLabel('Automatic part range').uncheck();
  await page.getByLabel('Minimum part count').fill('2');
  await page.getByLabel('Maximum part count').fill('3');
  await page.getByLabel('Seed').fill('1');
  await page.locator('#btn-fit').click();
  await page.waitForFunction(() => /Done in/.test(document.querySelector('#fit-status').innerText), null, { timeout: 540_000 });
  const mine = await page.evaluate(() => JSON.parse(window.gsart.state.model.to_json(false)));
  await page.locator('#btn-embed').click();
  const src = await copiedIframeSrc(page);
  const q = new URL(src).searchParams;
  assert.deepEqual(Object.fromEntries(q), { example: 'laptop', quality: 'fast', seed: '1', parts: '2..3', example_seed: '0', fit: '1', embed: '1' });
  await page.goto(src);
  await waitLoaded(page);
  await page.waitForSelector('#embed-card.has-result', { timeout: 540_000 });
  const theirs = await page.evaluate(() => JSON.parse(window.gsart.state.model.to_json(false)));
  assert.deepEqual(theirs.labels, mine.labels, 'the same segmentation');
  assert.deepEqual(theirs.joints, mine.joints, 'the same joints');
  assert.deepEqual(errors, []);
  await context.close();
});
