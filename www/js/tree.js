// The kinematic tree as an SVG diagram: nodes in part colours, edges labelled
// with the joint type (R revolute, P prismatic). Layered top-down layout.

const NS = 'http://www.w3.org/2000/svg';

function el(name, attrs = {}, parent) {
  const e = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

/**
 * @param {HTMLElement} container
 * @param {{parent: number[], root: number, colors: string[], jointOf: (part) => {type}|null,
 *          onHover?: (part|null) => void, onClick?: (part) => void}} opts
 */
export function drawTree(container, { parent, root, colors, jointOf, onHover, onClick }) {
  container.replaceChildren();
  const n = parent.length;
  const children = Array.from({ length: n }, () => []);
  for (let p = 0; p < n; p++) if (parent[p] >= 0 && parent[p] < n) children[parent[p]].push(p);
  // Tidy layout: leaves get consecutive x slots, parents centre over their children.
  const x = new Array(n).fill(0), depth = new Array(n).fill(0);
  let slot = 0, maxDepth = 0;
  const seen = new Set();
  const place = (p, d) => {
    if (seen.has(p)) return;
    seen.add(p);
    depth[p] = d; maxDepth = Math.max(maxDepth, d);
    const ch = children[p].filter((c) => !seen.has(c));
    if (!ch.length) { x[p] = slot++; return; }
    for (const c of ch) place(c, d + 1);
    x[p] = (x[ch[0]] + x[ch[ch.length - 1]]) / 2;
  };
  place(root, 0);
  for (let p = 0; p < n; p++) if (!seen.has(p)) place(p, 0); // disconnected parts, if any
  const dx = 38, dy = 46, r = 12, m = 18;
  const width = Math.max(slot, 1) * dx + 2 * m - (dx - 2 * r);
  const height = maxDepth * dy + 2 * m + 2;
  const svg = el('svg', { width, height, viewBox: `0 0 ${width} ${height}`, role: 'img',
    'aria-label': `Kinematic tree with ${n} parts, root part ${root}` }, container);
  const px = (p) => m + r - 2 + x[p] * dx;
  const py = (p) => m + depth[p] * dy;
  for (let p = 0; p < n; p++) {
    const q = parent[p];
    if (q < 0 || q >= n) continue;
    const x1 = px(q), y1 = py(q), x2 = px(p), y2 = py(p);
    const ym = (y1 + y2) / 2;
    el('path', { class: 'edge', d: `M${x1},${y1 + r} C${x1},${ym} ${x2},${ym} ${x2},${y2 - r}` }, svg);
    const j = jointOf(p);
    if (j) {
      const t = el('text', { class: 'edge-label', x: (x1 + x2) / 2 + 5, y: ym + 3 }, svg);
      t.textContent = j.type === 'prismatic' ? 'P' : 'R';
    }
  }
  for (let p = 0; p < n; p++) {
    const g = el('g', { class: 'node', 'data-part': p, tabindex: 0, role: 'button',
      'aria-label': `Part ${p}${p === root ? ' (root)' : ''}` }, svg);
    el('circle', { cx: px(p), cy: py(p), r, fill: colors[p % colors.length] }, g);
    const t = el('text', { x: px(p), y: py(p) + 4, 'text-anchor': 'middle' }, g);
    t.textContent = String(p);
    const title = el('title', {}, g);
    title.textContent = p === root ? `part ${p} (root)` : `part ${p}, child of ${parent[p]}`;
    g.addEventListener('mouseenter', () => onHover?.(p));
    g.addEventListener('mouseleave', () => onHover?.(null));
    g.addEventListener('click', () => onClick?.(p));
  }
  return svg;
}
