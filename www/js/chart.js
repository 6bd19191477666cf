// Live loss plot on a small 2D canvas: one line per series (a candidate part
// count, or a refinement stage), log-scaled y, x = iteration fraction.

const MIN_MS = 250;
const COLORS = ['#4cc9f0', '#f72585', '#ffc15e', '#52d49b', '#b388ff', '#ff8a5b', '#7ee0ff', '#ff9ecd', '#c3f584'];

export class LossChart {
  constructor(canvas) {
    this.canvas = canvas;
    this.series = new Map(); // key -> {label, points: [[x, y]], color}
    this.title = '';
    this.pending = false;
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  clear(title = '') {
    this.series.clear();
    this.title = title;
    this.draw();
  }

  /** Adds a point; x in [0, 1] (progress), y > 0 (loss). */
  add(key, label, x, y) {
    if (!Number.isFinite(y)) return;
    let s = this.series.get(key);
    if (!s) {
      s = { label, points: [], color: COLORS[this.series.size % COLORS.length] };
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
    for (let i = 0; i <= 3; i++) {
      const v = a + ((b - a) * i) / 3;
      const y = pad.t + ph * (1 - i / 3);
      g.beginPath(); g.moveTo(pad.l, y); g.lineTo(w - pad.r, y); g.stroke();
      const val = useLog ? 10 ** v : v;
      g.fillText(fmt(val), pad.l - 4, y);
    }
    // lines
    for (const s of this.series.values()) {
      g.strokeStyle = s.color;
      g.lineWidth = 1.5;
      g.beginPath();
      s.points.forEach(([x, y], i) => (i ? g.lineTo(xOf(x), yOf(y)) : g.moveTo(xOf(x), yOf(y))));
      g.stroke();
    }
    // legend
    g.textAlign = 'left';
    let lx = pad.l;
    g.fillStyle = '#8d96b5';
    if (this.title) { g.fillText(this.title, lx, 9); lx += g.measureText(this.title).width + 10; }
    for (const s of this.series.values()) {
      if (lx > w - 30) break;
      g.fillStyle = s.color;
      g.fillRect(lx, 6, 8, 6);
      g.fillStyle = '#c5cbe0';
      g.fillText(s.label, lx + 11, 9);
      lx += g.measureText(s.label).width + 20;
    }
  }
}

function fmt(v) {
  if (v === 0) return '0';
  const a = Math.abs(v);
  if (a >= 1000 || a < 0.01) return v.toExponential(0);
  if (a >= 10) return v.toFixed(0);
  if (a >= 1) return v.toFixed(1);
  return v.toFixed(2);
}
