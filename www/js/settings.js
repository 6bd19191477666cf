// The fit settings in a link: `?example=laptop&fit=1&quality=fast&parts=2..4&seed=3`
// opens the example and fits it as the author did (a fit is deterministic for its
// settings, and the page's equals the CLI's). Parsing and writing are pure; the page
// applies the values to its form.

export const DEFAULTS = { quality: 'balanced', occlusion: 'auto', seed: 0, restarts: 1, medial_init: false, key_frames: 20, parts: null };
// The page's choices of key frames for long sequences (0: every frame).
const KEY_FRAMES = [20, 12, 40, 0];

const QUALITIES = ['fast', 'balanced', 'paper'];
const OCCLUSIONS = ['auto', 'on', 'off'];

/**
 * The settings a URL's query gives, as `{ values, problems }`: `values` holds only the
 * settings present and valid (the `readOptions` names), `problems` one message per
 * parameter that was given but could not be used.
 */
export function settingsFromParams(params) {
  const values = {};
  const problems = [];
  const get = (k) => { const v = params.get(k); return v === null ? null : v.trim(); };
  const q = get('quality');
  if (q !== null) {
    if (QUALITIES.includes(q)) values.quality = q;
    else problems.push(`quality=${q}: use ${QUALITIES.join(', ')}`);
  }
  const o = get('occlusion');
  if (o !== null) {
    if (OCCLUSIONS.includes(o)) values.occlusion = o;
    else problems.push(`occlusion=${o}: use ${OCCLUSIONS.join(', ')}`);
  }
  const s = get('seed');
  if (s !== null) {
    if (/^\d{1,9}$/.test(s)) values.seed = Number(s);
    else problems.push(`seed=${s}: use a whole number ≥ 0`);
  }
  const r = get('restarts');
  if (r !== null) {
    if (/^[123]$/.test(r)) values.restarts = Number(r);
    else problems.push(`restarts=${r}: use 1, 2 or 3`);
  }
  const m = get('medial');
  if (m !== null) {
    if (m === '0' || m === '1') values.medial_init = m === '1';
    else problems.push(`medial=${m}: use 0 or 1`);
  }
  const kf = get('keys');
  if (kf !== null) {
    if (/^\d{1,2}$/.test(kf) && KEY_FRAMES.includes(Number(kf))) values.key_frames = Number(kf);
    else problems.push(`keys=${kf}: use ${KEY_FRAMES.join(', ')} (0: every frame)`);
  }
  const p = get('parts');
  if (p !== null) {
    // "3..7" as the CLI writes it, or "3-7"; one number is a single part count.
    const mm = p.match(/^(\d{1,2})(?:(?:\.\.|-)(\d{1,2}))?$/);
    const lo = mm ? Number(mm[1]) : NaN;
    const hi = mm ? Number(mm[2] ?? mm[1]) : NaN;
    if (lo >= 2 && hi >= lo && hi <= 40) values.parts = [lo, hi];
    else problems.push(`parts=${p}: use a range like 3..7 (each at least 2, at most 40)`);
  }
  return { values, problems };
}

/** The query parameters of the settings (and `example_seed`, see `exampleSeed`). */
export const SETTING_KEYS = ['quality', 'occlusion', 'seed', 'restarts', 'medial', 'keys', 'parts', 'example_seed'];

/**
 * The seed an example is generated with: `example_seed` when the link has it (the
 * author changed the seed after generating the example), else the fit's `seed`.
 */
export function exampleSeed(params, fallback) {
  const v = params.get('example_seed');
  return v !== null && /^\d{1,9}$/.test(v.trim()) ? Number(v.trim()) : fallback;
}

/**
 * Writes the settings of `opts` that differ from the defaults into `url`'s query (the
 * others removed), and `example_seed` when the example was generated with another seed.
 */
export function writeSettings(url, opts, genSeed = opts.seed) {
  const sp = url.searchParams;
  for (const k of SETTING_KEYS) sp.delete(k);
  if (opts.quality !== DEFAULTS.quality) sp.set('quality', opts.quality);
  if (opts.occlusion !== DEFAULTS.occlusion) sp.set('occlusion', opts.occlusion);
  if (opts.seed !== DEFAULTS.seed) sp.set('seed', String(opts.seed));
  if (opts.restarts !== DEFAULTS.restarts) sp.set('restarts', String(opts.restarts));
  if (opts.medial_init) sp.set('medial', '1');
  if (opts.key_frames !== undefined && opts.key_frames !== DEFAULTS.key_frames) sp.set('keys', String(opts.key_frames));
  if (opts.parts) sp.set('parts', `${opts.parts[0]}..${opts.parts[1]}`);
  if (genSeed !== opts.seed) sp.set('example_seed', String(genSeed));
  return url;
}
