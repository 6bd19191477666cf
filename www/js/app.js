// GSArt page controller: Load → Fit → Explore/Export.
// All computation is done by the wasm core (in workers for anything slow);
// this file only moves data between the UI, the workers and the 3D view.
import init, * as wasm from '../pkg/gsart.js';
import { View } from './view.js';
import { FitJob, WorkerJob, CancelledError, maxParallel } from './jobs.js';
import { entriesFromDrop, entriesFromInput, classify, basename } from './files.js';
import { LossChart } from './chart.js';
import { drawTree } from './tree.js';
import { download, zip } from './save.js';
import { FPS, recordVideo, videoSize, VideoUnsupported } from './video.js';
import { follow, jointMotion } from './motion.js';
import { EMBED, setupEmbed, syncEmbed, withoutEmbed, iframeCode, readableUrl } from './embed.js';
import { DEFAULTS, SETTING_KEYS, settingsFromParams, writeSettings, exampleSeed } from './settings.js';

const $ = (id) => document.getElementById(id);
const ICON_PLAY = '<svg viewBox="0 0 24 24" width="16" height="16" aria-hidden="true"><path d="M7 4.5v15l12-7.5z" fill="currentColor"/></svg>';
const ICON_PAUSE = '<svg viewBox="0 0 24 24" width="16" height="16" aria-hidden="true"><rect x="6" y="4.5" width="4" height="15" rx="1" fill="currentColor"/><rect x="14" y="4.5" width="4" height="15" rx="1" fill="currentColor"/></svg>';
const params = new URLSearchParams(location.search);
// `play=1` (a link's or a figure's option): the frames play once they are on view, and
// again when a fit's model replaces them. `play=joints` / `play=together` play the
// model's joints instead (each in turn, or all at once: motion.js), and Play does too.
const PLAY = { 1: 'frames', frames: 'frames', joints: 'joints', together: 'together' }[params.get('play')] ?? null;
// Seconds per input frame when the frames play (and in the video of the frames).
const FRAME_S = 0.4;

const S = {
  view: null,
  frames: [], // {name, bytes?, points, labels, error, status}
  seqName: '',
  example: null,
  gt: null, // gt.json text
  heldout: null, // {frames: Float32Array[], names: string[]}
  loadToken: 0,
  current: 0,
  job: null,
  working: null, // {m, frames}
  focusM: null,
  model: null, // wasm Model
  modelSource: '', // 'fit' | 'file' | 'url'
  modelUrl: null,
  framesUrls: null, // {frames: [URL], gt: URL or null} when the frames came from ?frames=
  states: null,
  frameStates: null,
  playing: false,
  playTimer: null,
  playRaf: 0, // the animation frame of joints playing (`play=joints`)
  movingHot: -1, // the part whose joint moves alone (play=joints, the video), highlighted
  gaussiansOn: true,
  hot: -1,
  palette: null,
  metrics: null,
  // Per attempt of the last fit: whether its runner-up was copied to another worker to
  // finish beside the best (`FitJob.movedRunner`).
  movedRunners: [],
  resultExtra: {}, // what the result on view was opened with (openResult's `extra`)
  video: null, // the AbortController of a video being recorded
  modelAttached: false, // the model on view labels the loaded frames (so it can be edited)
  editJob: null, // the WorkerJob of a running edit (parts joined)
  undo: [], // models before each edit: {text, source, extra}
};

// ------------------------------------------------------------------ helpers

function toast(text, kind = '', ms = 4000) {
  const t = $('toast');
  t.textContent = text;
  t.className = `toast ${kind}`;
  t.hidden = false;
  clearTimeout(toast.timer);
  toast.timer = setTimeout(() => { t.hidden = true; }, ms);
}

function errText(e) {
  return e instanceof Error ? e.message : String(e);
}

function fmtInt(n) { return n.toLocaleString('en-US'); }

/** Least time between two redraws of the fit's progress (see startFit). */
const UI_MS = 250;

function fmtTime(s) {
  if (!Number.isFinite(s) || s < 0) return '';
  if (s < 1) return '<1 s';
  if (s < 60) return `${Math.round(s)} s`;
  const m = Math.floor(s / 60);
  return `${m} min ${String(Math.round(s % 60)).padStart(2, '0')} s`;
}

function partColor(p) {
  try { return wasm.palette_css(p); } catch { return `hsl(${(p * 137.508) % 360} 70% 60%)`; }
}

function goodFrames() { return S.frames.filter((f) => f.points && !f.error); }

/** Whether metrics can be computed for the frames `good`: ground truth, every frame loaded and labelled. */
function hasTruth(good) { return !!S.gt && good.length === S.frames.length && good.every((f) => f.labels); }

function safeName(s) { return (s || 'gsart').replace(/[^A-Za-z0-9._-]+/g, '_').replace(/^_+|_+$/g, '') || 'gsart'; }

function setStepActive(step) {
  for (const id of ['step-load', 'step-fit', 'step-explore']) $(id).classList.toggle('active', id === step);
}

// ------------------------------------------------------------------ 3D view

async function startView() {
  const badge = $('backend');
  const forceWebgl = params.get('backend') === 'webgl2' || params.get('backend') === 'webgl';
  try {
    S.view = await View.create($('view'), wasm, { forceWebgl });
  } catch (e) {
    badge.textContent = 'no 3D';
    badge.className = 'badge none';
    const neither = !navigator.gpu && !hasWebgl2();
    const box = neither
      ? viewMessage('No WebGPU or WebGL2 here', 'This browser offers neither WebGPU nor WebGL2, so the point clouds cannot be drawn. '
        + 'Loading, fitting and exporting still work. Use a current Chrome, Edge, Firefox or Safari, or turn on hardware acceleration.')
      : viewMessage('The 3D view could not start', 'Loading, fitting and exporting still work; only the drawing is missing.');
    const detail = document.createElement('p');
    detail.className = 'muted small';
    detail.textContent = errText(e);
    box.appendChild(detail);
    console.warn('3D view unavailable:', e);
    return;
  }
  const b = S.view.backend;
  badge.textContent = b === 'webgpu' ? 'WebGPU' : b === 'webgl2' ? 'WebGL2' : b;
  badge.className = `badge ${b}`;
  badge.title = b === 'webgpu' ? 'Drawing with WebGPU' : 'Drawing with WebGL2 (this browser has no usable WebGPU)';
  document.body.dataset.backend = b;
  S.view.onCamera = (state) => writeHash(state);
  S.view.setGaussiansVisible(S.gaussiansOn);
}

/** A message over the 3D view: a title and a line of text (both plain text); its box. */
function viewMessage(title, text) {
  const box = document.createElement('div');
  box.className = 'box';
  const h = document.createElement('h2');
  h.textContent = title;
  const p = document.createElement('p');
  p.textContent = text;
  box.append(h, p);
  $('view-message').replaceChildren(box);
  $('view-message').hidden = false;
  $('empty-hint').hidden = true;
  return box;
}

function hasWebgl2() {
  try { return !!document.createElement('canvas').getContext('webgl2'); } catch { return false; }
}

function writeHash(camState) {
  const h = new URLSearchParams(location.hash.slice(1));
  if (camState) h.set('cam', camState);
  history.replaceState(null, '', `${location.pathname}${location.search}#${h.toString()}`);
}

function applyHashCamera() {
  const cam = new URLSearchParams(location.hash.slice(1)).get('cam');
  if (cam && S.view) S.view.setCameraState(cam);
}

// ------------------------------------------------------------------ loading

function resetResult({ keepUndo = false } = {}) {
  S.video?.abort();
  S.editJob?.cancel();
  S.editJob = null;
  editStatus('');
  if (!keepUndo) S.undo = [];
  stopPlay();
  if (S.model) { try { S.model.free(); } catch { /* already freed */ } }
  S.model = null;
  S.metrics = null;
  S.metricsError = null;
  S.modelUrl = null;
  $('explore').hidden = true;
  $('explore-empty').hidden = false;
  $('metrics-wrap').hidden = true;
  if (S.view) { S.view.clearGaussians(); S.view.clearAxes(); }
  embedState();
}

function cancelFit(silent = false) {
  if (!S.job) return;
  S.job.cancel();
  S.job = null;
  fitUi(false);
  const provisional = S.model && S.resultExtra?.provisional;
  if (provisional) {
    // The earlier attempt's model stays, now as the result.
    S.resultExtra = { ...S.resultExtra, provisional: null };
    renderResult(S.resultExtra);
  }
  if (!silent) {
    $('fit-status').innerHTML = provisional
      ? '<span class="msg-warn">Cancelled.</span> The model shown, from the attempt before, is the result.'
      : '<span class="msg-warn">Cancelled.</span> Your frames are still loaded; change the settings and fit again.';
  }
  showFrame(S.current);
}

/** Replaces the sequence with named PLY byte buffers; parses them in a worker. */
async function loadSequence({ name, files, gt = null, heldout = [], example = null, note = '', urls = null }) {
  cancelFit(true);
  resetResult();
  const token = ++S.loadToken;
  S.seqName = name;
  S.example = example;
  // Where the frames came from when they are online (`?frames=`), for links to them.
  S.framesUrls = urls;
  S.gt = gt;
  S.heldout = null;
  S.current = 0;
  // Natural filename order (f2 before f10), by the core's rule.
  let order = files.map((_, i) => i);
  try { order = Array.from(wasm.natural_order(files.map((f) => f.name))); } catch { /* keep given order */ }
  const sorted = order.map((i) => files[i]);
  S.frames = sorted.map((f) => ({ name: f.name, points: null, labels: null, error: null, status: 'reading…' }));
  $('fit-status').textContent = '';
  $('progress').hidden = true;
  renderFrameList();
  renderSummary(note);
  const buffers = await Promise.all(sorted.map((f) => f.bytes ?? f.file.arrayBuffer()));
  if (token !== S.loadToken) return;
  const job = new WorkerJob(
    { type: 'parse', files: sorted.map((f, i) => ({ name: f.name, bytes: buffers[i] })) },
    buffers,
    (msg) => {
      if (token !== S.loadToken || msg.type !== 'parsed') return;
      let fr = S.frames.find((f) => f.name === msg.name && f.status);
      if (!fr) {
        // A file of several frames (a NumPy stack, `walk.npy[3]`): its frames go in
        // before its row, in order; the row goes once the file is read.
        const i = S.frames.findIndex((f) => f.status && msg.name.startsWith(`${f.name}[`));
        if (i < 0) return;
        S.frames[i].many = true;
        fr = { name: msg.name, points: null, labels: null, error: null, status: 'reading…' };
        S.frames.splice(i, 0, fr);
      }
      fr.status = null;
      if (msg.error) fr.error = msg.error;
      else { fr.points = msg.points; fr.labels = msg.labels; }
      renderFrameList();
      const good = goodFrames();
      if (good.length === 1 || (good.length && fr === good[0])) showFrame(0, { frameBox: true });
    },
  );
  try {
    await job.promise;
  } catch (e) {
    if (token === S.loadToken) toast(`Could not read the files: ${errText(e)}`, 'error', 8000);
    return;
  }
  if (token !== S.loadToken) return;
  S.frames = S.frames.filter((f) => !f.many);
  afterLoad(note);
}

function afterLoad(note = '') {
  renderFrameList();
  renderSummary(note);
  updateAutoRange();
  const good = goodFrames();
  $('btn-fit').disabled = good.length < 2;
  setStepActive(good.length >= 2 ? 'step-fit' : 'step-load');
  if (good.length) showFrame(Math.min(S.current, good.length - 1), { frameBox: true });
  applyHashCamera();
  embedState();
  if (params.get('fit') === '1' && !afterLoad.autoFitDone && good.length >= 2) {
    afterLoad.autoFitDone = true;
    startFit();
  }
}

function renderSummary(note = '') {
  const el = $('sequence-summary');
  const all = S.frames.length;
  if (!all) { el.textContent = ''; $('load-actions').hidden = true; return; }
  $('load-actions').hidden = false;
  const good = goodFrames();
  const bad = S.frames.filter((f) => f.error).length;
  const reading = S.frames.filter((f) => f.status).length;
  const parts = [];
  parts.push(`<strong>${escapeHtml(S.seqName || 'Sequence')}</strong>`);
  parts.push(`${good.length} frame${good.length === 1 ? '' : 's'}`);
  if (good.length) {
    const n = good.map((f) => f.points.length / 3);
    const lo = Math.min(...n), hi = Math.max(...n);
    parts.push(lo === hi ? `${fmtInt(lo)} points each` : `${fmtInt(lo)}–${fmtInt(hi)} points`);
  }
  if (S.gt) parts.push('ground truth ✓');
  let html = parts.join(' · ');
  if (reading) html += ` <span class="muted">(reading ${reading}…)</span>`;
  if (bad) html += `<br><span class="msg-error">${bad} file${bad === 1 ? '' : 's'} could not be read (see below); ${bad === 1 ? 'it is' : 'they are'} left out of the fit.</span>`;
  if (!reading && good.length === 1) html += '<br><span class="msg-warn">A sequence needs at least 2 frames: add more PLY files.</span>';
  if (note) html += `<br><span class="msg-warn">${escapeHtml(note)}</span>`;
  const big = good.filter((f) => f.points.length / 3 > 4096).length;
  if (big) html += `<br><span class="muted">${big} frame${big === 1 ? '' : 's'} larger than 4,096 points will be downsampled for the fit (labels are still given for every point).</span>`;
  el.innerHTML = html;
}

function escapeHtml(s) {
  return String(s).replace(/[&<>"']/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' })[c]);
}

function renderFrameList() {
  const ol = $('frame-list');
  ol.replaceChildren();
  const good = goodFrames();
  for (const f of S.frames) {
    const li = document.createElement('li');
    const name = document.createElement('span');
    name.className = 'fname';
    name.textContent = f.name;
    name.title = f.name;
    const count = document.createElement('span');
    count.className = 'fcount';
    li.append(name, count);
    if (f.error) {
      li.className = 'bad';
      count.textContent = 'error';
      const err = document.createElement('span');
      err.className = 'ferror';
      // The core's message starts with the file name; it is already on the row.
      const prefix = `${f.name}: `;
      err.textContent = f.error.startsWith(prefix) ? f.error.slice(prefix.length) : f.error;
      err.title = f.error;
      err.setAttribute('role', 'alert');
      li.appendChild(err);
      li.setAttribute('aria-label', `${f.name}: ${f.error}`);
    } else if (f.status) {
      count.textContent = f.status;
    } else {
      const n = f.points.length / 3;
      count.textContent = `${fmtInt(n)} pts`;
      const gi = good.indexOf(f);
      li.dataset.index = String(gi);
      if (gi === S.current) li.classList.add('current');
      li.addEventListener('click', () => { stopPlay(); showFrame(gi); });
      li.setAttribute('aria-label', `${f.name}, ${n} points`);
    }
    ol.appendChild(li);
  }
}

function updateAutoRange() {
  const good = goodFrames();
  if (good.length < 2) return;
  try {
    const r = wasm.default_part_range(good.map((f) => f.points), good.map((f) => f.name));
    S.autoRange = [r[0], r[1]];
    if ($('parts-auto').checked) {
      $('parts-min').value = r[0];
      $('parts-max').value = r[1];
    }
  } catch (e) {
    console.warn('default_part_range', e);
  }
}

async function handleEntries(entries) {
  const c = classify(entries);
  if (c.kind === 'empty') { toast(c.message, 'error'); return; }
  if (c.kind === 'result') {
    const text = await c.entry.file.text();
    openResult(text, basename(c.entry.path), 'file');
    return;
  }
  const gt = c.gt ? await c.gt.file.text() : null;
  const name = c.folder ? basename(c.folder) : (c.frames.length === 1 ? c.frames[0].file.name : 'Sequence');
  await loadSequence({
    name,
    files: c.frames.map((e) => ({ name: basename(e.path), file: e.file })),
    gt,
    heldout: c.heldout.map((e) => ({ name: basename(e.path), file: e.file })),
    note: c.note,
  });
}

async function loadExample(name, { seed = null } = {}) {
  cancelFit(true);
  if (seed === null) seed = Number($('seed').value) || 0;
  for (const b of document.querySelectorAll('.chip')) b.classList.toggle('current', b.dataset.example === name);
  const token = ++S.loadToken;
  $('sequence-summary').innerHTML = `<span class="muted">Generating “${escapeHtml(name)}”…</span>`;
  let ex;
  try {
    const job = new WorkerJob({ type: 'example', name, seed });
    ex = (await job.promise).example;
  } catch (e) {
    if (EMBED) viewMessage('Could not generate the example', errText(e));
    else toast(`Could not generate the example: ${errText(e)}`, 'error', 8000);
    $('sequence-summary').textContent = '';
    return;
  }
  if (token !== S.loadToken) return;
  resetResult();
  S.seqName = `${name} (example)`;
  S.example = name;
  S.framesUrls = null;
  S.exampleSeed = seed;
  S.gt = ex.gt;
  S.frames = ex.frames.map((f) => ({ name: f.name, points: f.points, labels: f.labels ?? null, error: null, status: null }));
  S.current = 0;
  const url = new URL(location.href);
  url.searchParams.set('example', name);
  url.searchParams.delete('model');
  history.replaceState(null, '', url);
  $('fit-status').textContent = '';
  $('progress').hidden = true;
  afterLoad();
}

// ------------------------------------------------------------------ frames & timeline

function frameCount() {
  if (S.model) return S.model.frames();
  return goodFrames().length;
}

function showFrame(k, { frameBox = false } = {}) {
  const n = frameCount();
  if (!n) { updateHud(); return; }
  k = ((k % n) + n) % n;
  S.current = k;
  $('empty-hint').hidden = true;
  if (S.model) {
    S.frameStates = Float64Array.from(S.model.frame_states(k));
    S.states = S.frameStates.slice();
    syncSliders();
    drawModel({ frameBox });
  } else if (!S.job) {
    const f = goodFrames()[k];
    if (S.view) {
      S.view.clearGaussians();
      S.view.clearAxes();
      S.view.setPoints(f.points, null, { frameBox });
    }
  }
  $('timeline').hidden = n < 2;
  const slider = $('frame-slider');
  slider.max = String(n - 1);
  slider.value = String(k);
  $('frame-label').textContent = `${k + 1} / ${n}`;
  for (const li of $('frame-list').children) li.classList.toggle('current', li.dataset.index === String(k));
  updateHud();
}

function updateHud() {
  const n = frameCount();
  if (!n) { $('hud-title').textContent = ''; $('hud-sub').textContent = ''; return; }
  const k = S.current;
  // `title=` (a figure's caption) names what is on view instead of its file or example.
  let title = params.get('title') ?? (S.seqName || '');
  let sub = '';
  if (S.model) {
    const fname = goodFrames()[k]?.name;
    sub = `frame ${k + 1} of ${n}${fname ? ` · ${fname}` : ''} · ${S.model.parts()} parts`;
    if (S.states && S.frameStates && S.states.some((v, i) => Math.abs(v - S.frameStates[i]) > 1e-9)) sub += ' · re-posed';
  } else if (S.job) {
    sub = 'fitting…';
  } else {
    const f = goodFrames()[k];
    sub = `frame ${k + 1} of ${n} · ${f.name} · ${fmtInt(f.points.length / 3)} points`;
  }
  $('hud-title').textContent = title;
  $('hud-sub').textContent = sub;
}

function play() {
  const joints = S.model && S.states && (PLAY === 'joints' || PLAY === 'together') ? S.model.joints() : [];
  if (!joints.length && frameCount() < 2) return;
  S.playing = true;
  $('btn-play').innerHTML = ICON_PAUSE;
  $('btn-play').setAttribute('aria-label', 'Pause');
  clearInterval(S.playTimer);
  cancelAnimationFrame(S.playRaf);
  if (!joints.length) {
    S.playTimer = setInterval(() => showFrame(S.current + 1), FRAME_S * 1000);
    return;
  }
  // The joints, from the pose on view, by the clock (a slow machine skips, not slows).
  const motion = jointMotion(joints, S.states.slice(), PLAY);
  const t0 = performance.now();
  const step = (now) => {
    if (!S.playing || !S.model) return;
    showJointPose(motion.at((now - t0) / 1000));
    S.playRaf = requestAnimationFrame(step);
  };
  S.playRaf = requestAnimationFrame(step);
}

/** A pose of a joint motion (motion.js `at`) on view: the states, sliders and highlight. */
function showJointPose({ states, moving }) {
  S.states = states;
  syncSliders();
  showMoving(moving);
  drawModel();
}

/**
 * While joints move one at a time (play=joints, the video), the moving joint's axis,
 * tree node and row are highlighted, as when hovered; `child` -1 clears it.
 */
function showMoving(child) {
  if (child === S.movingHot) return;
  S.movingHot = child;
  markHot(child);
}

function stopPlay() {
  S.playing = false;
  clearInterval(S.playTimer);
  cancelAnimationFrame(S.playRaf);
  if (S.movingHot >= 0) { showMoving(-1); if (S.model) drawModel(); }
  $('btn-play').innerHTML = ICON_PLAY;
  $('btn-play').setAttribute('aria-label', 'Play');
}

function togglePlay() { if (S.playing) stopPlay(); else play(); }

// ------------------------------------------------------------------ fitting

function readOptions() {
  const quality = document.querySelector('input[name=quality]:checked')?.value || 'balanced';
  const auto = $('parts-auto').checked;
  let lo = Math.round(Number($('parts-min').value)), hi = Math.round(Number($('parts-max').value));
  const opts = {
    quality,
    occlusion: $('occlusion').value,
    seed: Math.max(0, Math.round(Number($('seed').value) || 0)),
    restarts: Math.min(3, Math.max(1, Math.round(Number($('restarts').value) || 1))),
    medial_init: $('medial-init').checked,
    key_frames: Math.max(0, Math.round(Number($('key-frames').value) || 0)),
    parts: null,
  };
  if (!auto) {
    if (!(lo >= 2) || !(hi >= lo) || hi > 40) throw new Error('Part counts: give a range like 3 to 7 (each at least 2, at most 40).');
    opts.parts = [lo, hi];
  } else {
    [lo, hi] = S.autoRange || [lo, hi];
  }
  return { opts, range: [lo, hi] };
}

const STAGES = [
  { key: 'gaussians', name: 'Step 1 · dynamic Gaussians' },
  { key: 'select', name: 'Choosing the part count' },
  { key: 'tree', name: 'Step 2 · kinematic tree' },
  { key: 'joints', name: 'Step 3 · joints' },
  { key: 'track', name: 'Tracking the frames between key frames' },
  { key: 'metrics', name: 'Metrics against ground truth' },
];

// `withTrack`: a long sequence, fitted on key frames and the other frames tracked.
function buildStages(withMetrics, withTrack = false) {
  const box = $('stage-list');
  box.replaceChildren();
  S.stageEls = {};
  for (const st of STAGES) {
    if (st.key === 'metrics' && !withMetrics) continue;
    if (st.key === 'track' && !withTrack) continue;
    const row = document.createElement('div');
    row.className = 'stage-row pending';
    row.innerHTML = `<span class="sname"></span><span class="seta"></span><div class="bar" role="progressbar" aria-valuemin="0" aria-valuemax="100" aria-valuenow="0"><div></div></div>`;
    row.querySelector('.sname').textContent = st.name;
    row.querySelector('.bar').setAttribute('aria-label', st.name);
    box.appendChild(row);
    S.stageEls[st.key] = { row, t0: null };
  }
}

function setStage(key, frac, text = '') {
  const s = S.stageEls?.[key];
  if (!s) return;
  frac = Math.max(0, Math.min(1, frac));
  if (s.t0 === null) s.t0 = performance.now();
  const row = s.row;
  row.classList.remove('pending');
  row.classList.toggle('done', frac >= 1);
  row.querySelector('.bar > div').style.width = `${(frac * 100).toFixed(1)}%`;
  row.querySelector('.bar').setAttribute('aria-valuenow', String(Math.round(frac * 100)));
  let eta = text;
  if (!eta) {
    if (frac >= 1) eta = `done in ${fmtTime((performance.now() - s.t0) / 1000)}`;
    else if (frac > 0.02) {
      const el = (performance.now() - s.t0) / 1000;
      eta = `${Math.round(frac * 100)}% · ${fmtTime(el / frac - el)} left`;
    } else eta = 'starting…';
  }
  row.querySelector('.seta').textContent = eta;
  // Earlier stages are complete once a later one reports.
  let before = true;
  for (const st of STAGES) {
    if (st.key === key) before = false;
    else if (before && S.stageEls[st.key] && !S.stageEls[st.key].row.classList.contains('done')) {
      const r = S.stageEls[st.key].row;
      r.classList.remove('pending');
      r.classList.add('done');
      r.querySelector('.bar > div').style.width = '100%';
      if (!r.querySelector('.seta').textContent || !r.querySelector('.seta').textContent.startsWith('done')) {
        const t0 = S.stageEls[st.key].t0;
        r.querySelector('.seta').textContent = t0 === null ? 'done' : `done in ${fmtTime((performance.now() - t0) / 1000)}`;
      }
    }
  }
}

function fitUi(running) {
  S.fitRunning = running;
  $('btn-fit').hidden = running;
  $('btn-cancel').hidden = !running;
  for (const el of $('settings').querySelectorAll('input, select')) el.disabled = running || ((el.id === 'parts-min' || el.id === 'parts-max') && $('parts-auto').checked);
  for (const el of document.querySelectorAll('#step-load button, #step-load input, .chip')) el.disabled = running;
  embedState();
}

/** Embed mode's card follows the page: a model's joints, or the fit. */
function embedState() {
  syncEmbed({ joints: S.model ? S.model.joints().length : null, fitting: !!S.fitRunning, frames: goodFrames().length >= 2 });
}

// The loss a progress report's curve shows: [term, value] of its first term among the
// transfer losses (Step 1's Chamfer phase, then its EMD phase) and Step 3's refinement,
// or [null, NaN]. Reports without one (the warm-up's L_MLE, which is negative, and
// L_sep; the pose search's, which carry no losses) are not plotted.
function lossTerm(losses) {
  if (!losses) return [null, NaN];
  const entries = Array.isArray(losses) ? losses : Object.entries(losses);
  for (const p of ['chamfer', 'emd', 'refine']) {
    const e = entries.find(([k]) => k.toLowerCase() === p);
    if (e) return [p, e[1]];
  }
  return [null, NaN];
}

// Steps 2–3 run the tree and the joint refinement again (the symmetry repair, the
// joint sweeps), each from iteration 0: each run is a pass, which the stage row names
// and the chart draws as its own line, so neither seems to go back (as `gsart fit`'s
// bar does). A pass begins when the stage changes or its iteration goes back.
class Passes {
  constructor() { this.last = null; this.tree = 0; this.joints = 0; }
  /** Records a report of stage `key` at iteration `iter`; the pass it belongs to (0 for other stages). */
  update(key, iter) {
    if (key !== 'tree' && key !== 'joints') return 0;
    if (!(this.last && this.last[0] === key && iter >= this.last[1])) this[key] += 1;
    this.last = [key, iter];
    return this[key];
  }
}

// Step 1's curves: a candidate's Chamfer phase solid, its EMD phase dashed in the same
// colour (the two losses differ in scale, so one line would seem to jump up).
const STEP1_CHART = ['Step 1: Chamfer', 'EMD'];

async function startFit() {
  const good = goodFrames();
  if (good.length < 2) { toast('Load at least 2 frames first.', 'error'); return; }
  let opts, range;
  try { ({ opts, range } = readOptions()); } catch (e) { toast(errText(e), 'error'); return; }
  // What a link to this fit's model carries (`shareUrl`).
  S.fitOpts = opts;
  stopPlay();
  resetResult();
  const gtOk = hasTruth(good);
  // A long sequence is fitted on its key frames (the core's choice), and the other
  // frames are tracked with the model at the end (`key_frames::extend_recorded`), as
  // `gsart fit` does.
  let keys;
  try { keys = Array.from(wasm.key_frames(good.length, opts)); } catch (e) { toast(errText(e), 'error'); return; }
  const keyed = keys.length < good.length;
  const fitGood = keyed ? keys.map((k) => good[k]) : good;
  S.fitKeys = keyed ? keys : null;
  buildStages(!!gtOk, keyed);
  $('progress').hidden = false;
  $('step-fit').scrollIntoView({ block: 'start', behavior: 'smooth' });
  S.chart.clear(...STEP1_CHART);
  fitUi(true);
  setStepActive('step-fit');
  // The core decides which part counts a quality tries (fast: the two ends of the
  // range, unless the frames are fitted as occluded).
  let parts;
  try {
    parts = Array.from(wasm.candidate_parts(fitGood.map((f) => f.points), fitGood.map((f) => f.name),
      range[0], range[1], opts));
  } catch (e) {
    $('fit-status').innerHTML = `<span class="msg-error">${escapeHtml(errText(e))}</span>`;
    fitUi(false);
    return;
  }
  const par = Math.min(maxParallel(), parts.length);
  const whole = parts.length === range[1] - range[0] + 1;
  const tried = range[0] === range[1] ? `m = ${range[0]}`
    : whole ? `m = ${range[0]}…${range[1]}` : `m = ${parts.join(', ')} of ${range[0]}…${range[1]}`;
  const fits = (opts.restarts > 1 ? `, best of ${opts.restarts} fits each` : '')
    + (opts.medial_init ? ', started on the medial axis' : '');
  const longSeq = keyed ? ` A long sequence: fitted on ${keys.length} key frames of ${good.length}, the others tracked after.` : '';
  const trying = `Trying ${tried} Gaussians (${par} in parallel${fits}), ${opts.quality} quality.${longSeq}`;
  $('fit-status').innerHTML = trying;
  let job = null; // the attempt running now
  // One attempt of the whole fit with these options (the core may ask for a second,
  // from another seed): Step 1's candidates in workers, then Steps 2–3.
  const attempt = async (jobOpts) => {
    const cands = new Map(); // m -> {iter, total, done}
    const passes = new Passes();
    let totalGuess = 0;
    let nCand = parts.length;
    const step1Progress = () => {
      let done = 0, tot = 0;
      for (const c of cands.values()) { done += c.done ? c.total : c.iter; tot += c.total; }
      const missing = nCand - cands.size;
      tot += missing * totalGuess;
      const finished = [...cands.values()].filter((c) => c.done).length;
      const running = cands.size - finished;
      const frac = tot ? done / tot : 0;
      setStage('gaussians', frac);
      const eta = S.stageEls.gaussians.row.querySelector('.seta');
      eta.textContent = `${finished}/${nCand} done${running ? ` · ${running} running` : ''} · ${eta.textContent}`;
    };
    // Progress reaches the page up to 20 times a second per worker; the page redraws
    // at most every UI_MS: every DOM or view update repaints the page, which on a
    // two-core laptop takes CPU from the workers (robot workload, fast, headless
    // Chromium, per-candidate times: 6.3–7.2 s with a redraw per message, 5.6–6.7 s
    // at UI_MS = 250, 5.0–5.8 s with no progress shown at all).
    let uiTimer = null;
    let pendingSnap = null;
    const refreshUi = () => {
      uiTimer = null;
      if (S.job !== job) return;
      step1Progress();
      if (pendingSnap) showSnapshot(...pendingSnap);
      pendingSnap = null;
    };
    const scheduleUi = () => { if (uiTimer === null) uiTimer = setTimeout(refreshUi, UI_MS); };
    S.working = null;
    S.focusM = null;
    S.gaussiansSnapshot = null;
    job = new FitJob({
      frames: fitGood.map((f) => f.points),
      names: fitGood.map((f) => f.name),
      options: jobOpts,
      parts,
      // Key frames get their metrics after the tracking, on every frame.
      gt: gtOk && !keyed ? S.gt : null,
      labels: gtOk && !keyed ? good.map((f) => f.labels) : null,
      bestOf: (ms, losses) => wasm.best_candidate(Uint32Array.from(ms), Float64Array.from(losses)),
      extraCandidate: (ms, losses, occluded) => wasm.extra_candidate(Uint32Array.from(ms), Float64Array.from(losses),
        jobOpts, occluded, jobOpts.parts === null) ?? null,
      secondLook: (best, runner) => wasm.second_look(best, runner),
      callbacks: {
        onCandidateStart: (m) => {
          cands.set(m, { iter: 0, total: totalGuess, done: false });
          if (S.focusM === null) S.focusM = m;
          step1Progress();
        },
        onWorking: (m, frames) => { if (m === S.focusM || !S.working) S.working = { m, frames }; },
        onCandidateProgress: (m, p) => {
          const c = cands.get(m);
          if (!c) return;
          if (p.stage === 'gaussians' || p.stage === 'init') {
            c.iter = p.iter; c.total = p.total || c.total;
            if (!totalGuess && p.total) totalGuess = p.total;
          }
          const [term, y] = lossTerm(p.losses);
          if (p.total && term) {
            const emd = term === 'emd';
            S.chart.add(emd ? `m${m}:emd` : `m${m}`, `m=${m}`, p.iter / p.total, y, { group: `m${m}`, dashed: emd });
          }
          if (p.snapshot && m === S.focusM) pendingSnap = [m, p.snapshot];
          scheduleUi();
        },
        onExtraCandidate: (m, done) => {
          nCand += 1;
          const top = done[done.length - 1];
          const bottom = done[0];
          $('fit-status').innerHTML = `m = ${top.m} fitted worse than m = ${bottom.m}`
            + ` (final Chamfer ${top.loss.toExponential(2)} against ${bottom.loss.toExponential(2)}): trying m = ${m} too.`;
          step1Progress();
        },
        onCandidateDone: (m) => {
          const c = cands.get(m);
          if (c) c.done = true;
          if (S.focusM === m) {
            // Follow a candidate that is still running.
            const next = [...cands.entries()].find(([, v]) => !v.done);
            S.focusM = next ? next[0] : S.focusM;
          }
          step1Progress();
        },
        onFinishProgress: (p) => {
          const key = p.stage === 'done' ? 'joints' : p.stage;
          if (!S.stageEls[key]) return;
          const frac = p.total ? p.iter / p.total : 0;
          const pass = p.stage === 'done' ? passes.joints : passes.update(key, p.iter);
          setStage(key, frac, pass > 1 && frac < 1 ? `pass ${pass} · ${Math.round(frac * 100)}%` : '');
          const row = S.stageEls[key].row;
          if (pass > 1 && !row.title) {
            row.title = 'Steps 2–3 run again after the symmetry repair and the joint sweeps; each run is a pass.';
          }
          if (key === 'joints' && p.total) {
            if (S.chart.title !== 'Step 3 loss') S.chart.clear('Step 3 loss');
            S.chart.add(`joints${pass}`, `pass ${pass}`, frac, lossTerm(p.losses)[1]);
          }
        },
      },
    });
    S.job = job;
    updateHud();
    const tAttempt = performance.now();
    try {
      const out = await job.run();
      S.movedRunners.push(out.movedRunner);
      attemptMs.push(performance.now() - tAttempt);
      return out;
    } finally {
      clearTimeout(uiTimer);
    }
  };
  // A fit done again (a model that leaves much unexplained) shows the model it has so
  // far while the next attempt runs: it can be explored and exported, and a cancel keeps
  // it as the result.
  const keptCandidate = (o) => o.candidates.find((c) => c.m === o.best) ?? null;
  // What the status says of the earlier attempt's model while another runs.
  const onView = keyed ? '' : '; its model is on view meanwhile, and Cancel keeps it';
  const showProvisional = (o, note) => {
    // A key-frame model does not match the loaded frames until it is tracked.
    if (keyed) return;
    openResult(o.result, S.seqName, 'fit', { best: keptCandidate(o), metrics: o.metrics, metricsError: o.metricsError, provisional: note });
  };
  const t0 = performance.now();
  S.movedRunners = [];
  const attemptMs = []; // wall time of each finished attempt
  let out;
  let retried = '';
  try {
    out = await attempt(opts);
    // A balanced fit of full input whose model leaves much of the clouds unexplained is
    // done once more from another seed, and the core keeps one (`pipeline::retry_wanted`,
    // `pipeline::retry_look`), as `gsart fit` does.
    const retry = wasm.retry_seed(out.result, opts);
    if (retry !== undefined && S.job === job) {
      const { seed } = retry;
      const again = { ...opts, seed };
      const first = out;
      const share = (100 * retry.unexplained).toFixed(2);
      showProvisional(first, `Provisional: the first attempt's model, shown while a second attempt runs (this one left ${share} % of the points unexplained). Cancel to keep it.`);
      buildStages(!!gtOk, keyed);
      S.chart.clear(...STEP1_CHART);
      $('fit-status').innerHTML = `The model left ${share} % of the points unexplained: fitting again from seed ${again.seed}${onView}. ${trying}`;
      let second = null;
      try {
        second = await attempt(again);
      } catch (e) {
        // The second attempt failing leaves the first as it is (a cancel still cancels).
        if (e instanceof CancelledError || S.job !== job) throw e;
        console.warn('second attempt:', e);
      }
      if (second) {
        const look = wasm.retry_look(first.result, second.result, opts);
        const kept = look.second ? second : first;
        out = { ...kept, result: look.result };
        retried = `Fitted twice (seeds ${opts.seed} and ${seed}); the ${look.second ? 'second' : 'first'} was kept. `;
      }
      // Still much unexplained: a third attempt with the Gaussians placed on the last
      // frame (`pipeline::third_wanted`, `pipeline::third_look`), as `gsart fit` does.
      const third = wasm.third_wanted(out.result, opts);
      if (third !== undefined && S.job === job) {
        const kept = out;
        const share3 = (100 * third.unexplained).toFixed(2);
        showProvisional(kept, `Provisional: the model kept from the first two attempts, shown while a third runs (it left ${share3} % of the points unexplained). Cancel to keep it.`);
        buildStages(!!gtOk, keyed);
        S.chart.clear(...STEP1_CHART);
        $('fit-status').innerHTML = `The model kept left ${share3} % of the points unexplained: fitting a third time, with the Gaussians placed on the last frame${onView.replace('its model', 'that model')}. ${trying}`;
        let res3 = null;
        try {
          res3 = await attempt({ ...opts, from_last_frame: true });
        } catch (e) {
          if (e instanceof CancelledError || S.job !== job) throw e;
          console.warn('third attempt:', e);
        }
        if (res3) {
          const look = wasm.third_look(kept.result, res3.result);
          const k = look.third ? res3 : kept;
          out = { ...k, result: look.result };
          retried += `A third attempt from the last frame; the ${look.third ? 'third' : 'earlier one'} was kept. `;
        }
      }
    }
    if (keyed && S.job === job) {
      // Every frame between key frames gets the model's root motion and joint states
      // that fit it, then the metrics on every frame.
      $('fit-status').innerHTML = `Tracking the other ${good.length - keys.length} frames with the model fitted on ${keys.length} key frames…`;
      const frames = good.map((f) => f.points.slice());
      const t1 = performance.now();
      const ext = new WorkerJob(
        {
          type: 'extend', frames, names: good.map((f) => f.name), keys, result: out.result, options: opts,
          gt: gtOk ? S.gt : null, labels: gtOk ? good.map((f) => f.labels) : null,
        },
        frames.map((a) => a.buffer),
        (msg) => {
          if (msg.type === 'progress' && S.stageEls[msg.stage]) setStage(msg.stage, msg.total ? msg.iter / msg.total : 0);
        },
      );
      // Cancel stops the tracking; the fit then ends like any cancelled one.
      job = { cancel: () => ext.cancel() };
      S.job = job;
      const r = await ext.promise;
      out = { ...out, result: r.result, metrics: r.metrics, metricsError: r.metricsError, trackMs: performance.now() - t1 };
    }
  } catch (e) {
    if (S.job !== job) return; // replaced or cancelled by a new load
    S.job = null;
    fitUi(false);
    if (e instanceof CancelledError) return;
    $('fit-status').innerHTML = `<span class="msg-error">The fit failed: ${escapeHtml(errText(e))}</span>`;
    showFrame(S.current);
    return;
  }
  if (S.job !== job) return;
  S.job = null;
  fitUi(false);
  for (const st of STAGES) if (S.stageEls[st.key]) setStage(st.key, 1);
  const secs = (performance.now() - t0) / 1000;
  const best = keptCandidate(out);
  // Where the time went: each candidate's Step 1 in its worker, then Steps 2–3.
  const sec1 = (ms) => `${(ms / 1000).toFixed(1)} s`;
  const perCand = out.candidates.map((c) => `${c.m} (${sec1(c.ms)})`).join(', ');
  // After several attempts: each one's time, then the kept one's split.
  const attempts = attemptMs.length > 1
    ? `The attempts took ${attemptMs.map(sec1).join(', ')}; the kept one's ` : '';
  $('fit-status').innerHTML = `<span class="msg-good">Done in ${fmtTime(secs)}.</span> ${retried}`
    + `${attempts}Step 1: m = ${perCand}; Steps 2–3: ${sec1(out.finishMs)}`
    + (out.trackMs !== undefined ? `; tracking the ${good.length - keys.length} frames between the ${keys.length} key frames: ${sec1(out.trackMs)}.` : '.');
  openResult(out.result, S.seqName, 'fit', { seconds: secs, best, metrics: out.metrics, metricsError: out.metricsError });
}

function showSnapshot(m, snap) {
  // A provisional model (an earlier attempt's) is on view: the next attempt's Gaussians stay off it.
  if (!S.view || !S.working || S.working.m !== m || S.model) return;
  const pts = S.working.frames[snap.frame];
  if (!pts || pts.length / 3 !== snap.labels.length) return;
  S.view.setPoints(pts, snap.labels);
  const nG = snap.centers.length / 3;
  S.view.setGaussians(snap.centers, snap.rotations, snap.scales, Uint32Array.from({ length: nG }, (_, i) => i));
  $('hud-sub').textContent = `fitting m = ${m} · frame ${(S.fitKeys?.[snap.frame] ?? snap.frame) + 1}`;
}

// ------------------------------------------------------------------ results

/**
 * Opens a result (JSON text) on the page. `how`: 'fit' (fitted here), 'file', 'url' or
 * 'edit' (an edit of the model on view, or its undo: the view, the frame and the undo
 * history stay).
 */
function openResult(text, source, how, extra = {}) {
  let model;
  try {
    model = wasm.Model.from_json(text, source || 'result');
  } catch (e) {
    if (EMBED) viewMessage('Could not open the model', errText(e));
    else toast(errText(e), 'error', 9000);
    return false;
  }
  const edit = how === 'edit';
  resetResult({ keepUndo: edit });
  S.model = model;
  S.modelSource = how;
  S.metrics = extra.metrics ?? null;
  S.metricsError = extra.metricsError ?? null;
  // Points: the loaded frames when they match the result, else the points the file carries.
  const good = goodFrames();
  let attached = false;
  if (how === 'fit' || edit || (good.length === model.frames() && good.every((f, k) => model.label_count(k) === f.points.length / 3))) {
    try {
      good.forEach((f, k) => model.set_frame_points(k, f.points));
      attached = true;
    } catch (e) { console.warn('frames do not match the result', e); }
  }
  S.modelAttached = attached;
  if (!attached) {
    if (!model.has_points()) {
      toast('This result carries no points and does not match the loaded frames: load its frames to see it.', 'error', 9000);
    }
    if (how !== 'fit' && !edit) {
      // A shared result stands alone: its frames are not the ones in the list.
      S.seqName = source;
    }
  }
  if (!model.has_tree()) {
    toast('This result has no kinematic tree (the fit stopped after Step 1): segmentation only.', '', 6000);
  }
  S.resultExtra = extra;
  renderResult(extra);
  showFrame(Math.min(S.current, model.frames() - 1), { frameBox: how !== 'fit' && !edit });
  if (how !== 'fit' && !edit) applyHashCamera();
  if (PLAY && !extra.provisional && !edit) play();
  if (!extra.provisional && !EMBED && !edit) {
    // Not in an iframe: scrolling into view there would scroll the host page too.
    setStepActive('step-explore');
    $('step-explore').scrollIntoView({ block: 'start', behavior: 'smooth' });
  }
  embedState();
  return true;
}

function renderResult(extra = {}) {
  const m = S.model;
  $('explore').hidden = false;
  $('explore-empty').hidden = true;
  const joints = m.joints();
  const nR = joints.filter((j) => j.type === 'revolute').length;
  const nP = joints.length - nR;
  const bits = [`<strong>${m.parts()} parts</strong>`, `${joints.length} joint${joints.length === 1 ? '' : 's'}`];
  if (joints.length) bits.push([nR ? `${nR} revolute` : '', nP ? `${nP} prismatic` : ''].filter(Boolean).join(', '));
  const nF = joints.filter((j) => j.mimic).length;
  if (nF) bits.push(`${nF} following another (mimic)`);
  bits.push(`${m.frames()} frames`);
  let html = bits.join(' · ');
  if (extra.provisional) html = `<span class="msg-warn" id="provisional">${escapeHtml(extra.provisional)}</span><br>${html}`;
  const info = m.info();
  const notes = [];
  if (extra.best) notes.push(`chosen m = ${extra.best.m} Gaussians`);
  if (info && typeof info === 'object' && Array.isArray(info.notes)) {
    for (const n of info.notes) if (!/^model selection/.test(n) || !extra.best) notes.push(String(n));
  }
  if (notes.length) html += `<br><span class="muted">${escapeHtml(notes.join(' · '))}</span>`;
  $('result-summary').innerHTML = html;

  // Tree
  const parent = Array.from(m.parents());
  if (parent.length) {
    drawTree($('tree'), {
      parent, root: m.root(), colors: parent.map((_, p) => partColor(p)),
      jointOf: (p) => joints.find((j) => j.child === p) || null,
      onHover: (p) => highlightPart(p),
      onClick: (p) => document.querySelector(`.joint[data-child="${p}"] input`)?.focus(),
    });
  } else {
    $('tree').innerHTML = '<p class="muted small" style="margin:4px">No tree in this result.</p>';
  }

  // Joints
  const list = $('joint-list');
  list.replaceChildren();
  if (!joints.length) list.innerHTML = '<p class="muted small">No joints.</p>';
  joints.forEach((j, idx) => {
    const row = document.createElement('div');
    row.className = 'joint';
    row.dataset.child = String(j.child);
    const sw = document.createElement('span');
    sw.className = 'swatch';
    sw.style.background = partColor(j.child);
    const title = document.createElement('span');
    title.className = 'jtitle';
    title.textContent = `Joint ${idx + 1}: part ${j.parent} → ${j.child}`;
    const val = document.createElement('span');
    val.className = 'jvalue';
    const detail = document.createElement('span');
    detail.className = 'jdetail';
    const ax = j.axis.map((v) => v.toFixed(2)).join(', ');
    const [lo, hi] = j.limits;
    const unit = j.type === 'revolute' ? '°' : '';
    const fmtState = (v) => (j.type === 'revolute' ? `${(v * 180 / Math.PI).toFixed(1)}°` : v.toFixed(3));
    detail.textContent = `${j.type} · axis (${ax}) · range ${fmtState(lo)} … ${fmtState(hi)}`;
    // A joint that follows another (URDF mimic) moves with its leader's slider.
    const leader = j.mimic ? joints.findIndex((x) => x.child === j.mimic.joint) : -1;
    if (leader >= 0) {
      const mul = j.mimic.multiplier, off = j.mimic.offset;
      const offText = fmtState(Math.abs(off));
      // An offset that rounds to nothing is left out.
      const offPart = /[1-9]/.test(offText) ? ` ${off < 0 ? '−' : '+'} ${offText}` : '';
      detail.textContent += ` · follows joint ${leader + 1}: ${mul.toFixed(3)} × its state${offPart}`;
    }
    const slider = document.createElement('input');
    slider.type = 'range';
    // A little room beyond the observed range, so the model can be explored.
    const span = Math.max(hi - lo, j.type === 'revolute' ? 0.2 : 0.02);
    slider.min = String(lo - 0.25 * span);
    slider.max = String(hi + 0.25 * span);
    slider.step = String(span / 400);
    slider.setAttribute('aria-label', `Joint ${idx + 1} (${j.type}, part ${j.child})`);
    slider.dataset.child = String(j.child);
    if (leader >= 0) {
      slider.disabled = true;
      slider.title = `Follows joint ${leader + 1}: move that joint's slider`;
    }
    slider.addEventListener('input', () => {
      // Playing would put the frame's states back on the next frame.
      stopPlay();
      S.states[j.child] = Number(slider.value);
      val.textContent = fmtState(S.states[j.child]);
      // Its followers move with it (the others keep their states on view).
      const followers = joints.filter((x) => x.mimic?.joint === j.child);
      if (followers.length) { follow(followers, S.states); syncSliders(); }
      drawModel();
    });
    slider.addEventListener('focus', () => highlightPart(j.child));
    slider.addEventListener('blur', () => highlightPart(null));
    row.addEventListener('mouseenter', () => highlightPart(j.child));
    row.addEventListener('mouseleave', () => highlightPart(null));
    row.append(sw, title, val, detail, slider);
    if (canEdit()) {
      // Edits by hand: each builds the tree and the joints again (`editModel`).
      const edits = document.createElement('div');
      edits.className = 'jedits';
      const button = (cls, text, tip, label, onClick) => {
        const b = document.createElement('button');
        b.className = `button small ${cls}`;
        b.textContent = text;
        b.title = tip;
        b.setAttribute('aria-label', label);
        b.addEventListener('click', onClick);
        edits.append(b);
      };
      const other = j.type === 'revolute' ? 'prismatic' : 'revolute';
      button('jtype', `Make ${other}`,
        `Fit this joint as a ${other === 'prismatic' ? 'slide' : 'hinge'} instead, then refine the joints again`,
        `Make joint ${idx + 1} ${other}`,
        () => editModel({ joint_types: [[j.child, other]] }, `Making joint ${idx + 1} ${other}`,
          `Joint ${idx + 1} made ${other}`));
      if (leader >= 0) {
        button('junlink', 'Unlink', `This joint moves on its own: it does not follow joint ${leader + 1}`,
          `Unlink joint ${idx + 1} from joint ${leader + 1}`,
          () => editModel({ unlink: [j.child] }, `Unlinking joint ${idx + 1}`, `Joint ${idx + 1} unlinked`));
      }
      button('jjoin', 'Join', `No joint here: make part ${j.child} one rigid part with part ${j.parent}, then build the tree and the joints again`,
        `Join part ${j.child} to part ${j.parent}`,
        () => editModel({ join: [[j.parent, j.child]] }, `Joining part ${j.child} to part ${j.parent}`,
          `Parts ${j.parent} and ${j.child} joined`));
      row.append(edits);
    }
    row._fmt = fmtState;
    row._unit = unit;
    list.appendChild(row);
  });

  $('btn-undo-edit').hidden = !S.undo.length;
  const rootSel = $('root-part');
  $('root-edit').hidden = !canEdit() || m.parts() < 2;
  rootSel.disabled = !!S.editJob;
  rootSel.replaceChildren(...Array.from({ length: m.parts() }, (_, p) => {
    const o = document.createElement('option');
    o.value = String(p);
    o.textContent = `part ${p}`;
    o.selected = parent.length > 0 && p === m.root();
    return o;
  }));
  // Metrics
  renderMetrics();
}

// ------------------------------------------------------------------ edits

/**
 * Whether the model on view can be edited by hand: it labels the loaded frames (an
 * edit builds its tree and joints again on them), it has a tree, and no fit runs.
 */
function canEdit() {
  return !!S.model && S.modelAttached && S.model.has_tree() && !EMBED && !S.fitRunning;
}

function editStatus(html) {
  const el = $('edit-status');
  el.hidden = !html;
  $('edit-text').innerHTML = html || '';
}

function editButtons(enabled) {
  for (const b of document.querySelectorAll('.jedits button, #root-part')) b.disabled = !enabled;
  // An edit that did not happen leaves the root as it is.
  if (enabled && S.model?.has_tree()) $('root-part').value = String(S.model.root());
}

/**
 * Edits the model by hand: `edit` is the core's `edit::Edit` (`join`: parts to make
 * one, e.g. a joint that should not be there or two pieces of one link; `joint_types`:
 * a joint's type). The core's `edit_model` in a worker builds the tree and the joints
 * again on the loaded frames, keeping the rest of the tree. The model before goes on
 * the undo history. `doing` and `done` name the edit in the status line and the toast.
 */
async function editModel(edit, doing, done) {
  if (!canEdit() || S.editJob) return;
  stopPlay();
  const good = goodFrames();
  const before = { text: S.model.to_json(false), source: S.modelSource, extra: S.resultExtra };
  const gtOk = hasTruth(good);
  const frames = good.map((f) => f.points.slice());
  // Unlinking alone changes no geometry, so the core does not build the model again.
  const onlyUnlink = edit.unlink && !edit.join && !edit.joint_types && edit.root === undefined;
  editStatus(onlyUnlink ? `${escapeHtml(doing)}…` : `${escapeHtml(doing)}: building the tree and the joints again…`);
  editButtons(false);
  const t0 = performance.now();
  const job = new WorkerJob(
    {
      type: 'edit', frames, names: good.map((f) => f.name), result: before.text, edit,
      gt: gtOk ? S.gt : null, labels: gtOk ? good.map((f) => f.labels) : null,
    },
    frames.map((a) => a.buffer),
    (msg) => {
      if (msg.type !== 'progress' || S.editJob !== job) return;
      const step = msg.stage === 'joints' ? `refining the joints ${msg.iter}/${msg.total}`
        : msg.stage === 'metrics' ? 'metrics' : 'building the tree';
      editStatus(`${escapeHtml(doing)}: ${step}…`);
    },
  );
  S.editJob = job;
  try {
    const r = await job.promise;
    if (S.editJob !== job) return;
    S.editJob = null;
    const old = S.model.parts();
    S.undo.push(before);
    if (!openResult(r.result, S.seqName, 'edit', { ...before.extra, metrics: r.metrics, metricsError: r.metricsError })) {
      // openResult said why; the model before is still on view.
      S.undo.pop();
      editStatus('');
      editButtons(true);
      return;
    }
    const n = S.model.joints().length;
    editStatus('');
    toast(`${done} in ${((performance.now() - t0) / 1000).toFixed(1)} s: `
      + `${old} → ${S.model.parts()} parts, ${n} joint${n === 1 ? '' : 's'}.`, '', 5000);
  } catch (e) {
    if (S.editJob === job) S.editJob = null;
    editStatus('');
    editButtons(true);
    if (!(e instanceof CancelledError)) toast(`Could not edit the model: ${errText(e)}`, 'error', 9000);
  }
}

/** The model before the last edit, back on view. */
function undoEdit() {
  const prev = S.undo.pop();
  if (!prev || S.editJob) { if (prev) S.undo.push(prev); return; }
  if (!openResult(prev.text, S.seqName, 'edit', prev.extra)) return;
  // It is the model it was before, not an edit.
  S.modelSource = prev.source;
  toast('Edit undone.', '', 2500);
}

function syncSliders() {
  for (const row of document.querySelectorAll('.joint')) {
    const c = Number(row.dataset.child);
    const s = row.querySelector('input');
    if (!S.states) continue;
    s.value = String(S.states[c]);
    row.querySelector('.jvalue').textContent = row._fmt(S.states[c]);
  }
}

function drawModel({ frameBox = false } = {}) {
  const m = S.model;
  if (!m || !S.view) { updateHud(); return; }
  const k = S.current;
  try {
    const pts = m.pose_points(k, S.states);
    const labels = m.labels(k);
    S.view.setPoints(pts, labels, { frameBox });
    const g = m.pose_gaussians(k, S.states);
    if (g) S.view.setGaussians(g.centers, g.rotations, g.scales, g.parts);
    else S.view.clearGaussians();
    const ax = m.joint_axes(k, S.states);
    const hl = S.hot >= 0 ? Array.from(ax.children).indexOf(S.hot) : -1;
    S.view.setAxes(ax.origins, ax.dirs, ax.kinds, hl);
  } catch (e) {
    console.error(e);
    toast(`Cannot draw this result: ${errText(e)}`, 'error', 8000);
  }
  updateHud();
}

function highlightPart(p) {
  markHot(p ?? -1);
  if (S.model) drawModel();
}

/** Part `p` (-1: none) is the hot one: its axis, tree node and joint row stand out. */
function markHot(p) {
  S.hot = p;
  for (const el of document.querySelectorAll('.tree .node')) el.classList.toggle('hot', Number(el.dataset.part) === p);
  for (const el of document.querySelectorAll('.joint')) el.classList.toggle('hot', Number(el.dataset.child) === p);
}

const METRIC_LABELS = [
  ['reconstruction_error', 'Reconstruction error', '×100, lower is better'],
  ['flow_error', 'Flow error (EPE)', '×100, lower is better'],
  ['mean_ri', 'Rand index (mean over frames)', 'higher is better'],
  ['canonical_ri', 'Rand index (canonical frame)', 'higher is better'],
  ['tree_edit_distance', 'Tree edit distance', 'lower is better'],
  ['reanimation_error', 'Re-animation error', '×100, lower is better'],
];

function renderMetrics() {
  const wrap = $('metrics-wrap');
  const t = $('metrics');
  t.replaceChildren();
  if (S.metricsError) {
    wrap.hidden = false;
    t.innerHTML = `<tr><td class="msg-error">${escapeHtml(S.metricsError)}</td></tr>`;
    return;
  }
  const mt = S.metrics;
  if (!mt) { wrap.hidden = true; return; }
  wrap.hidden = false;
  const seen = new Set();
  const row = (label, hint, v) => {
    const tr = document.createElement('tr');
    const a = document.createElement('td');
    a.textContent = label;
    if (hint) { const h = document.createElement('div'); h.className = 'hint'; h.textContent = hint; a.appendChild(h); }
    const b = document.createElement('td');
    b.textContent = typeof v === 'number' ? (Number.isInteger(v) ? String(v) : v.toFixed(Math.abs(v) < 10 ? 3 : 2)) : String(v);
    tr.append(a, b);
    t.appendChild(tr);
  };
  for (const [k, label, hint] of METRIC_LABELS) {
    if (mt[k] !== undefined && mt[k] !== null) { row(label, hint, mt[k]); seen.add(k); }
  }
  const jt = mt.joints;
  if (jt && typeof jt === 'object') {
    row('Joints found', 'true joints joining two recovered parts', `${jt.found} / ${jt.joints}`);
    row('Joint types right', 'of the found joints', `${jt.type_correct} / ${jt.found}`);
    if (jt.max_axis_deg != null) row('Largest axis error', 'degrees, found joints', jt.max_axis_deg);
    if (jt.max_pivot_error != null) row('Largest pivot error', '×100, found revolute joints', jt.max_pivot_error);
    if (jt.within_bar != null) row('Joints within 5° and 2 %', 'right type, axis within 5°, a hinge\'s pivot within 2 % of the object size', `${jt.within_bar} / ${jt.joints}`);
  }
  for (const [k, v] of Object.entries(mt)) {
    if (seen.has(k) || v === null || typeof v === 'object') continue;
    row(k.replace(/_/g, ' '), '', v);
  }
  for (const n of Array.isArray(mt.notes) ? mt.notes : []) {
    const tr = document.createElement('tr');
    const td = document.createElement('td');
    td.colSpan = 2;
    td.className = 'hint';
    td.textContent = n;
    tr.appendChild(td);
    t.appendChild(tr);
  }
}

// ------------------------------------------------------------------ export & share

function exportName() { return safeName(S.seqName.replace(/ \(example\)$/, '').replace(/(\.gsart)?\.json$/i, '')); }

function exportJson() {
  if (!S.model) return;
  download(new Blob([S.model.to_json(true)], { type: 'application/json' }), `${exportName()}.gsart.json`);
}

function exportPly() {
  if (!S.model) return;
  const n = S.model.frames();
  const files = [];
  const names = goodFrames().map((f) => f.name);
  try {
    for (let k = 0; k < n; k++) {
      const base = wasm.frame_stem(names[k] || `frame_${String(k).padStart(3, '0')}.ply`);
      files.push({ name: `${base}_parts.ply`, bytes: S.model.segmented_ply(k) });
    }
  } catch (e) { toast(errText(e), 'error', 8000); return; }
  if (files.length === 1) download(new Blob([files[0].bytes]), files[0].name);
  else download(zip(files), `${exportName()}_segmented_ply.zip`);
}

/** The URDF and its link meshes (each part's convex hull, binary STL) in one zip. */
function exportUrdf() {
  if (!S.model) return;
  try {
    const files = Array.from(S.model.urdf_files(exportName(), 'hull'));
    download(zip(files), `${exportName()}_urdf.zip`);
  } catch (e) { toast(errText(e), 'error', 8000); }
}

async function exportPng() {
  if (!S.view) { toast('No 3D view to capture.', 'error'); return; }
  const blob = await S.view.screenshot();
  if (blob) download(blob, `${exportName()}_frame${S.current + 1}.png`);
  else toast('The screenshot could not be encoded.', 'error');
}

/**
 * A video of the view (MP4 or WebM): the joints swept through their ranges (one at a
 * time, or all at once) from the pose on view, or the frames as Play shows them;
 * optionally with the camera turning once around. Afterwards the pose, frame and camera
 * are put back.
 */
async function exportVideo() {
  if (S.video) { S.video.abort(); return; }
  if (!S.model || !S.view) return;
  const mode = $('video-mode').value, format = $('video-format').value;
  const joints = S.model.joints();
  if (mode !== 'frames' && !joints.length) { toast('This model has no joints to move: choose "The frames".', 'error', 6000); return; }
  stopPlay();
  const saved = { current: S.current, states: S.states?.slice() ?? null, cam: S.view.cameraState() };
  let frames, pose;
  if (mode === 'frames') {
    const per = Math.round(FRAME_S * FPS);
    frames = S.model.frames() * per;
    pose = (i) => { const k = Math.floor(i / per); if (k !== S.current || i === 0) showFrame(k); return k; };
  } else {
    const motion = jointMotion(joints, saved.states ?? [], mode);
    frames = Math.round(motion.seconds * FPS);
    pose = (i) => { showJointPose(motion.at(i / FPS)); return i; };
  }
  const dpr = window.devicePixelRatio || 1;
  const [width, height] = videoSize(Math.round(S.view.canvas.clientWidth * dpr), Math.round(S.view.canvas.clientHeight * dpr));
  const ctl = new AbortController();
  S.video = ctl;
  document.body.classList.add('recording');
  const btn = $('btn-export-video'), status = $('video-status');
  btn.textContent = 'Cancel video';
  status.hidden = false;
  const secs = (frames / FPS).toFixed(1);
  status.textContent = `Recording ${secs} s at ${width} × ${height}…`;
  const model = S.model;
  try {
    const blob = await recordVideo({
      wasm, viewer: S.view.viewer, format, width, height, frames, pose,
      turn: $('video-turn').checked ? (2 * Math.PI) / frames : 0,
      signal: ctl.signal,
      onProgress: (done, total) => { status.textContent = `Recording ${secs} s at ${width} × ${height}: ${Math.floor((100 * done) / total)} %`; },
    });
    download(blob, `${exportName()}_${mode}.${format}`);
    status.textContent = `Saved a ${secs} s video, ${width} × ${height}, ${(blob.size / 1e6).toFixed(1)} MB.`;
  } catch (e) {
    if (e?.name === 'AbortError') status.textContent = 'The video was cancelled.';
    else {
      status.textContent = e instanceof VideoUnsupported ? e.message : `The video failed: ${errText(e)}`;
      if (!(e instanceof VideoUnsupported)) console.error(e);
    }
  } finally {
    S.video = null;
    document.body.classList.remove('recording');
    showMoving(-1);
    btn.textContent = 'Save video';
    // Put back what was on view: the camera, and the pose unless the model itself was
    // replaced meanwhile.
    S.view?.setCameraState(saved.cam);
    if (S.model === model && S.view) {
      showFrame(saved.current);
      if (saved.states) { S.states = saved.states; syncSliders(); drawModel(); }
    }
  }
}

/**
 * The link that opens what is on view: `?model=URL` for a model opened from a URL (or
 * `model`, given), `?example=NAME` for an example and `?frames=URL` for frames opened
 * from URLs (with `fit=1` when `fitted`), the camera in the hash. Null for frames or a
 * result that came from this machine, which have no URL.
 */
function shareUrl({ fitted = false, model = null } = {}) {
  const url = new URL(location.href);
  for (const k of ['model', 'example', 'frames', 'gt', 'fit', 'embed', ...SETTING_KEYS]) url.searchParams.delete(k);
  if (S.view) {
    const h = new URLSearchParams();
    h.set('cam', S.view.cameraState());
    url.hash = h.toString();
  }
  if (model) url.searchParams.set('model', model);
  else if (S.modelSource === 'url' && S.modelUrl) url.searchParams.set('model', new URL(S.modelUrl, location.href).toString());
  else if (S.example && S.modelSource !== 'edit') {
    // An edited model is not the example's fit: it has no address until saved.
    url.searchParams.set('example', S.example);
    if (S.model && S.modelSource === 'fit' && S.fitOpts) {
      // The settings of the fit on view: the link's page fits as this one did.
      writeSettings(url, S.fitOpts, S.exampleSeed);
      if (fitted) url.searchParams.set('fit', '1');
    } else writeSettings(url, { ...DEFAULTS, seed: S.exampleSeed ?? 0 });
  } else if (S.framesUrls && (!S.model || S.modelSource === 'fit')) {
    for (const u of S.framesUrls.frames) url.searchParams.append('frames', u);
    if (S.framesUrls.gt) url.searchParams.set('gt', S.framesUrls.gt);
    if (S.model && S.fitOpts) {
      writeSettings(url, S.fitOpts);
      if (fitted) url.searchParams.set('fit', '1');
    }
  } else return null;
  return url;
}

const NOT_SHAREABLE = 'To share a fitted model, export the result JSON, put it online, and open ?model=URL.';

async function copyText(text, what, note = '') {
  try {
    await navigator.clipboard.writeText(text);
    toast(`${what} copied.${note ? ` ${note}` : ''}`, '', note ? 7000 : 3000);
  } catch {
    toast(text, '', 10000);
  }
}

async function copyLink() {
  if (S.model && S.modelSource === 'edit') {
    // The page's own address would open the example and fit it again, without the edit.
    toast(`An edited model has no link yet. ${NOT_SHAREABLE}`, '', 7000);
    return;
  }
  const url = shareUrl();
  if (url) await copyText(readableUrl(url), 'Link');
  else await copyText(location.href, 'Link', NOT_SHAREABLE);
}

/**
 * An iframe for a project page: the view, the timeline and the sliders only. A model
 * fitted here or opened from a file has no URL yet: its result JSON is saved, and the
 * code names it at a place-holder address to replace with where it is put.
 */
async function copyEmbed() {
  let url = shareUrl({ fitted: true });
  const fitted = S.framesUrls ? 'frames' : 'example';
  let note = url?.searchParams.get('fit') === '1' ? `The figure fits the ${fitted} in the visitor's browser, with this fit's settings.` : '';
  if (!url) {
    if (!S.model) { toast('Nothing to embed yet: fit the frames first, or open a model.', 'error', 6000); return; }
    const file = `${exportName()}.gsart.json`;
    exportJson();
    url = shareUrl({ model: `https://YOUR.HOST/PATH/${file}` });
    note = `Saved ${file}: put it online where the figure's page can read it, and write its address in place of https://YOUR.HOST/PATH/${file}.`;
  }
  url.searchParams.set('embed', '1');
  await copyText(iframeCode(readableUrl(url), `${S.seqName || 'model'} (GSArt)`), 'Embed code', note);
}

// ------------------------------------------------------------------ events

function wire() {
  $('file-input').addEventListener('change', async (e) => {
    const entries = entriesFromInput(e.target);
    e.target.value = '';
    if (entries.length) await handleEntries(entries);
  });
  $('folder-input').addEventListener('change', async (e) => {
    const entries = entriesFromInput(e.target);
    e.target.value = '';
    if (entries.length) await handleEntries(entries);
  });
  let depth = 0;
  const overlay = $('drop-overlay');
  window.addEventListener('dragenter', (e) => {
    if (EMBED || ![...(e.dataTransfer?.types || [])].includes('Files')) return;
    e.preventDefault();
    depth++;
    overlay.hidden = false;
  });
  window.addEventListener('dragover', (e) => { e.preventDefault(); if (e.dataTransfer) e.dataTransfer.dropEffect = EMBED ? 'none' : 'copy'; });
  window.addEventListener('dragleave', () => { depth = Math.max(0, depth - 1); if (!depth) overlay.hidden = true; });
  window.addEventListener('drop', async (e) => {
    e.preventDefault();
    if (EMBED) return;
    depth = 0;
    overlay.hidden = true;
    if (S.job) { toast('A fit is running: cancel it before loading new files.', 'error'); return; }
    const entries = await entriesFromDrop(e.dataTransfer);
    if (entries.length) await handleEntries(entries);
  });

  $('btn-clear').addEventListener('click', () => {
    cancelFit(true);
    resetResult();
    S.loadToken++;
    S.frames = [];
    S.gt = null;
    S.heldout = null;
    S.example = null;
    S.seqName = '';
    renderFrameList();
    renderSummary();
    $('btn-fit').disabled = true;
    $('timeline').hidden = true;
    $('empty-hint').hidden = false;
    $('fit-status').textContent = '';
    $('progress').hidden = true;
    if (S.view) S.view.setPoints(new Float32Array(0), null);
    for (const b of document.querySelectorAll('.chip')) b.classList.remove('current');
    updateHud();
    setStepActive('step-load');
  });

  $('parts-auto').addEventListener('change', () => {
    const auto = $('parts-auto').checked;
    $('parts-min').disabled = auto;
    $('parts-max').disabled = auto;
    if (auto && S.autoRange) { $('parts-min').value = S.autoRange[0]; $('parts-max').value = S.autoRange[1]; }
  });
  $('btn-fit').addEventListener('click', startFit);
  $('btn-cancel').addEventListener('click', () => cancelFit());

  $('btn-play').addEventListener('click', togglePlay);
  $('frame-slider').addEventListener('input', (e) => { stopPlay(); showFrame(Number(e.target.value)); });
  $('btn-reset-view').addEventListener('click', () => S.view?.resetView());
  $('btn-frame').addEventListener('click', () => S.view?.frameObject());
  $('btn-gaussians').addEventListener('click', toggleGaussians);
  $('btn-screenshot').addEventListener('click', exportPng);
  $('btn-reset-joints').addEventListener('click', () => { if (S.model) showFrame(S.current); });
  $('btn-undo-edit').addEventListener('click', undoEdit);
  $('root-part').addEventListener('change', (e) => {
    const p = Number(e.target.value);
    editModel({ root: p }, `Making part ${p} the root`, `Part ${p} made the root`);
  });
  $('btn-cancel-edit').addEventListener('click', () => {
    S.editJob?.cancel();
    S.editJob = null;
    editStatus('');
    editButtons(true);
  });
  $('btn-export-json').addEventListener('click', exportJson);
  $('btn-export-ply').addEventListener('click', exportPly);
  $('btn-export-urdf').addEventListener('click', exportUrdf);
  $('btn-export-png').addEventListener('click', exportPng);
  $('btn-export-video').addEventListener('click', exportVideo);
  $('btn-share').addEventListener('click', copyLink);
  $('btn-embed').addEventListener('click', copyEmbed);

  $('help-button').addEventListener('click', () => toggleHelp(true));
  $('help-close').addEventListener('click', () => toggleHelp(false));
  $('help').addEventListener('click', (e) => { if (e.target === $('help')) toggleHelp(false); });

  window.addEventListener('keydown', (e) => {
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    // A recording video owns the view until it ends.
    if (S.video) return;
    const t = e.target;
    const typing = t instanceof HTMLElement && (t.tagName === 'INPUT' || t.tagName === 'SELECT' || t.tagName === 'TEXTAREA' || t.isContentEditable);
    if (e.key === 'Escape') { toggleHelp(false); return; }
    if (typing && !(t.type === 'range' && (e.key === ' ' || /^[rRfFgG?]$/.test(e.key)))) return;
    if (t instanceof HTMLElement && t.tagName === 'BUTTON' && (e.key === ' ' || e.key === 'Enter')) return;
    switch (e.key) {
      case ' ': e.preventDefault(); togglePlay(); break;
      case 'ArrowRight': case 'ArrowLeft': case 'ArrowUp': case 'ArrowDown':
        if (!e.shiftKey) break;
        // Shift + arrows orbit the camera (plain arrows step frames).
        e.preventDefault();
        S.view?.orbit({ ArrowRight: 20, ArrowLeft: -20, ArrowUp: 0, ArrowDown: 0 }[e.key],
          { ArrowRight: 0, ArrowLeft: 0, ArrowUp: -20, ArrowDown: 20 }[e.key]);
        return;
      case '+': case '=': S.view?.zoom(1 / 1.15); return;
      case '-': case '_': S.view?.zoom(1.15); return;
    }
    switch (e.key) {
      case 'ArrowRight': e.preventDefault(); stopPlay(); showFrame(S.current + 1); break;
      case 'ArrowLeft': e.preventDefault(); stopPlay(); showFrame(S.current - 1); break;
      case 'r': case 'R': S.view?.resetView(); break;
      case 'f': case 'F': S.view?.frameObject(); break;
      case 'g': case 'G': toggleGaussians(); break;
      case '?': toggleHelp($('help').hidden); break;
      default: break;
    }
  });
}

function toggleGaussians() {
  S.gaussiansOn = !S.gaussiansOn;
  $('btn-gaussians').setAttribute('aria-pressed', String(S.gaussiansOn));
  S.view?.setGaussiansVisible(S.gaussiansOn);
}

function toggleHelp(show) {
  $('help').hidden = !show;
  if (show) $('help-close').focus();
}

function renderExamples() {
  const box = $('example-list');
  let names = [];
  try { names = Array.from(wasm.example_names()); } catch (e) { console.warn('example_names', e); }
  for (const n of names) {
    const b = document.createElement('button');
    b.className = 'chip';
    b.textContent = n;
    b.dataset.example = n;
    b.setAttribute('aria-label', `Example ${n}`);
    b.addEventListener('click', () => loadExample(n));
    box.appendChild(b);
  }
}

/** The response of `url`, or an error that says why there is none. */
async function fetchOk(url) {
  let res;
  try {
    res = await fetch(url);
  } catch (e) {
    // fetch rejects with a TypeError, and no status, when the network or CORS stops it.
    throw new Error(`${url}: ${errText(e)} (the server is unreachable or does not allow other sites to read the file: it needs CORS)`);
  }
  if (!res.ok) throw new Error(`${url}: HTTP ${res.status} ${res.statusText}`);
  return res;
}

const urlName = (url) => basename(new URL(url, location.href).pathname);

async function openModelUrl(url) {
  $('sequence-summary').innerHTML = `<span class="muted">Opening ${escapeHtml(url)}…</span>`;
  try {
    const text = await (await fetchOk(url)).text();
    $('sequence-summary').textContent = '';
    if (openResult(text, urlName(url) || 'model', 'url')) S.modelUrl = url;
  } catch (e) {
    $('sequence-summary').textContent = '';
    if (EMBED) viewMessage('Could not open the model', errText(e));
    else toast(`Could not open the model: ${errText(e)}`, 'error', 10000);
  }
}

/**
 * `?frames=URL` (repeatable; one `.npz`/`.npy` can hold the whole sequence) and
 * `gt=URL`: a sequence put online, loaded as dropped files are, then fitted when the
 * link says `fit=1` — a figure that fits the authors' own data in the visitor's browser.
 */
async function openFramesUrls(urls, gtUrl) {
  const what = urls.length === 1 ? escapeHtml(urls[0]) : `${urls.length} files`;
  $('sequence-summary').innerHTML = `<span class="muted">Downloading ${what}…</span>`;
  let files;
  let gt = null;
  try {
    files = await Promise.all(urls.map(async (u) => ({ name: urlName(u) || 'frames', bytes: await (await fetchOk(u)).arrayBuffer() })));
    if (gtUrl) gt = await (await fetchOk(gtUrl)).text();
  } catch (e) {
    $('sequence-summary').textContent = '';
    if (EMBED) viewMessage('Could not open the frames', errText(e));
    else toast(`Could not open the frames: ${errText(e)}`, 'error', 10000);
    return;
  }
  const first = new URL(urls[0], location.href).pathname;
  const name = urls.length === 1 ? files[0].name : (basename(first.slice(0, first.lastIndexOf('/'))) || 'Sequence');
  const abs = (u) => new URL(u, location.href).toString();
  await loadSequence({ name, files, gt, urls: { frames: urls.map(abs), gt: gtUrl ? abs(gtUrl) : null } });
}

/** Sets the fit form from the link's settings (`settings.js`); says which were ignored. */
function applyUrlSettings() {
  const { values, problems } = settingsFromParams(params);
  if (values.quality) document.querySelector(`input[name=quality][value=${values.quality}]`).checked = true;
  if (values.occlusion) $('occlusion').value = values.occlusion;
  if (values.seed !== undefined) $('seed').value = String(values.seed);
  if (values.restarts) $('restarts').value = String(values.restarts);
  if (values.medial_init !== undefined) $('medial-init').checked = values.medial_init;
  if (values.key_frames !== undefined) $('key-frames').value = String(values.key_frames);
  if (values.parts) {
    $('parts-min').value = String(values.parts[0]);
    $('parts-max').value = String(values.parts[1]);
    // The checkbox's own handler enables the two fields.
    $('parts-auto').checked = false;
    $('parts-auto').dispatchEvent(new Event('change'));
  }
  if (problems.length) toast(`Ignored in the link: ${problems.join('; ')}.`, 'error', 9000);
}

// ------------------------------------------------------------------ start

async function main() {
  S.chart = new LossChart($('loss-chart'));
  try {
    await init();
  } catch (e) {
    $('backend').textContent = 'failed';
    $('backend').className = 'badge none';
    $('view-message').innerHTML = `<div class="box"><h2>GSArt could not start</h2><p>The WebAssembly module failed to load: ${escapeHtml(errText(e))}</p></div>`;
    $('view-message').hidden = false;
    return;
  }
  $('version').textContent = wasm.version();
  wire();
  setupEmbed({ fullUrl: () => withoutEmbed(location.href) });
  applyUrlSettings();
  renderExamples();
  await startView();
  // Display options of a link or a figure: `gaussians=0` hides the Gaussians, `play=1`
  // plays the frames once something is on view.
  if (params.get('gaussians') === '0') toggleGaussians();
  document.body.dataset.ready = '1';
  const model = params.get('model');
  const example = params.get('example');
  const frames = params.getAll('frames').filter(Boolean);
  if (model) await openModelUrl(model);
  else if (frames.length) await openFramesUrls(frames, params.get('gt'));
  else if (example) await loadExample(example, { seed: exampleSeed(params, Number($('seed').value) || 0) });
  else if (EMBED) viewMessage('Nothing to show', 'An embedded GSArt figure needs ?model=URL (a result JSON), ?frames=URL (a sequence online) or ?example=NAME.');
  else setStepActive('step-load');
  if (PLAY && !S.fitRunning && !S.playing) play();
  document.body.dataset.loaded = '1';
}

main();

// Exposed for tests and the console.
window.gsart = { state: S, showFrame, loadExample, startFit, cancelFit, openResult };
