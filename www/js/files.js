// Gathering what the user dropped or picked: frame files (from files or a folder,
// folders read recursively through webkitGetAsEntry), an optional gt.json and
// heldout/ clouds beside them, or a result JSON to open directly.

/** @typedef {{file: File, path: string}} Entry */

function readAllEntries(reader) {
  // readEntries returns results in batches; keep calling until it returns none.
  return new Promise((resolve, reject) => {
    const all = [];
    const next = () => reader.readEntries((batch) => {
      if (!batch.length) resolve(all);
      else { all.push(...batch); next(); }
    }, reject);
    next();
  });
}

async function walk(entry, prefix, out) {
  if (entry.isFile) {
    const file = await new Promise((resolve, reject) => entry.file(resolve, reject));
    out.push({ file, path: prefix + entry.name });
  } else if (entry.isDirectory) {
    const children = await readAllEntries(entry.createReader());
    for (const c of children) await walk(c, `${prefix}${entry.name}/`, out);
  }
}

/** Entries of a drop (files and folders). Must be called synchronously in the drop handler. */
export function entriesFromDrop(dataTransfer) {
  const items = [...(dataTransfer.items || [])];
  const roots = items.map((it) => (it.kind === 'file' && it.webkitGetAsEntry ? it.webkitGetAsEntry() : null));
  const plain = [...(dataTransfer.files || [])];
  return (async () => {
    const out = [];
    if (roots.length && roots.every(Boolean)) {
      for (const r of roots) await walk(r, '', out);
    } else {
      for (const f of plain) out.push({ file: f, path: f.name });
    }
    return out;
  })();
}

/** Entries of an <input type=file> (multiple files, or a folder with webkitdirectory). */
export function entriesFromInput(input) {
  return [...input.files].map((f) => ({ file: f, path: f.webkitRelativePath || f.name }));
}

/** The extensions read as frames, in the order a folder's formats are preferred. */
export const FRAME_EXTENSIONS = ['ply', 'pcd', 'npy', 'npz', 'obj', 'xyz', 'pts', 'csv', 'txt'];

const dirOf = (p) => (p.includes('/') ? p.slice(0, p.lastIndexOf('/')) : '');
const baseOf = (p) => p.slice(p.lastIndexOf('/') + 1);
const isHidden = (p) => p.split('/').some((s) => s.startsWith('.') || s === '__MACOSX');

/**
 * Sorts a drop into what it means. Returns one of
 *   {kind: 'result', entry}
 *   {kind: 'sequence', frames: Entry[], gt: Entry|null, heldout: Entry[], folder, note}
 *   {kind: 'empty', message}
 * Explicitly chosen files of any kind (a zip) are kept as frames so the core names
 * the problem beside them; inside folders the frames are the files of the first
 * format of FRAME_EXTENSIONS the folder has (the core's rule,
 * `io::cloud_file::FRAME_EXTENSIONS`), so notes beside PLY frames are no frames.
 */
export function classify(entries) {
  entries = entries.filter((e) => !isHidden(e.path));
  const jsons = entries.filter((e) => /\.json$/i.test(e.path));
  const others = entries.filter((e) => !/\.json$/i.test(e.path));
  const fromFolder = entries.some((e) => e.path.includes('/'));

  if (!others.length && jsons.length) {
    const gt = jsons.find((e) => baseOf(e.path).toLowerCase() === 'gt.json');
    const res = jsons.find((e) => e !== gt);
    if (res) return { kind: 'result', entry: res };
    return { kind: 'empty', message: 'gt.json alone is not a sequence: drop it together with the frames.' };
  }

  let candidates = others;
  if (fromFolder) {
    const ext = (e) => (/\.([^./]+)$/.exec(e.path)?.[1] ?? '').toLowerCase();
    const first = FRAME_EXTENSIONS.find((x) => others.some((e) => ext(e) === x));
    candidates = first ? others.filter((e) => ext(e) === first) : [];
  }
  if (!candidates.length) {
    return { kind: 'empty', message: fromFolder ? `No frame files (.${FRAME_EXTENSIONS.join(', .')}) in that folder.` : 'Nothing to load.' };
  }
  // Frames are the frame files of the shallowest folder (not a heldout/ folder).
  const dirs = new Map();
  for (const e of candidates) {
    const d = dirOf(e.path);
    if (baseOf(d) === 'heldout') continue;
    if (!dirs.has(d)) dirs.set(d, []);
    dirs.get(d).push(e);
  }
  if (!dirs.size) return { kind: 'empty', message: 'Only held-out clouds found; drop the sequence folder itself.' };
  const depth = (d) => (d === '' ? 0 : d.split('/').length);
  const minDepth = Math.min(...[...dirs.keys()].map(depth));
  const top = [...dirs.keys()].filter((d) => depth(d) === minDepth);
  let note = '';
  if (top.length > 1) {
    note = `Several folders hold frame files (${top.slice(0, 4).join(', ')}${top.length > 4 ? ', …' : ''}); loaded “${top[0]}”. Drop one sequence folder at a time.`;
  }
  const folder = top[0];
  const frames = dirs.get(folder);
  const inFolder = (e, d) => dirOf(e.path) === d;
  const gt = jsons.find((e) => inFolder(e, folder) && baseOf(e.path).toLowerCase() === 'gt.json') || null;
  const heldDir = folder ? `${folder}/heldout` : 'heldout';
  const heldout = candidates.filter((e) => inFolder(e, heldDir));
  return { kind: 'sequence', frames, gt, heldout, folder, note };
}

export const basename = baseOf;
