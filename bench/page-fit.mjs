// The whole pipeline in the page vs natively: for each target it fits the sequence in
// the real page (headless Chromium, wasm in the page's Web Workers: load the frames
// through the file input, pick a quality, fit — model selection, Steps 2–3, metrics)
// and with the native CLI (`gsart fit`, two threads, then `gsart eval`), and prints per
// stage the wall time, iterations and ms per iteration, the accuracy reached (mean RI,
// reconstruction error) and the wasm/native ratio, all from the same run. A benchmark,
// not a test.
//
// Usage (after `npm run build`; it builds the release binary itself):
//   node bench/page-fit.mjs [--quality fast|balanced|paper] [--reps N] [--page-only] [--json out.json] [TARGET...]
// TARGET: `robot` (quadruped 10 × 4096, m 10–15) or `object` (laptop 4 × 512, m 3–7) —
// SPEC §7's workloads, generated with `gsart synth` — or a sequence folder with gt.json
// (e.g. ../shared/bench-dev/full/*). Default: robot object.
import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { ROOT, startServer, launch, newPage, waitLoaded } from '../tests/page/helpers.mjs';

function parseArgs(argv) {
  const o = { quality: 'fast', reps: 1, json: null, pageOnly: false, targets: [] };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    const v = () => {
      if (i + 1 >= argv.length) throw new Error(`${a} needs a value`);
      return argv[++i];
    };
    if (a === '--quality') o.quality = v();
    else if (a === '--reps') o.reps = Number(v());
    else if (a === '--json') o.json = v();
    else if (a === '--page-only') o.pageOnly = true;
    else if (a.startsWith('--')) throw new Error(`unknown option ${a}`);
    // Older form: page-fit.mjs DIR QUALITY.
    else if (['fast', 'balanced', 'paper'].includes(a)) o.quality = a;
    else o.targets.push(a);
  }
  if (o.targets.length === 0) o.targets = ['robot', 'object'];
  return o;
}

const WORKLOADS = {
  robot: ['quadruped', '--frames', '10', '--points', '4096'],
  object: ['laptop', '--frames', '4', '--points', '512'],
};

function run(bin, args) {
  const r = spawnSync(bin, args, { encoding: 'utf8', maxBuffer: 1 << 26 });
  if (r.status !== 0) throw new Error(`${path.basename(bin)} ${args.join(' ')}: ${r.stderr}`);
  return r.stdout;
}

/** The sequence folder of a target (workloads generated like `gsart bench` does). */
function sequenceDir(bin, target, tmp) {
  if (!WORKLOADS[target]) return target;
  const dir = path.join(tmp, target);
  if (!fs.existsSync(dir)) run(bin, ['synth', ...WORKLOADS[target], '--seed', '0', '--heldout', '0', '--out', dir]);
  return dir;
}

function native(bin, dir, quality, tmp) {
  const out = path.join(tmp, 'native.json');
  const t0 = performance.now();
  run(bin, ['fit', dir, '--quality', quality, '--out', out, '--quiet']);
  const seconds = (performance.now() - t0) / 1000;
  const info = JSON.parse(fs.readFileSync(out, 'utf8')).info;
  const ev = JSON.parse(run(bin, ['eval', out, dir]));
  return {
    seconds,
    m: info.m,
    candidates: info.candidates_timing.map(([m, s, iters]) => ({ m, seconds: s, iterations: iters })),
    steps23: info.kinematics_seconds.reduce((a, [, s]) => a + s, 0),
    ri: ev.mean_ri,
    recon: ev.reconstruction_error,
  };
}

/** The number the metrics panel shows under a heading. */
function metric(text, heading) {
  const lines = text.split('\n');
  const i = lines.findIndex((l) => l.startsWith(heading));
  return i < 0 ? null : Number(lines.slice(i + 1).find((l) => /^\s*-?[\d.]+\s*$/.test(l)));
}

async function pageFit(browser, base, dir, quality) {
  const { page } = await newPage(browser);
  try {
    await page.goto(`${base}/`);
    await waitLoaded(page);
    const files = fs.readdirSync(dir).filter((f) => /\.ply$/.test(f) || f === 'gt.json').map((f) => path.join(dir, f));
    await page.locator('#file-input').setInputFiles(files);
    await page.waitForFunction(() => document.querySelectorAll('#frame-list li[data-index]').length >= 2);
    await page.locator(`label:has(input[value=${quality}])`).click();
    const t0 = Date.now();
    await page.locator('#btn-fit').click();
    // The end of the whole fit (an earlier attempt's model shows while a later one runs).
    await page.waitForFunction(() => /Done in/.test(document.querySelector('#fit-status').innerText), null, { timeout: 60 * 60_000 });
    const seconds = (Date.now() - t0) / 1000;
    const status = await page.locator('#fit-status').innerText();
    const metrics = await page.locator('#metrics').innerText().catch(() => '');
    const summary = await page.locator('#explore').innerText();
    // "Step 1: m = 10 (4.6 s), 15 (6.1 s); Steps 2–3: 1.4 s."
    const cands = [...(status.split('Steps')[0].matchAll(/(\d+) \(([\d.]+) s\)/g))]
      .map((x) => ({ m: Number(x[1]), seconds: Number(x[2]) }));
    const steps23 = Number(/Steps 2–3: ([\d.]+) s/.exec(status)?.[1]);
    const m = Number(/chosen m = (\d+)/.exec(summary)?.[1]);
    return {
      seconds, m, candidates: cands, steps23, status,
      ri: metric(metrics, 'Rand index (mean over frames)'), recon: metric(metrics, 'Reconstruction error'),
    };
  } finally {
    await page.close();
  }
}

const median = (xs) => {
  const s = [...xs].sort((a, b) => a - b);
  return s.length % 2 ? s[(s.length - 1) / 2] : (s[s.length / 2 - 1] + s[s.length / 2]) / 2;
};
const f = (x, d = 2) => (x == null || Number.isNaN(x) ? '–' : x.toFixed(d));

const opts = parseArgs(process.argv.slice(2));
const build = spawnSync('cargo', ['build', '--release', '--quiet', '--bin', 'gsart'], { cwd: ROOT, stdio: 'inherit' });
if (build.status !== 0) process.exit(1);
const bin = path.join(ROOT, 'target', 'release', 'gsart');
const tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'gsart-page-fit-'));
const srv = await startServer();
const browser = await launch();
const results = [];
const workers = Math.min(os.availableParallelism?.() ?? os.cpus().length, 8);
try {
  for (const target of opts.targets) {
    const dir = sequenceDir(bin, target, tmp);
    for (let rep = 0; rep < opts.reps; rep++) {
      // Interleaved, so a slow phase of a shared machine hits both sides alike.
      const n = opts.pageOnly ? null : native(bin, dir, opts.quality, tmp);
      const w = await pageFit(browser, srv.base, dir, opts.quality);
      results.push({ target, rep, native: n, wasm: w });
      process.stderr.write(`${target} rep ${rep + 1}/${opts.reps}: page ${w.seconds.toFixed(1)} s (${w.status})` +
        `${n ? `, native ${n.seconds.toFixed(1)} s` : ''}\n`);
    }
  }
  if (opts.pageOnly) {
    for (const r of results) console.log(JSON.stringify({ target: r.target, seconds: r.wasm.seconds, status: r.wasm.status, ri: r.wasm.ri, recon: r.wasm.recon }));
  } else printTable();
  if (opts.json) fs.writeFileSync(opts.json, JSON.stringify({ quality: opts.quality, workers, results }, null, 1));
} finally {
  await browser.close();
  srv.server.close();
  fs.rmSync(tmp, { recursive: true, force: true });
}

function printTable() {
  console.log(`\n${opts.quality} quality, ${workers} cores (page: one worker per core; native: one thread per core), ` +
    `median of ${opts.reps} run(s). Candidate seconds include each worker's preparation; ms/iter = candidate seconds / main-loop iterations (so it includes the pose search).\n`);
  console.log('| target | stage | iterations | native s | wasm s | native ms/iter | wasm ms/iter | wasm/native | native RI / recon | wasm RI / recon |');
  console.log('|---|---|---|---|---|---|---|---|---|---|');
  for (const target of opts.targets) {
    const rs = results.filter((r) => r.target === target);
    const label = WORKLOADS[target] ? target : path.basename(target);
    for (const c of rs[0].native.candidates) {
      const ns = median(rs.map((r) => r.native.candidates.find((x) => x.m === c.m)?.seconds));
      const ws = median(rs.map((r) => r.wasm.candidates.find((x) => x.m === c.m)?.seconds));
      console.log(`| ${label} | Step 1, m = ${c.m} | ${c.iterations} | ${f(ns)} | ${f(ws, 1)} | ${f(1000 * ns / c.iterations)} | ${f(1000 * ws / c.iterations)} | ${f(ws / ns)} | | |`);
    }
    const n23 = median(rs.map((r) => r.native.steps23));
    const w23 = median(rs.map((r) => r.wasm.steps23));
    console.log(`| ${label} | Steps 2–3 (m = ${rs[0].native.m}) | | ${f(n23)} | ${f(w23, 1)} | | | ${f(w23 / n23)} | | |`);
    const ns = median(rs.map((r) => r.native.seconds));
    const ws = median(rs.map((r) => r.wasm.seconds));
    const n = rs[0].native;
    const w = rs[0].wasm;
    console.log(`| ${label} | **whole fit** | | ${f(ns)} | ${f(ws)} | | | ${f(ws / ns)} | ${f(n.ri, 3)} / ${f(n.recon, 3)} | ${f(w.ri, 3)} / ${f(w.recon, 3)} |`);
    if (rs.length > 1) console.log(`|  | (page runs: ${rs.map((r) => r.wasm.seconds.toFixed(1)).join(', ')} s) | | | | | | | | |`);
  }
}
