// The 3D view: wraps the wasm `Viewer` (wgpu: WebGPU when the browser has it,
// WebGL2 otherwise), forwards pointer/wheel input, renders on demand (one
// requestAnimationFrame per change), and keeps the camera in the URL hash.

export class View {
  /** @returns {Promise<View>} */
  static async create(canvas, wasm, { forceWebgl = false } = {}) {
    if (typeof wasm.Viewer !== 'function') throw new Error('this build has no 3D viewer');
    const v = new View(canvas, wasm);
    v.viewer = await wasm.Viewer.create(canvas, forceWebgl);
    v.backend = v.viewer.backend();
    v.attach();
    v.resize();
    return v;
  }

  constructor(canvas, wasm) {
    this.canvas = canvas;
    this.wasm = wasm;
    this.dirty = false;
    this.onCamera = null; // called (debounced) after the user moves the camera
    this.hasContent = false;
  }

  attach() {
    const c = this.canvas;
    const pos = (e) => {
      const r = c.getBoundingClientRect();
      return [e.clientX - r.left, e.clientY - r.top];
    };
    c.addEventListener('pointerdown', (e) => {
      c.setPointerCapture(e.pointerId);
      const [x, y] = pos(e);
      this.viewer.pointer_down(e.pointerId, x, y, e.button, e.shiftKey || e.ctrlKey || e.metaKey);
      c.focus({ preventScroll: true });
    });
    c.addEventListener('pointermove', (e) => {
      const [x, y] = pos(e);
      if (this.viewer.pointer_move(e.pointerId, x, y)) { this.request(); this.cameraMoved(); }
    });
    c.addEventListener('pointerup', (e) => this.viewer.pointer_up(e.pointerId));
    c.addEventListener('pointercancel', () => this.viewer.pointer_cancel());
    c.addEventListener('blur', () => this.viewer.pointer_cancel());
    c.addEventListener('contextmenu', (e) => e.preventDefault());
    c.addEventListener('wheel', (e) => {
      e.preventDefault();
      // Normalise line/page deltas to pixels.
      const k = e.deltaMode === 1 ? 16 : e.deltaMode === 2 ? 400 : 1;
      this.viewer.wheel(e.deltaY * k);
      this.request();
      this.cameraMoved();
    }, { passive: false });
    new ResizeObserver(() => this.resize()).observe(c);
    window.matchMedia?.(`(resolution: ${window.devicePixelRatio}dppx)`).addEventListener?.('change', () => this.resize());
  }

  resize() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, this.canvas.clientWidth), h = Math.max(1, this.canvas.clientHeight);
    this.viewer.resize(w, h, dpr);
    this.request();
  }

  cameraMoved() {
    clearTimeout(this.camTimer);
    this.camTimer = setTimeout(() => this.onCamera?.(this.viewer.camera_state()), 300);
  }

  request() {
    if (this.dirty) return;
    this.dirty = true;
    requestAnimationFrame(() => {
      this.dirty = false;
      this.renderNow();
    });
  }

  renderNow() {
    try {
      this.viewer.render();
    } catch (e) {
      console.error('render failed', e);
    }
  }

  /** Points coloured by part (labels) or, without labels, plain (before a fit). */
  setPoints(points, labels, { frameBox = false } = {}) {
    const n = points.length / 3;
    this.viewer.set_points(points, labels ?? new Uint32Array(0));
    this.viewer.set_color_mode(labels ? 0 : 2);
    if (frameBox || !this.hasContent) this.viewer.frame_object();
    this.hasContent = n > 0;
    this.request();
  }

  setPointSize(px) { this.viewer.set_point_size(px); this.request(); }

  setGaussians(centers, rotations, scales, parts) {
    this.viewer.set_gaussians(centers, rotations, scales, parts);
    this.request();
  }

  clearGaussians() {
    this.viewer.set_gaussians(new Float32Array(0), new Float32Array(0), new Float32Array(0), new Uint32Array(0));
    this.request();
  }

  setGaussiansVisible(on) { this.viewer.set_gaussians_visible(on); this.request(); }

  setAxes(origins, dirs, kinds, highlight = -1) {
    this.viewer.set_axes(origins, dirs, kinds, highlight);
    this.request();
  }

  clearAxes() { this.setAxes(new Float32Array(0), new Float32Array(0), new Uint32Array(0), -1); }

  resetView() { this.viewer.reset_view(); this.request(); this.cameraMoved(); }
  frameObject() { this.viewer.frame_object(); this.request(); this.cameraMoved(); }
  /** Keyboard camera: orbit by (dx, dy) pixels-equivalent, zoom by a factor. */
  orbit(dx, dy) { this.viewer.orbit(dx, dy); this.request(); this.cameraMoved(); }
  zoom(f) { this.viewer.zoom(f); this.request(); this.cameraMoved(); }
  cameraState() { return this.viewer.camera_state(); }
  setCameraState(s) {
    try { this.viewer.set_camera_state(s); this.request(); return true; } catch { return false; }
  }

  /** PNG of the current view; rendered offscreen so it works on WebGPU and WebGL2 alike. */
  async screenshot() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.round(this.canvas.clientWidth * dpr), h = Math.round(this.canvas.clientHeight * dpr);
    let rgba = null;
    try {
      rgba = await this.viewer.render_offscreen_rgba(w, h);
    } catch (e) {
      console.warn('offscreen render failed, capturing the canvas instead', e);
    }
    if (rgba && rgba.length === w * h * 4) {
      const c = document.createElement('canvas');
      c.width = w; c.height = h;
      c.getContext('2d').putImageData(new ImageData(new Uint8ClampedArray(rgba.buffer, rgba.byteOffset, rgba.length), w, h), 0, 0);
      return await new Promise((res) => c.toBlob(res, 'image/png'));
    }
    // The canvas is only readable in the task that rendered it (WebGPU): render, then capture.
    this.renderNow();
    return await new Promise((res) => this.canvas.toBlob(res, 'image/png'));
  }
}
