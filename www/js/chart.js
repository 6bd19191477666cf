// Live loss plot on a small 2D canvas: one line per series, log-scaled y, x =
// iteration fraction. Series of one group (a candidate part count's Chamfer phase and
// its EMD phase) share a colour and one legend entry; a dashed series is drawn dashed,
// and the legend says what dashes stand for.

const MIN_MS = 250;
const COLORS = ['#4cc9f0', '#f72585', '#ffc15e', '#52d49b', '#b388ff', '#ff8a5b', '#7ee0ff', '#ff9ecd', '#c3f584'];

export class LossChart {
  constructor(canvas) {
    this.canvas = canvas;
    this.series = new Map(); // key -> {label, points: [[x, y]], color, group, dashed}
    this.colors = new Map(); // group -> colour
    this.title = '';
    this.dashNote = '';
    this.pending = false;
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  /** Empties the chart; `dashNote` names what a dashed line stands for in the legend. */
  clear(title = '', dashNote = '') {
    this.series.clear();
    this.colors.clear();
    this.title = title;
    this.dashNote = dashNote;
    this.draw();
  }

  /**
   * Adds a point; x in [0, 1] (progress), y > 0 (loss). `group` (default: the key)
   * picks the colour and the legend entry; `dashed` draws the series dashed.
   */
  add(key, label, x, y, { group = key, dashed = false } = {}) {
    if (!Number.isFinite(y)) return;
    let s = this.series.get(key);
    if (!s) {
      if (!this.colors.has(group)) this.colors.set(group, COLORS[this.colors.size % COLORS.length]);
      s = { label, points: [], color: this.colors.get(group), group, dashed };
      this.series.set(key, s);
    }
    s.points.push([x, y]);
    if (s.points.length > 2000) s.points = s.points.filter((_, i) => i % 2 === 0);
    this.schedule();
  }

  // At most one redraw per MIN_MS: points arrive up to 40 times a second, and each
  // repaint takes CPU from the workers fitting on the same cores.
  schedule() {
    if (this.pending) return;
    this.pending = true;
    setTimeout(() => requestAnimationFrame(() => { this.pending = false; this.draw(); }), MIN_MS);
  }

  draw() {
    const c = this.canvas;
    const dpr = window.devicePixelRatio || 1;
    const w = c.clientWidth, h = c.clientHeight;
    if (!w || !h) return;
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
      c.width = Math.round(w * dpr);
      c.height = Math.round(h * dpr);
    }
    const g = c.getContext('2d');
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, w, h);
    const pad = { l: 40, r: 8, t: 18, b: 16 };
    const pw = w - pad.l - pad.r, ph = h - pad.t - pad.b;
    g.font = '10px system-ui, sans-serif';
    g.fillStyle = '#8d96b5';
    g.textBaseline = 'middle';
    let lo = Infinity, hi = -Infinity;
    for (const s of this.series.values()) {
      for (const [, y] of s.points) {
        if (y > 0) { lo = Math.min(lo, y); hi = Math.max(hi, y); }
      }
    }
    if (!(lo < Infinity)) {
      g.textAlign = 'center';
      g.fillText(this.title ? `${this.title}: waiting for the first iterations…` : 'loss curve', w / 2, h / 2);
      return;
    }
    const useLog = hi / lo > 20;
    const tf = (y) => (useLog ? Math.log10(Math.max(y, 1e-12)) : y);
    let a = tf(lo), b = tf(hi);
    if (b - a < 1e-9) { a -= 0.5; b += 0.5; }
    const yOf = (y) => pad.t + ph * (1 - (tf(y) - a) / (b - a));
    const xOf = (x) => pad.l + pw * Math.min(1, Math.max(0, x));
    // grid + labels
    g.strokeStyle = '#232a45';
    g.lineWidth = 1;
    g.textAlign = 'right';
    const ticks = [0, 1, 2, 3].map((i) => {
      const v = a + ((b - a) * i) / 3;
      return useLog ? 10 ** v : v;
    });
    const labels = tickLabels(ticks);
    ticks.forEach((_, i) => {
      const y = pad.t + ph * (1 - i / 3);
      g.beginPath(); g.moveTo(pad.l, y); g.lineTo(w - pad.r, y); g.stroke();
      g.fillText(labels[i], pad.l - 4, y);
    });
    // lines
    for (const s of this.series.values()) {
      g.strokeStyle = s.color;
      g.lineWidth = 1.5;
      g.setLineDash(s.dashed ? [4, 3] : []);
      g.beginPath();
      s.points.forEach(([x, y], i) => (i ? g.lineTo(xOf(x), yOf(y)) : g.moveTo(xOf(x), yOf(y))));
      g.stroke();
    }
    g.setLineDash([]);
    // legend: one entry per group, then what the dashes stand for
    g.textAlign = 'left';
    let lx = pad.l;
    g.fillStyle = '#8d96b5';
    if (this.title) { g.fillText(this.title, lx, 9); lx += g.measureText(this.title).width + 10; }
    const entries = [];
    const seen = new Set();
    for (const s of this.series.values()) {
      if (!seen.has(s.group)) { seen.add(s.group); entries.push(s); }
    }
    // The dashes' note sits at the right end; the groups' entries stop short of it.
    const note = this.dashNote && [...this.series.values()].some((s) => s.dashed) ? this.dashNote : '';
    const noteW = note ? g.measureText(note).width + 24 : 0;
    if (note) {
      const nx = Math.max(lx, w - pad.r - noteW);
      g.strokeStyle = '#c5cbe0';
      g.setLineDash([4, 3]);
      g.beginPath(); g.moveTo(nx, 9); g.lineTo(nx + 14, 9); g.stroke();
      g.setLineDash([]);
      g.fillStyle = '#c5cbe0';
      g.fillText(note, nx + 18, 9);
    }
    for (const s of entries) {
      if (lx + 11 + g.measureText(s.label).width > w - pad.r - noteW) break;
      g.fillStyle = s.color;
      g.fillRect(lx, 6, 8, 6);
      g.fillStyle = '#c5cbe0';
      g.fillText(s.label, lx + 11, 9);
      lx += g.measureText(s.label).width + 20;
    }
  }
}

/** Labels for the axis ticks `vs`, with just enough digits that no two read the same. */
export function tickLabels(vs) {
  let labels = vs.map((v) => fmt(v, 0));
  for (let extra = 1; extra <= 3 && new Set(labels).size < labels.length; extra++) {
    labels = vs.map((v) => fmt(v, extra));
  }
  return labels;
}

function fmt(v, extra) {
  if (v === 0) return '0';
  const a = Math.abs(v);
  if (a >= 1000 || a < 0.01) return v.toExponential(extra);
  if (a >= 10) return v.toFixed(extra);
  if (a >= 1) return v.toFixed(1 + extra);
  return v.toFixed(2 + extra);
}
