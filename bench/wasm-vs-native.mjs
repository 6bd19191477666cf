// wasm vs native cost of one Step-1 iteration. For each workload of SPEC §7 (robot:
// quadruped 10 × 4096, object: laptop 4 × 512) it fits ONE candidate m for a fixed
// iteration count, natively (`gsart bench --step1-only`, release build, one thread)
// and in headless Chromium (`bench_step1` of a wasm package, in a fresh dedicated Web
// Worker like the page's fits), REPS times each, interleaved, and prints the medians:
// ms per main-loop iteration, the wasm/native ratio, and whether the final Chamfer and
// the labels are bit-identical (the core is deterministic across targets).
// A benchmark, not a test.
//
// Usage (after `cargo build --release` and `npm run build`):
//   node bench/wasm-vs-native.mjs [--workloads robot,object] [--iters 400] [--reps 3]
//        [--m N] [--seed S] [--pkg www/pkg[=LABEL]]... [--json out.json]
// Several --pkg compare wasm builds (e.g. with and without simd128) in one run.
import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import http from 'node:http';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const ROOT = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..');

function parseArgs(argv) {
  const o = { workloads: ['robot', 'object'], iters: 400, reps: 3, m: null, seed: 0, pkgs: [], json: null };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    const v = () => {
      if (i + 1 >= argv.length) throw new Error(`${a} needs a value`);
      return argv[++i];
    };
    if (a === '--workloads') o.workloads = v().split(',');
    else if (a === '--iters') o.iters = Number(v());
    else if (a === '--reps') o.reps = Number(v());
    else if (a === '--m') o.m = Number(v());
    else if (a === '--seed') o.seed = Number(v());
    else if (a === '--pkg') o.pkgs.push(v());
    else if (a === '--json') o.json = v();
    else throw new Error(`unknown argument ${a}`);
  }
  if (o.pkgs.length === 0) o.pkgs.push('www/pkg');
  o.pkgs = o.pkgs.map((p, i) => {
    const [dir, label] = p.split('=');
    const abs = path.resolve(ROOT, dir);
    if (!fs.existsSync(path.join(abs, 'gsart.js'))) throw new Error(`${dir}/gsart.js missing: run \`npm run build\``);
    return { index: i, dir: abs, label: label ?? dir };
  });
  return o;
}

const DEFAULT_M = { robot: 12, object: 5 };
const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.wasm': 'application/wasm' };

// Serves /bench/* from bench/ and /pkg/<i>/* from the i-th wasm package, on 127.0.0.1.
function serve(pkgs) {
  const server = http.createServer((req, res) => {
    const url = new URL(req.url, 'http://x');
    let file = null;
    const m = url.pathname.match(/^\/pkg\/(\d+)\/([\w.-]+)$/);
    if (m && pkgs[Number(m[1])]) file = path.join(pkgs[Number(m[1])].dir, m[2]);
    const b = url.pathname.match(/^\/bench\/([\w.-]+)$/);
    if (b) file = path.join(ROOT, 'bench', b[1]);
    if (!file || !fs.existsSync(file)) return res.writeHead(404).end('not found');
    res.writeHead(200, { 'content-type': TYPES[path.extname(file)] ?? 'application/octet-stream', 'cache-control': 'no-cache' });
    fs.createReadStream(file).pipe(res);
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

function native(bin, workload, m, iters, seed) {
  const r = spawnSync(bin, ['bench', '--step1-only', '--workload', workload, '--m', String(m),
    '--iters', String(iters), '--seed', String(seed)], { encoding: 'utf8' });
  if (r.status !== 0) throw new Error(`gsart bench --step1-only failed: ${r.stderr}`);
  return JSON.parse(r.stdout.trim().split('\n').pop());
}

const median = (xs) => {
  const s = [...xs].sort((a, b) => a - b);
  return s.length % 2 ? s[(s.length - 1) / 2] : (s[s.length / 2 - 1] + s[s.length / 2]) / 2;
};

const opts = parseArgs(process.argv.slice(2));
const build = spawnSync('cargo', ['build', '--release', '--quiet', '--bin', 'gsart'], { cwd: ROOT, stdio: 'inherit' });
if (build.status !== 0) process.exit(1);
const bin = path.join(ROOT, 'target', 'release', 'gsart');

const server = await serve(opts.pkgs);
const base = `http://127.0.0.1:${server.address().port}`;
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM_PATH || '/usr/bin/chromium',
  headless: true,
  args: ['--no-sandbox', '--no-first-run', '--disable-background-networking', '--disable-component-update',
    '--disable-sync', '--disable-quic'],
});
const runs = [];
try {
  const page = await browser.newPage();
  await page.goto(`${base}/bench/wasm-vs-native.html`);
  await page.waitForFunction(() => document.body.dataset.ready === '1');
  const chromeVersion = browser.version();
  for (const w of opts.workloads) {
    const m = opts.m ?? DEFAULT_M[w];
    if (!m) throw new Error(`unknown workload ${w} (expected robot or object)`);
    for (let rep = 0; rep < opts.reps; rep++) {
      // Interleaved so slow phases of the shared machine hit every variant alike.
      runs.push({ workload: w, variant: 'native', rep, ...native(bin, w, m, opts.iters, opts.seed) });
      for (const p of opts.pkgs) {
        const r = await page.evaluate(([u, w2, m2, it, s]) => window.runBench(u, w2, m2, it, s),
          [`${base}/pkg/${p.index}/gsart.js`, w, m, opts.iters, opts.seed]);
        runs.push({ workload: w, variant: p.label, rep, ...r });
      }
      process.stderr.write(`${w} rep ${rep + 1}/${opts.reps} done\n`);
    }
  }
  const rows = [];
  for (const w of opts.workloads) {
    const nat = runs.filter((r) => r.workload === w && r.variant === 'native');
    const nMs = median(nat.map((r) => r.ms_per_iter));
    for (const p of opts.pkgs) {
      const was = runs.filter((r) => r.workload === w && r.variant === p.label);
      const wMs = median(was.map((r) => r.ms_per_iter));
      // Every run of a variant must agree with itself (deterministic); across targets
      // the inputs and labels are compared exactly and the Chamfer bit for bit.
      const all = [...nat, ...was];
      const sameInput = all.every((r) => r.input_hash === nat[0].input_hash);
      const sameLabels = all.every((r) => r.labels_hash === nat[0].labels_hash);
      const deterministic = [nat, was].every((rs) => rs.every((r) => r.final_chamfer === rs[0].final_chamfer));
      // Against the first wasm build, paired per repetition (they ran back to back).
      const first = runs.filter((r) => r.workload === w && r.variant === opts.pkgs[0].label);
      const paired = median(was.map((r, i) => r.ms_per_iter / first[i].ms_per_iter));
      const relDiff = Math.abs(was[0].final_chamfer - nat[0].final_chamfer) / Math.abs(nat[0].final_chamfer);
      rows.push({
        workload: `${w} (${nat[0].object} ${nat[0].frames}×${nat[0].points})`, m: nat[0].m, wasm: p.label,
        iterations: nat[0].iterations, native_ms_per_iter: nMs, wasm_ms_per_iter: wMs, ratio: wMs / nMs, vs_first_wasm: paired,
        native_ms_total: median(nat.map((r) => r.ms_total)), wasm_ms_total: median(was.map((r) => r.ms_total)),
        native_final_chamfer: nat[0].final_chamfer, wasm_final_chamfer: was[0].final_chamfer,
        same_input: sameInput, same_labels: sameLabels, deterministic, chamfer_rel_diff: relDiff,
      });
    }
  }
  console.log(`\nChromium ${chromeVersion}, ${opts.reps} runs each (median), seed ${opts.seed}\n`);
  console.log('| workload | m | wasm build | iterations | native ms/iter | wasm ms/iter | wasm/native | vs first wasm build (paired) | native total ms | wasm total ms | final Chamfer (native) | wasm − native (relative) | labels identical |');
  console.log('|---|---|---|---|---|---|---|---|---|---|---|---|---|');
  for (const r of rows) {
    const diff = r.chamfer_rel_diff === 0 ? '0 (bit-identical)' : r.chamfer_rel_diff.toExponential(1);
    const labels = !r.same_input ? 'INPUT DIFFERS' : r.same_labels ? 'yes' : 'NO';
    console.log(`| ${r.workload} | ${r.m} | ${r.wasm} | ${r.iterations} | ${r.native_ms_per_iter.toFixed(3)} | ${r.wasm_ms_per_iter.toFixed(3)} | ${r.ratio.toFixed(2)} | ${r.vs_first_wasm.toFixed(3)} | ${r.native_ms_total.toFixed(0)} | ${r.wasm_ms_total.toFixed(0)} | ${r.native_final_chamfer.toPrecision(17)} | ${diff} | ${labels}${r.deterministic ? '' : ' (NOT deterministic across runs)'} |`);
  }
  if (opts.json) fs.writeFileSync(opts.json, JSON.stringify({ chromium: chromeVersion, opts, rows, runs }, null, 1));
} finally {
  await browser.close();
  server.close();
}
