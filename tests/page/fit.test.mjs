// The whole product flow on a built-in example with the fast preset: fit (progress,
// live Gaussians), results (tree, joints, metrics), a slider re-poses the model,
// exports (JSON, PLY zip, URDF), and the exported JSON opens again (file and ?model=URL).
// Also: cancelling a fit leaves the page usable with the frames loaded, fast tries
// every part count on occluded frames (the core's rule), fast tries one part count
// above the range when the top of it fails, a poorly explained balanced fit is done
// again from another seed (and a third time from the last frame when the kept attempt
// still explains little), a long sequence is fitted on key frames and the others
// tracked, and the page's results equal the CLI's bit for bit (talos full, the
// procedural cabinet and a long laptop sequence, so101 occluded).
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { execFileSync, spawnSync } from 'node:child_process';
import { startServer, launch, newPage, waitLoaded, canvasStats, canvasPng, pixelDiff, shot, ARTIFACTS, ROOT, benchDev, unzipStored } from './helpers.mjs';

let srv, browser;
before(async () => { srv = await startServer(); browser = await launch(); });
after(async () => { await browser?.close(); srv?.server.close(); });

const FIT_TIMEOUT = 20 * 60_000;
let exported = null; // path of the exported result JSON

async function download(page, button) {
  const [dl] = await Promise.all([page.waitForEvent('download'), page.locator(button).click()]);
  const file = path.join(ARTIFACTS, `export-${dl.suggestedFilename()}`);
  await dl.saveAs(file);
  return file;
}

test('fit an example end to end (fast), explore, re-pose, export', { timeout: FIT_TIMEOUT }, async () => {
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/?example=laptop`);
  await waitLoaded(page);
  await page.locator('label:has(input[value=fast])').click();
  // A manual part range (the laptop has 2 parts) keeps the test short.
  await page.getByLabel('Automatic part range').uncheck();
  await page.getByLabel('Minimum part count').fill('2');
  await page.getByLabel('Maximum part count').fill('4');
  // Two fits per part count (restarts), the better one counting.
  await page.getByLabel('Fits per part count').selectOption('2');
  // The Gaussians start on the medial-axis estimate (the core's option, off by default).
  await page.getByLabel('Start on the medial axis').check();
  // Record what the live loss chart is given.
  await page.evaluate(() => {
    const c = window.gsart.state.chart;
    const add = c.add.bind(c);
    window.plotted = [];
    c.add = (key, label, x, y, o) => {
      if (Number.isFinite(y)) window.plotted.push([key, y, x, c.title]);
      add(key, label, x, y, o);
    };
  });
  await page.locator('#btn-fit').click();
  // The view as the fit starts, to compare with views taken while Step 1 runs.
  let a = await canvasPng(page);
  assert.equal(await page.locator('#btn-cancel').isVisible(), true);
  assert.equal(await page.locator('#progress').isVisible(), true);
  // The Gaussians move in the view while Step 1 runs.
  await page.waitForFunction(() => /running|left/.test(document.querySelector('#stage-list').innerText), null, { timeout: 120_000 });
  // Fast tries the two ends of the range (the core's rule).
  assert.match(await page.locator('#fit-status').innerText(), /m = 2, 4 of 2…4/);
  assert.match(await page.locator('#fit-status').innerText(), /best of 2 fits each, started on the medial axis/);
  // A view taken while a Step-1 candidate still runs must differ from the first one
  // (or from the one before it). Sampled back to back, not at fixed times: a view takes
  // ~0.5 s to capture under SwiftShader, and on a quiet machine the laptop's Step 1
  // ends within ~3 s, after which the final result changes the view anyway.
  const step1Running = () => page.evaluate(() =>
    /running/.test(document.querySelector('#stage-list .stage-row .seta')?.textContent ?? ''));
  let moving = 0;
  let views = 0;
  while (await step1Running()) {
    const b = await canvasPng(page);
    if (!(await step1Running())) break;
    views++;
    if (views === 1) await shot(page, 'fit-running');
    moving = await pixelDiff(page, a, b);
    if (moving > 0) break;
    a = b;
  }
  await page.waitForSelector('#explore:not([hidden])', { timeout: FIT_TIMEOUT });
  assert.ok(moving > 0, `the view updates during the fit (${views} views taken while Step 1 ran)`);
  await page.waitForTimeout(400);
  await shot(page, 'fit-done');
  // The loss chart got Step 1's transfer loss per candidate and Step 3's refinement
  // loss, all positive: the warm-up's (negative) L_MLE and terms a step did not compute
  // (once reported as 0) are not plotted.
  const plotted = await page.evaluate(() => window.plotted);
  const keys = new Set(plotted.map(([k]) => k));
  // Each candidate's Chamfer phase and EMD phase are lines of their own (the two losses
  // differ in scale), and so is each pass of Step 3's refinement.
  for (const k of ['m2', 'm2:emd', 'm4', 'm4:emd', 'joints1']) {
    assert.ok(keys.has(k), `chart series ${k} missing: ${[...keys]}`);
  }
  const bad = plotted.filter(([, y]) => !(y > 0));
  assert.equal(bad.length, 0, `non-positive losses plotted: ${JSON.stringify(bad.slice(0, 5))}`);
  // No line goes back: within a series (and a chart) the iteration fraction only grows.
  const lastX = new Map();
  for (const [k, , x, title] of plotted) {
    const id = `${title}/${k}`;
    assert.ok(!(x < lastX.get(id)), `series ${id} goes back: ${x} after ${lastX.get(id)}`);
    lastX.set(id, x);
  }

  // Results: tree diagram, joints with sliders, metrics (the example has ground truth).
  const nodes = await page.locator('#tree .node').count();
  assert.ok(nodes >= 2, `tree has ${nodes} nodes`);
  const sliders = page.locator('#joint-list input[type=range]');
  assert.ok(await sliders.count() >= 1, 'at least one joint slider');
  assert.equal(await page.locator('#metrics-wrap').isVisible(), true);
  assert.match(await page.locator('#metrics').innerText(), /Rand index/i);
  assert.match(await page.locator('#metrics').innerText(), /Joint types right/i);
  assert.match(await page.locator('#metrics').innerText(), /Joints within 5° and 2 %[^\n]*\n[^\n]*\s+\d+ \/ \d+/i);
  const st = await canvasStats(page);
  assert.ok(st.lit > 500, 'points coloured by part are drawn');

  // A slider re-poses the model live.
  const before = await canvasPng(page);
  await sliders.first().evaluate((el) => { el.value = el.max; el.dispatchEvent(new Event('input', { bubbles: true })); });
  await page.waitForTimeout(400);
  const after = await canvasPng(page);
  const changed = await pixelDiff(page, before, after);
  assert.ok(changed > 100, `moving a joint slider changes the view (${changed} pixels)`);
  assert.match(await page.locator('#hud-sub').innerText(), /re-posed/);
  await shot(page, 'fit-reposed');

  // Exports.
  exported = await download(page, '#btn-export-json');
  const json = JSON.parse(fs.readFileSync(exported, 'utf8'));
  assert.equal(json.format, 'gsart-result');
  assert.equal(json.version, 1);
  assert.equal(json.frames, json.labels.length);
  assert.equal(json.info.restarts, 2, 'each part count was fitted twice');
  assert.equal(json.info.medial_init, true, 'the fit started on the medial axis');
  assert.ok(json.info.notes.some((n) => /medial-axis estimate/.test(n)), 'the notes say so');
  // Both ends were finished and the second look kept one of them (the page runs the
  // core's rule on the two finished results).
  const look = json.info.second_look;
  assert.ok(look && [2, 4].includes(look.taken), `second look: ${JSON.stringify(look)}`);
  assert.equal(look.taken, json.info.m, 'the kept result is the candidate the look took');
  assert.ok(json.info.notes.some((n) => /^second look/.test(n)), 'the notes say what was compared');
  assert.match(await page.locator('#result-summary').innerText(), new RegExp(`chosen m = ${look.taken} Gaussians`));
  assert.ok(Array.isArray(json.joints) && json.joints.length >= 1);
  assert.ok(Array.isArray(json.points), 'the export carries the canonical points');
  const zipFile = await download(page, '#btn-export-ply');
  const zip = fs.readFileSync(zipFile);
  assert.equal(zip.subarray(0, 2).toString(), 'PK');
  assert.ok(zip.includes(Buffer.from('property int part')), 'segmented PLY frames have a part property');
  // The URDF comes in a zip with each link's convex hull as an STL mesh.
  const urdfZip = await download(page, '#btn-export-urdf');
  assert.match(path.basename(urdfZip), /laptop_urdf\.zip$/);
  const entries = unzipStored(fs.readFileSync(urdfZip));
  const urdf = entries.find((e) => e.name === 'laptop.urdf')?.bytes.toString('utf8');
  assert.match(urdf ?? '', /<robot[\s\S]*<joint[\s\S]*<axis/);
  const meshes = entries.filter((e) => /^laptop_meshes\/part_\d+\.stl$/.test(e.name));
  assert.equal(meshes.length, json.parts, 'a mesh per part');
  for (const m of meshes) assert.ok(urdf.includes(`<mesh filename="${m.name}"/>`), m.name);
  // yourdfpy (a standard parser, with trimesh) loads the URDF and every mesh.
  const dir = fs.mkdtempSync(path.join(ARTIFACTS, 'urdf-'));
  for (const e of entries) {
    fs.mkdirSync(path.dirname(path.join(dir, e.name)), { recursive: true });
    fs.writeFileSync(path.join(dir, e.name), e.bytes);
  }
  fs.writeFileSync(path.join(dir, 'states.json'), '{}');
  const check = spawnSync('python3', [path.join(ROOT, 'tests', 'urdf_check.py'), path.join(dir, 'laptop.urdf'), path.join(dir, 'states.json')], { encoding: 'utf8' });
  if (check.status === 3 && !process.env.CI) console.log('# yourdfpy not installed: the URDF was not loaded');
  else {
    assert.equal(check.status, 0, check.stderr);
    const read = JSON.parse(check.stdout);
    assert.equal(Object.keys(read.meshes).length, json.parts);
    for (const m of Object.values(read.meshes)) assert.ok(m.watertight && m.volume > 0, JSON.stringify(m));
  }
  assert.deepEqual(errors, []);
  await context.close();
});

test('an exported result opens again from a file and from ?model=URL', { timeout: 120_000 }, async (t) => {
  if (!exported) { t.skip('needs the export of the previous test'); return; }
  const text = fs.readFileSync(exported, 'utf8');
  const njoints = JSON.parse(text).joints.length;
  {
    const { page, errors, context } = await newPage(browser);
    await page.goto(`${srv.base}/`);
    await waitLoaded(page);
    await page.locator('#file-input').setInputFiles(exported);
    await page.waitForSelector('#explore:not([hidden])');
    assert.equal(await page.locator('#joint-list input[type=range]').count(), njoints);
    await page.waitForTimeout(300);
    assert.ok((await canvasStats(page)).lit > 500, 'the shared result shows its points');
    const before = await canvasPng(page);
    await page.locator('#joint-list input[type=range]').first()
      .evaluate((el) => { el.value = el.min; el.dispatchEvent(new Event('input', { bubbles: true })); });
    await page.waitForTimeout(300);
    assert.ok(await pixelDiff(page, before, await canvasPng(page)) > 100, 'its sliders work');
    assert.deepEqual(errors, []);
    await context.close();
  }
  {
    const { page, errors, context } = await newPage(browser);
    // Match on the path: a glob would also match the page URL, whose query names the model.
    await page.route((url) => url.pathname === '/shared/model.json', (r) => r.fulfill({ body: text, contentType: 'application/json' }));
    await page.goto(`${srv.base}/?model=/shared/model.json`);
    await waitLoaded(page);
    await page.waitForSelector('#explore:not([hidden])');
    assert.equal(await page.locator('#joint-list input[type=range]').count(), njoints);
    assert.ok((await canvasStats(page)).lit > 500);
    await shot(page, 'model-url');
    assert.deepEqual(errors, []);
    await context.close();
  }
});

test('a result JSON that is not valid shows an error', async () => {
  const { page, context } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  await page.locator('#file-input').setInputFiles({ name: 'bad.json', mimeType: 'application/json', buffer: Buffer.from('{"format":"gsart-result","version":7}') });
  await page.waitForSelector('#toast:not([hidden])');
  assert.match(await page.locator('#toast').innerText(), /bad\.json/);
  assert.equal(await page.locator('#explore').isVisible(), false);
  await context.close();
});

test('cancelling a fit keeps the page usable with the frames loaded', { timeout: 180_000 }, async () => {
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/?example=cabinet`);
  await waitLoaded(page);
  const n = await page.locator('#frame-list li').count();
  await page.locator('#btn-fit').click();
  await page.waitForFunction(() => /running|left|starting/.test(document.querySelector('#stage-list').innerText));
  await page.waitForTimeout(1000);
  await page.locator('#btn-cancel').click();
  assert.match(await page.locator('#fit-status').innerText(), /Cancelled/);
  assert.equal(await page.locator('#btn-fit').isVisible(), true);
  assert.equal(await page.locator('#btn-fit').isDisabled(), false);
  assert.equal(await page.locator('#frame-list li').count(), n, 'the frames are still loaded');
  await page.waitForTimeout(300);
  assert.ok((await canvasStats(page)).lit > 500, 'the frames are still drawn');
  await page.keyboard.press('ArrowRight');
  assert.equal((await page.locator('#frame-label').innerText()).trim().split(' ')[0], '2');
  assert.deepEqual(errors, []);
  await context.close();
});

const OCCLUDED = benchDev() && path.join(benchDev(), 'occluded', 'so101_00');

test('fast tries every part count on occluded frames, the two ends on full ones', { timeout: 180_000, skip: !OCCLUDED && 'bench-dev not found' }, async () => {
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  await page.locator('label:has(input[value=fast])').click();
  const tried = async () => {
    await page.locator('#btn-fit').click();
    await page.waitForFunction(() => /^Trying/.test(document.querySelector('#fit-status').innerText));
    const text = await page.locator('#fit-status').innerText();
    await page.locator('#btn-cancel').click();
    await page.waitForFunction(() => /Cancelled/.test(document.querySelector('#fit-status').innerText));
    return text;
  };
  // The occluded frames (one camera's view each: their point counts differ).
  const files = fs.readdirSync(OCCLUDED).filter((f) => /^frame_\d+\.ply$/.test(f)).map((f) => path.join(OCCLUDED, f));
  await page.locator('#file-input').setInputFiles(files);
  await page.waitForFunction((n) => document.querySelectorAll('#frame-list li[data-index]').length === n, files.length);
  assert.match(await tried(), /Trying m = 10…15 Gaussians \(\d+ in parallel\), fast quality/);
  // The same robot's full frames: the two ends only.
  await page.locator('#file-input').setInputFiles(files.map((f) => f.replace(`${path.sep}occluded${path.sep}`, `${path.sep}full${path.sep}`)));
  await page.waitForFunction((n) => document.querySelectorAll('#frame-list li[data-index]').length === n
    && /4,096 pts/.test(document.querySelector('#frame-list li').innerText), files.length);
  assert.match(await tried(), /Trying m = 10, 15 of 10…15 Gaussians \(\d+ in parallel\), fast quality/);
  assert.deepEqual(errors, []);
  await context.close();
});

const TALOS = benchDev() && path.join(benchDev(), 'full', 'talos_00');
// The CLI the native tests built (same core), for the native side of the comparisons.
const CLI = ['release', 'debug'].map((p) => path.join(ROOT, 'target', p, 'gsart')).find((p) => fs.existsSync(p));
const NO_CLI = !CLI && 'the gsart CLI is not built';

// `gsart fit DIR --quality Q --seed 0 [--parts A..B]`, then the same frames fitted in
// the page with that quality and range (fast and the automatic range unless told;
// `during(page)` runs while the page fits); both results.
async function cliAndPage(dir, name, during = async () => {}, { quality = 'fast', parts = null } = {}) {
  const native = path.join(ARTIFACTS, `${name}-native.json`);
  const args = ['fit', dir, '--out', native, '--quality', quality, '--seed', '0', '--quiet'];
  if (parts) args.push('--parts', `${parts[0]}..${parts[1]}`);
  execFileSync(CLI, args, { stdio: 'ignore' });
  const want = JSON.parse(fs.readFileSync(native, 'utf8'));
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  await page.locator(`label:has(input[value=${quality}])`).click();
  if (parts) {
    await page.getByLabel('Automatic part range').uncheck();
    await page.getByLabel('Minimum part count').fill(String(parts[0]));
    await page.getByLabel('Maximum part count').fill(String(parts[1]));
  }
  const files = fs.readdirSync(dir).filter((f) => /^frame_\d+\.ply$/.test(f)).map((f) => path.join(dir, f));
  await page.locator('#file-input').setInputFiles(files);
  await page.waitForFunction((n) => document.querySelectorAll('#frame-list li[data-index]').length === n, files.length);
  await page.locator('#btn-fit').click();
  await during(page);
  // The end of the whole fit (an earlier attempt's model shows while a later one runs).
  await page.waitForFunction(() => /Done in/.test(document.querySelector('#fit-status').innerText), null, { timeout: FIT_TIMEOUT });
  await page.waitForSelector('#explore:not([hidden])');
  assert.equal(await page.locator('#provisional').count(), 0, 'the final result is not marked provisional');
  const status = await page.locator('#fit-status').innerText();
  const got = JSON.parse(fs.readFileSync(await download(page, '#btn-export-json'), 'utf8'));
  const movedRunners = await page.evaluate(() => window.gsart.state.movedRunners);
  const workers = await page.evaluate(() => Math.min(navigator.hardwareConcurrency || 2, 8));
  assert.deepEqual(errors, []);
  await context.close();
  // The whole pipeline gives the CLI's bits: every transcendental function comes from
  // the same pure-Rust libm natively and in wasm (`crate::math`).
  assert.deepEqual(got.info.candidates, want.info.candidates, 'the same candidates and final Chamfers');
  assert.equal(got.info.m, want.info.m);
  assert.deepEqual(got.tree, want.tree, 'the same kinematic tree as the CLI');
  assert.deepEqual(got.poses, want.poses, 'the same poses as the CLI');
  assert.deepEqual(got.labels, want.labels, 'the same labels as the CLI');
  return { got, want, status, movedRunners, workers };
}

test('fast tries one more part count when the top of the range fails, as the CLI does', { timeout: FIT_TIMEOUT, skip: (!TALOS && 'bench-dev not found') || NO_CLI }, async () => {
  // Talos, fit seed 0: m = 15 ends 3× above m = 10's final Chamfer, so m = 20 is tried.
  const { got, status, movedRunners, workers } = await cliAndPage(TALOS, 'talos', (page) => page.waitForFunction(
    () => /m = 15 fitted worse than m = 10 .*: trying m = 20 too/.test(document.querySelector('#fit-status').innerText),
    null, { timeout: FIT_TIMEOUT }));
  assert.deepEqual(got.info.candidates.map((c) => c[0]), [10, 15, 20]);
  // The first worker fitted m = 10 and then m = 20, the best and the runner-up: with a
  // second worker, the runner-up was copied there to finish beside the best, and the
  // result is still the CLI's bit for bit (compared in `cliAndPage`).
  assert.deepEqual(got.info.second_look.best[0], 20);
  assert.deepEqual(got.info.second_look.runner_up[0], 10);
  assert.deepEqual(movedRunners, [workers >= 2]);
  assert.match(status, /Step 1: m = 10 \(.*\), 15 \(.*\), 20 \(/);
  assert.ok(got.info.notes.some((n) => /so m = 20 was tried too/.test(n)), 'the notes say why m = 20 was tried');
});

test('a poorly explained balanced fit is done again from another seed, and a third time from the last frame, as the CLI does', { timeout: FIT_TIMEOUT, skip: NO_CLI }, async () => {
  // The procedural cabinet (generator seed 0) at m = 3–4 leaves 1.35 % of its points
  // unexplained from fit seed 0, above the core's bound (`pipeline::RETRY_UNEXPLAINED`).
  const dir = path.join(ARTIFACTS, 'cabinet-seq');
  fs.rmSync(dir, { recursive: true, force: true });
  execFileSync(CLI, ['synth', 'cabinet', '--seed', '0', '--out', dir], { stdio: 'ignore' });
  let provisional = null;
  const { got, want, status } = await cliAndPage(dir, 'cabinet-retry', async (page) => {
    await page.waitForFunction(
      () => /of the points unexplained: fitting again from seed \d+/.test(document.querySelector('#fit-status').innerText),
      null, { timeout: FIT_TIMEOUT });
    // Meanwhile the first attempt's model is on view, marked provisional, with its sliders.
    provisional = await page.locator('#provisional').innerText();
    assert.ok(await page.locator('#explore').isVisible(), 'the first attempt is explorable');
    assert.ok(await page.locator('#joint-list input[type=range]').count() > 0, 'with its sliders');
    await shot(page, 'fit-second-attempt');
  }, { quality: 'balanced', parts: [3, 4] });
  assert.match(provisional, /^Provisional: the first attempt's model, shown while a second attempt runs \(this one left 1\.35 % of the points unexplained\)/);
  // The same attempts and the same one kept (times differ: the page's workers time
  // Step 1 themselves, and the result's Step-1 seconds are the native clock's).
  const attempts = (r) => ({ first: r.first, second: r.second, taken: r.taken });
  assert.deepEqual(attempts(got.info.retry), attempts(want.info.retry), 'the same attempts and the same one kept');
  assert.equal(got.info.retry.first[0], 0);
  assert.match(status, new RegExp(`Fitted twice \\(seeds 0 and ${got.info.retry.second[0]}\\); the (first|second) was kept`));
  assert.ok(got.info.notes.some((n) => /^second attempt/.test(n)), 'the notes say why the fit was done twice');
  // The kept attempt still leaves more than the bound unexplained, so both fit a third
  // time from the last frame (`pipeline::third_wanted`) and keep the same one.
  assert.ok(want.info.third, 'the CLI made a third attempt');
  const look = (t) => ({ kept: t.kept, third: t.third, taken: t.taken });
  assert.deepEqual(look(got.info.third), look(want.info.third), 'the same third attempt and the same one kept');
  assert.match(status, /A third attempt from the last frame; the (third|earlier one) was kept/);
  assert.ok(got.info.notes.some((n) => /^third attempt/.test(n)), 'the notes say why the fit was done a third time');
});

test('a long sequence is fitted on its key frames and the others tracked, as the CLI does', { timeout: FIT_TIMEOUT, skip: NO_CLI }, async () => {
  // The procedural laptop over 24 frames: Steps 1–3 on 20 key frames (the core's
  // default), the other 4 tracked with the model (`key_frames::extend_recorded`).
  const dir = path.join(ARTIFACTS, 'laptop-long');
  fs.rmSync(dir, { recursive: true, force: true });
  execFileSync(CLI, ['synth', 'laptop', '--frames', '24', '--seed', '0', '--out', dir], { stdio: 'ignore' });
  let stages = '';
  const { got, want, status } = await cliAndPage(dir, 'laptop-long', async (page) => {
    await page.waitForFunction(() => /fitted on 20 key frames of 24/.test(document.querySelector('#fit-status').innerText));
    stages = await page.locator('#stage-list').innerText();
  }, { parts: [2, 3] });
  assert.match(stages, /Tracking the frames between key frames/);
  assert.equal(got.frames, 24);
  assert.equal(got.labels.length, 24);
  assert.deepEqual(got.info.key_frames.frames, want.info.key_frames.frames);
  assert.equal(got.info.key_frames.tracked, 4);
  assert.deepEqual(got.joints, want.joints, 'the same joints and states on every frame as the CLI');
  assert.ok(got.info.notes.some((n) => /^long sequence: Steps 1–3 fitted 20 key frames/.test(n)));
  assert.match(status, /tracking the 4 frames between the 20 key frames: [\d.]+ s\./);
});

test('cancelling a second attempt keeps the first attempt\'s model as the result', { timeout: FIT_TIMEOUT, skip: NO_CLI }, async () => {
  // The procedural cabinet at m = 3–4 is fitted again (see the retry test below).
  const dir = path.join(ARTIFACTS, 'cabinet-seq-cancel');
  fs.rmSync(dir, { recursive: true, force: true });
  execFileSync(CLI, ['synth', 'cabinet', '--seed', '0', '--out', dir], { stdio: 'ignore' });
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  await page.locator('label:has(input[value=balanced])').click();
  await page.getByLabel('Automatic part range').uncheck();
  await page.getByLabel('Minimum part count').fill('3');
  await page.getByLabel('Maximum part count').fill('4');
  const files = fs.readdirSync(dir).filter((f) => /^frame_\d+\.ply$/.test(f)).map((f) => path.join(dir, f));
  await page.locator('#file-input').setInputFiles(files);
  await page.waitForFunction((n) => document.querySelectorAll('#frame-list li[data-index]').length === n, files.length);
  await page.locator('#btn-fit').click();
  await page.waitForSelector('#provisional', { timeout: FIT_TIMEOUT });
  await page.locator('#btn-cancel').click();
  assert.match(await page.locator('#fit-status').innerText(), /Cancelled\. The model shown, from the attempt before, is the result\./);
  assert.equal(await page.locator('#provisional').count(), 0, 'no longer marked provisional');
  assert.ok(await page.locator('#explore').isVisible());
  assert.equal(await page.locator('#btn-fit').isDisabled(), false);
  // It is the first attempt's result: one fit, from seed 0, no retry recorded.
  const got = JSON.parse(fs.readFileSync(await download(page, '#btn-export-json'), 'utf8'));
  assert.equal(got.info.retry, undefined);
  assert.deepEqual(got.info.candidates.map((c) => c[0]), [3, 4]);
  assert.deepEqual(errors, []);
  await context.close();
});

test('an occluded fit in the page gives the CLI result bit for bit', { timeout: FIT_TIMEOUT, skip: (!OCCLUDED && 'bench-dev not found') || NO_CLI }, async () => {
  // Occluded input is the most sensitive path (the pose search's decisions): so101.
  const { got } = await cliAndPage(OCCLUDED, 'so101-occluded');
  assert.deepEqual(got.info.candidates.map((c) => c[0]), [10, 11, 12, 13, 14, 15]);
});
