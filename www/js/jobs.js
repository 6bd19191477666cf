// Workers: a helper to run one job in a fresh module worker, and the fit job that
// runs one worker per candidate part count (at most hardwareConcurrency at a
// time, the rest queued), then one worker for selection + Steps 2–3 + metrics.
// Cancelling terminates the workers; the page's own data is never handed over
// (workers get copies), so a cancelled or failed job leaves everything loaded.

const WORKER_URL = new URL('../worker.js', import.meta.url);
let nextId = 1;

/**
 * A module worker that runs jobs one after another (a Step-1 candidate stays in its
 * wasm memory, so the worker holding the best one goes on with Steps 2–3).
 */
export class Lane {
  constructor() {
    this.worker = new Worker(WORKER_URL, { type: 'module' });
    this.current = null; // {id, resolve, reject, onMessage}
    this.dead = false;
    this.worker.onmessage = (ev) => {
      const m = ev.data;
      const cur = this.current;
      if (!cur || m.id !== cur.id) return;
      if (m.type === 'result') { this.current = null; cur.resolve(m); }
      else if (m.type === 'error') { this.current = null; cur.reject(new Error(m.message)); }
      else cur.onMessage(m);
    };
    this.worker.onerror = (ev) => {
      ev.preventDefault?.();
      this.fail(new Error(ev.message || 'the worker failed to start (is www/pkg built?)'));
    };
    this.worker.onmessageerror = () => this.fail(new Error('a worker message could not be read'));
  }

  run(msg, transfer = [], onMessage = () => {}) {
    if (this.dead) return Promise.reject(new CancelledError());
    if (this.current) return Promise.reject(new Error('internal: the worker is busy'));
    const id = nextId++;
    return new Promise((resolve, reject) => {
      this.current = { id, resolve, reject, onMessage };
      this.worker.postMessage({ id, ...msg }, transfer);
    });
  }

  fail(err) {
    const cur = this.current;
    this.current = null;
    this.terminate();
    cur?.reject(err);
  }

  terminate() {
    if (!this.dead) { this.dead = true; this.worker.terminate(); }
  }

  cancel() { this.fail(new CancelledError()); }
}

/** Runs one message in a fresh worker; resolves with the 'result' message. */
export class WorkerJob {
  constructor(msg, transfer = [], onMessage = () => {}) {
    this.lane = new Lane();
    this.promise = this.lane.run(msg, transfer, onMessage).finally(() => this.lane.terminate());
  }
  cancel() { this.lane.cancel(); }
}

export class CancelledError extends Error {
  constructor() { super('cancelled'); this.name = 'CancelledError'; }
}

function copies(frames) {
  const arrays = frames.map((f) => f.slice());
  return { arrays, transfer: arrays.map((a) => a.buffer) };
}

// One worker per core: the main thread only draws and relays progress, so it does not
// need a core of its own (finger_edu fast on 2 cores: one worker 44.4 s, two: see docs/DEVELOPMENT.md).
export function maxParallel() {
  const hc = navigator.hardwareConcurrency || 2;
  return Math.max(1, Math.min(hc, 8));
}

/**
 * Runs a whole fit. Callbacks:
 *   onCandidateStart(m), onWorking(m, frames), onCandidateProgress(m, msg),
 *   onCandidateDone(m, {loss, ms}), onExtraCandidate(m, done), onFinishProgress(msg)
 * `extraCandidate(ms, losses, occluded)`: one more m to fit after the first ones, or null.
 * Resolves with {result, metrics, metricsError, candidates: [{m, loss, ms}], best, finishMs,
 * movedRunner} (`best`: the kept candidate, the runner-up when the second look took it;
 * `finishMs`: Steps 2–3's wall time; `movedRunner`: whether the runner-up was copied to
 * another worker to finish beside the best).
 */
export class FitJob {
  constructor({ frames, names, options, parts, gt, labels, bestOf, extraCandidate, secondLook, callbacks }) {
    this.frames = frames;
    this.names = names;
    this.options = options;
    this.ms = [...parts];
    this.gt = gt;
    this.labels = labels;
    this.bestOf = bestOf;
    this.extraCandidate = extraCandidate;
    this.secondLook = secondLook;
    this.cb = callbacks;
    this.lanes = [];
    this.cancelled = false;
    this.parallel = Math.min(maxParallel(), this.ms.length);
  }

  async run() {
    const queue = [...this.ms];
    const done = [];
    const owner = new Map(); // m -> lane holding its candidate
    let occluded = false;
    const runLane = async (lane) => {
      while (queue.length && !this.cancelled) {
        const m = queue.shift();
        const { arrays, transfer } = copies(this.frames);
        this.cb.onCandidateStart?.(m);
        const r = await lane.run(
          { type: 'start', frames: arrays, names: this.names, m, options: this.options },
          transfer,
          (msg) => {
            if (msg.type === 'progress') this.cb.onCandidateProgress?.(m, msg);
            else if (msg.type === 'working') this.cb.onWorking?.(m, msg.frames);
          },
        );
        done.push({ m, loss: r.loss, ms: r.ms });
        occluded = occluded || r.occlusionUsed;
        owner.set(m, lane);
        this.cb.onCandidateDone?.(m, { loss: r.loss, ms: r.ms });
      }
    };
    for (let i = 0; i < this.parallel; i++) this.lanes.push(new Lane());
    try {
      await Promise.all(this.lanes.map(runLane));
      if (this.cancelled) throw new CancelledError();
      done.sort((a, b) => a.m - b.m);
      // The core may want one more part count now that these finished (fast, full
      // input: the top of the default range failed; `fit::select::extra_candidate`).
      const extra = this.extraCandidate?.(done.map((c) => c.m), done.map((c) => c.loss), occluded) ?? null;
      if (extra !== null && !done.some((c) => c.m === extra)) {
        this.cb.onExtraCandidate?.(extra, done);
        queue.push(extra);
        // Beyond the range asked for, a fit that fails leaves the range's candidates (as
        // natively); a cancel still cancels.
        await runLane(this.lanes[0]).catch((e) => {
          if (e instanceof CancelledError || this.cancelled) throw e;
          console.warn(`m = ${extra}:`, e);
        });
        if (this.cancelled) throw new CancelledError();
        done.sort((a, b) => a.m - b.m);
      }
      const best = this.bestOf(done.map((c) => c.m), done.map((c) => c.loss));
      // The runner-up gets its own Steps 2–3 too (full input; the core's second look,
      // `pipeline::second_look`, keeps it when the best leaves clearly more of the
      // clouds unexplained). Both finish at once when two workers hold them.
      const rest = done.filter((c) => c.m !== best);
      const runner = rest.length > 0 && !occluded
        ? this.bestOf(rest.map((c) => c.m), rest.map((c) => c.loss)) : null;
      // When one worker holds both, the runner-up is copied to another worker so the two
      // finishes run side by side, as natively (`fit::candidate_bytes`).
      const spare = runner !== null && owner.get(runner) === owner.get(best)
        ? this.lanes.find((l) => l !== owner.get(best) && !l.dead) ?? null : null;
      const keep = new Set([owner.get(best), runner === null ? null : owner.get(runner), spare]);
      const t0 = performance.now();
      for (const l of this.lanes) if (!keep.has(l)) l.terminate();
      let movedRunner = false;
      if (spare) {
        try {
          const { bytes } = await owner.get(runner).run({ type: 'copy', m: runner });
          await spare.run({ type: 'put', bytes }, [bytes.buffer]);
          owner.set(runner, spare);
          movedRunner = true;
        } catch (e) {
          // The runner-up then finishes after the best, in the worker that fitted it.
          if (e instanceof CancelledError || this.cancelled) throw e;
          console.warn('copying the runner-up to the other worker:', e);
          spare.terminate();
        }
      }
      const finishOn = (m, report) => {
        const { arrays, transfer } = copies(this.frames);
        return owner.get(m).run(
          {
            type: 'finish', m, frames: arrays, names: this.names, options: this.options,
            candidates: done.map((c) => [c.m, c.loss]), gt: this.gt ?? null, labels: this.gt ? this.labels : null,
          },
          transfer,
          (msg) => { if (report && msg.type === 'progress') this.cb.onFinishProgress?.(msg); },
        );
      };
      let r;
      let kept = best;
      if (runner === null) {
        r = await finishOn(best, true);
      } else {
        // The runner-up failing leaves the best as it is (a cancel still cancels).
        const second = () => finishOn(runner, false).catch((e) => {
          if (e instanceof CancelledError || this.cancelled) throw e;
          return null;
        });
        const [a, b] = owner.get(best) === owner.get(runner)
          ? [await finishOn(best, true), await second()]
          : await Promise.all([finishOn(best, true), second()]);
        const look = b ? this.secondLook(a.result, b.result) : { runner: false, result: a.result };
        if (look.runner) kept = runner;
        r = { ...(look.runner ? b : a), result: look.result };
      }
      return {
        result: r.result, metrics: r.metrics, metricsError: r.metricsError,
        candidates: done, best: kept, finishMs: performance.now() - t0, movedRunner,
      };
    } finally {
      for (const l of this.lanes) l.terminate();
    }
  }

  cancel() {
    this.cancelled = true;
    for (const l of this.lanes) l.cancel();
  }
}
