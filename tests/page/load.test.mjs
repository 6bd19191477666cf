// Loading real files: a bench-dev sequence through the file input, a folder drop,
// and bad files (each shows its error beside it, the good ones stay loaded).
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { startServer, launch, newPage, waitLoaded, canvasStats, shot, benchDev } from './helpers.mjs';

let srv, browser;
before(async () => { srv = await startServer(); browser = await launch(); });
after(async () => { await browser?.close(); srv?.server.close(); });

const BENCH = benchDev();
const SEQ = BENCH && path.join(BENCH, 'full', 'finger_edu_00');

test('loads a bench-dev sequence through the file input', { skip: !SEQ && 'bench-dev not found (set GSART_BENCH_DEV)' }, async () => {
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  const files = fs.readdirSync(SEQ).filter((f) => /^frame_\d+\.ply$/.test(f)).map((f) => path.join(SEQ, f));
  assert.ok(files.length >= 2);
  // Reverse the order: the page must sort them naturally.
  await page.locator('#file-input').setInputFiles(files.reverse());
  await page.waitForFunction((n) => document.querySelectorAll('#frame-list li[data-index]').length === n, files.length);
  const names = await page.locator('#frame-list .fname').allInnerTexts();
  assert.deepEqual(names, [...names].sort(), 'frames are listed in filename order');
  assert.equal(names[0], 'frame_000.ply');
  assert.match(await page.locator('#frame-list li').first().innerText(), /4,096 pts/);
  assert.match(await page.locator('#sequence-summary').innerText(), new RegExp(`${files.length} frames`));
  assert.equal(await page.locator('#btn-fit').isDisabled(), false);
  await page.waitForTimeout(400);
  const st = await canvasStats(page);
  assert.ok(st.lit > 300, `points drawn (${st.lit} lit pixels)`);
  await shot(page, 'load-finger-edu');
  assert.deepEqual(errors, []);
  await context.close();
});

test('a folder drop loads frames and gt.json, not heldout/', { skip: !SEQ && 'bench-dev not found' }, async () => {
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  // The folder picker gives files with relative paths, like a dropped folder.
  await page.locator('#folder-input').setInputFiles(SEQ);
  await page.waitForFunction(() => document.querySelectorAll('#frame-list li[data-index]').length >= 2);
  await page.waitForFunction(() => !/reading/.test(document.querySelector('#sequence-summary').innerText));
  const n = await page.locator('#frame-list li').count();
  const expected = fs.readdirSync(SEQ).filter((f) => f.endsWith('.ply')).length;
  assert.equal(n, expected, 'only the frames of the folder, not heldout/');
  assert.match(await page.locator('#sequence-summary').innerText(), /ground truth/);
  assert.deepEqual(errors, []);
  await context.close();
});

test('bad files show their error beside them and the others stay loaded', async () => {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'gsart-bad-'));
  const good = (i, dx) => {
    const lines = [];
    for (let k = 0; k < 200; k++) {
      const t = k / 200;
      lines.push(`${(Math.cos(9 * t) + dx).toFixed(4)} ${Math.sin(7 * t).toFixed(4)} ${(t * 2 - 1).toFixed(4)}`);
    }
    const body = `ply\nformat ascii 1.0\nelement vertex ${lines.length}\nproperty float x\nproperty float y\nproperty float z\nend_header\n${lines.join('\n')}\n`;
    fs.writeFileSync(path.join(dir, `f${i}.ply`), body);
  };
  good(1, 0); good(2, 0.1); good(10, 0.2);
  // Truncated binary body.
  const hdr = 'ply\nformat binary_little_endian 1.0\nelement vertex 100\nproperty float x\nproperty float y\nproperty float z\nend_header\n';
  fs.writeFileSync(path.join(dir, 'f3.ply'), Buffer.concat([Buffer.from(hdr), Buffer.alloc(100)]));
  // A zip where a PLY was expected.
  fs.writeFileSync(path.join(dir, 'scan.zip'), Buffer.from('504b0304140000000800', 'hex'));
  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  await page.locator('#file-input').setInputFiles(['f1.ply', 'f10.ply', 'f2.ply', 'f3.ply', 'scan.zip'].map((f) => path.join(dir, f)));
  await page.waitForFunction(() => document.querySelectorAll('#frame-list .ferror').length === 2, null, { timeout: 20_000 });
  const rows = await page.locator('#frame-list li').allInnerTexts();
  const byName = Object.fromEntries(rows.map((r) => [r.split('\n')[0].trim(), r]));
  assert.match(byName['f3.ply'], /truncat|end of file|expected|short/i, `truncated body explained: ${byName['f3.ply']}`);
  assert.match(byName['scan.zip'], /zip|not a PLY/i, `zip explained: ${byName['scan.zip']}`);
  // Natural order of the good frames, counts shown.
  const goodNames = await page.locator('#frame-list li[data-index] .fname').allInnerTexts();
  assert.deepEqual(goodNames, ['f1.ply', 'f2.ply', 'f10.ply']);
  assert.match(await page.locator('#sequence-summary').innerText(), /3 frames[\s\S]*2 files could not be read/);
  assert.equal(await page.locator('#btn-fit').isDisabled(), false, 'the good frames can still be fitted');
  await shot(page, 'load-bad-files');
  assert.deepEqual(errors, []);

  // Dropping a corrupt file on the page replaces the sequence and shows the error too.
  await page.evaluate(() => {
    const dt = new DataTransfer();
    dt.items.add(new File(['ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n'], 'broken.ply'));
    const ev = (type) => new DragEvent(type, { dataTransfer: dt, bubbles: true, cancelable: true });
    window.dispatchEvent(ev('dragenter'));
    window.dispatchEvent(ev('drop'));
  });
  await page.waitForFunction(() => document.querySelectorAll('#frame-list .ferror').length === 1, null, { timeout: 20_000 });
  assert.match(await page.locator('#frame-list li').first().innerText(), /broken\.ply/);
  assert.equal(await page.locator('#btn-fit').isDisabled(), true, 'nothing to fit');
  assert.equal(await page.locator('#drop-overlay').isVisible(), false);
  assert.deepEqual(errors, []);
  await context.close();
});

test('a NumPy stack loads as its frames, a folder of PCD frames without its notes', async () => {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'gsart-formats-'));
  // A helix moved along x from frame to frame: (T, N, 3) float32, as np.save writes it.
  const T = 3, N = 300;
  const pts = (k) => Array.from({ length: N }, (_, i) => {
    const t = i / N;
    return [Math.cos(9 * t) + 0.1 * k, Math.sin(7 * t), 2 * t - 1];
  });
  const data = Buffer.alloc(T * N * 12);
  for (let k = 0; k < T; k++) pts(k).forEach((p, i) => p.forEach((v, c) => data.writeFloatLE(v, ((k * N + i) * 3 + c) * 4)));
  let header = `{'descr': '<f4', 'fortran_order': False, 'shape': (${T}, ${N}, 3), }`;
  header += ' '.repeat((64 - ((10 + header.length + 1) % 64)) % 64) + '\n';
  const len = Buffer.alloc(2);
  len.writeUInt16LE(header.length);
  fs.writeFileSync(path.join(dir, 'walk.npy'), Buffer.concat([Buffer.from('\x93NUMPY\x01\x00', 'latin1'), len, Buffer.from(header), data]));

  const { page, errors, context } = await newPage(browser);
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  await page.locator('#file-input').setInputFiles([path.join(dir, 'walk.npy')]);
  await page.waitForFunction(() => !/reading/.test(document.querySelector('#sequence-summary').innerText)
    && document.querySelectorAll('#frame-list li[data-index]').length === 3, null, { timeout: 20_000 });
  assert.deepEqual(await page.locator('#frame-list .fname').allInnerTexts(), ['walk.npy[0]', 'walk.npy[1]', 'walk.npy[2]']);
  assert.match(await page.locator('#frame-list li').first().innerText(), /300 pts/);
  assert.match(await page.locator('#sequence-summary').innerText(), /3 frames/);
  assert.equal(await page.locator('#btn-fit').isDisabled(), false);

  // A folder of PCD frames with a note beside them: the frames are the PCD files.
  const folder = path.join(dir, 'scan');
  fs.mkdirSync(folder);
  for (let k = 0; k < T; k++) {
    const rows = pts(k).map((p) => p.map((v) => v.toFixed(5)).join(' '));
    fs.writeFileSync(path.join(folder, `cloud_${k}.pcd`),
      `# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH ${N}\nHEIGHT 1\nPOINTS ${N}\nDATA ascii\n${rows.join('\n')}\n`);
  }
  fs.writeFileSync(path.join(folder, 'notes.txt'), 'captured on a bench\n');
  await page.locator('#folder-input').setInputFiles(folder);
  await page.waitForFunction(() => !/reading/.test(document.querySelector('#sequence-summary').innerText)
    && document.querySelectorAll('#frame-list li[data-index]').length === 3
    && /cloud_0/.test(document.querySelector('#frame-list').innerText), null, { timeout: 20_000 });
  assert.deepEqual(await page.locator('#frame-list .fname').allInnerTexts(), ['cloud_0.pcd', 'cloud_1.pcd', 'cloud_2.pcd']);
  assert.equal(await page.locator('#frame-list .ferror').count(), 0);
  await shot(page, 'load-formats');
  assert.deepEqual(errors, []);
  await context.close();
});

test('a sequence online (?frames=URL…&gt=URL&fit=1) is fitted, and its link and embed code point at it', { timeout: 300_000 }, async () => {
  // The laptop example's frames and ground truth, put "online" as PCD files with labels.
  const { page: gen, context: genCtx } = await newPage(browser);
  await gen.goto(`${srv.base}/?example=laptop`);
  await waitLoaded(gen);
  const ex = await gen.evaluate(() => {
    const s = window.gsart.state;
    return {
      gt: typeof s.gt === 'string' ? s.gt : JSON.stringify(s.gt),
      frames: s.frames.map((f) => ({ points: Array.from(f.points), labels: Array.from(f.labels) })),
    };
  });
  await genCtx.close();
  const pcds = ex.frames.map((f) => {
    const n = f.labels.length;
    const rows = f.labels.map((l, i) => `${f.points[3 * i]} ${f.points[3 * i + 1]} ${f.points[3 * i + 2]} ${l}`);
    return `# .PCD v0.7\nVERSION 0.7\nFIELDS x y z label\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH ${n}\nHEIGHT 1\nPOINTS ${n}\nDATA ascii\n${rows.join('\n')}\n`;
  });
  const { page, errors, context } = await newPage(browser);
  await context.route((url) => url.pathname.startsWith('/shared/'), (r) => {
    const file = new URL(r.request().url()).pathname.slice('/shared/'.length);
    if (file === 'gt.json') return r.fulfill({ body: ex.gt, contentType: 'application/json' });
    const k = /^cloud_(\d+)\.pcd$/.exec(file)?.[1];
    return k === undefined ? r.fulfill({ status: 404 }) : r.fulfill({ body: pcds[Number(k)] });
  });
  await page.addInitScript(() => {
    window.copied = [];
    Object.defineProperty(navigator, 'clipboard', { value: { writeText: async (s) => { window.copied.push(s); } } });
  });
  const frames = pcds.map((_, k) => `frames=/shared/cloud_${k}.pcd`).join('&');
  await page.goto(`${srv.base}/?${frames}&gt=/shared/gt.json&fit=1&quality=fast&parts=2..4`);
  await waitLoaded(page);
  await page.waitForFunction(() => /Done in/.test(document.querySelector('#fit-status').innerText), null, { timeout: 240_000 });
  assert.match(await page.locator('#sequence-summary').innerText(), new RegExp(`${pcds.length} frames[\\s\\S]*ground truth`));
  const m = await page.evaluate(() => ({ joints: window.gsart.state.model.joints().length, ted: window.gsart.state.metrics?.tree_edit_distance }));
  assert.deepEqual(m, { joints: 1, ted: 0 }, 'the laptop\'s hinge, scored against the ground truth it was given');

  await page.locator('#btn-share').click();
  await page.locator('#btn-embed').click();
  await page.waitForFunction(() => window.copied.length === 2);
  const [link, embed] = await page.evaluate(() => window.copied);
  const sp = new URL(link).searchParams;
  assert.deepEqual(sp.getAll('frames'), pcds.map((_, k) => `${srv.base}/shared/cloud_${k}.pcd`));
  assert.equal(sp.get('gt'), `${srv.base}/shared/gt.json`);
  assert.equal(sp.get('quality'), 'fast');
  assert.equal(sp.get('fit'), null, 'a link opens the frames with the fit settings');
  const src = new URL(embed.match(/^<iframe src="([^"]+)"/)[1].replace(/&amp;/g, '&'));
  assert.equal(src.searchParams.get('fit'), '1', 'a figure fits them in the visitor\'s browser');
  assert.equal(src.searchParams.getAll('frames').length, pcds.length);
  assert.match(await page.locator('#toast').innerText(), /fits the frames in the visitor's browser/);

  // A frame that is not there says which and why.
  const bad = await newPage(browser);
  await bad.page.goto(`${srv.base}/?frames=/missing/walk.npz&embed=1`);
  await waitLoaded(bad.page);
  assert.match(await bad.page.locator('#view-message').innerText(), /Could not open the frames[\s\S]*\/missing\/walk\.npz: HTTP 404/);
  await bad.context.close();
  assert.deepEqual(errors, []);
  await context.close();
});
