// Workers: a helper to run one job in a fresh module worker, and the fit job that
// runs one worker per candidate part count (at most hardwareConcurrency − 1 at a
// time, the rest queued), then one worker for selection + Steps 2–3 + metrics.
// Cancelling terminates the workers; the page's own data is never handed over
// (workers get copies), so a cancelled or failed job leaves everything loaded.

const WORKER_URL = new URL('../worker.js', import.meta.url);
let nextId = 1;

/** Runs one message in a worker; resolves with the 'result' message. */
export class WorkerJob {
  constructor(msg, transfer = [], onMessage = () => {}) {
    this.worker = new Worker(WORKER_URL, { type: 'module' });
    this.id = nextId++;
    this.done = false;
    this.promise = new Promise((resolve, reject) => {
      this.reject = reject;
      this.worker.onmessage = (ev) => {
        const m = ev.data;
        if (m.type === 'result') { this.finish(); resolve(m); }
        else if (m.type === 'error') { this.finish(); reject(new Error(m.message)); }
        else onMessage(m);
      };
      this.worker.onerror = (ev) => {
        this.finish();
        reject(new Error(ev.message || 'the worker failed to start (is www/pkg built?)'));
      };
      this.worker.onmessageerror = () => { this.finish(); reject(new Error('a worker message could not be read')); };
    });
    this.worker.postMessage({ id: this.id, ...msg }, transfer);
  }
  finish() {
    if (!this.done) { this.done = true; this.worker.terminate(); }
  }
  cancel() {
    if (!this.done) { this.finish(); this.reject(new CancelledError()); }
  }
}

export class CancelledError extends Error {
  constructor() { super('cancelled'); this.name = 'CancelledError'; }
}

function copies(frames) {
  const arrays = frames.map((f) => f.slice());
  return { arrays, transfer: arrays.map((a) => a.buffer) };
}

export function maxParallel() {
  const hc = navigator.hardwareConcurrency || 2;
  return Math.max(1, hc - 1);
}

/**
 * Runs a whole fit. Callbacks:
 *   onCandidateProgress(m, progressMsg), onWorking(m, frames), onCandidateDone(m, info),
 *   onFinishProgress(progressMsg)
 * Resolves with {result, metrics, metricsError, candidates: [{m, loss, ms}]}.
 */
export class FitJob {
  constructor({ frames, names, options, range, gt, heldout, callbacks }) {
    this.frames = frames;
    this.names = names;
    this.options = options;
    this.ms = [];
    for (let m = range[0]; m <= range[1]; m++) this.ms.push(m);
    this.gt = gt;
    this.heldout = heldout;
    this.cb = callbacks;
    this.jobs = new Set();
    this.cancelled = false;
    this.parallel = Math.min(maxParallel(), this.ms.length);
  }

  async run() {
    const queue = [...this.ms];
    const done = [];
    const runOne = async () => {
      while (queue.length && !this.cancelled) {
        const m = queue.shift();
        const { arrays, transfer } = copies(this.frames);
        const job = new WorkerJob(
          { type: 'start', frames: arrays, names: this.names, m, options: this.options },
          transfer,
          (msg) => {
            if (msg.type === 'progress') this.cb.onCandidateProgress?.(m, msg);
            else if (msg.type === 'working') this.cb.onWorking?.(m, msg.frames);
          },
        );
        this.jobs.add(job);
        this.cb.onCandidateStart?.(m);
        try {
          const r = await job.promise;
          done.push({ m, json: r.candidate, loss: r.loss, ms: r.ms });
          this.cb.onCandidateDone?.(m, { loss: r.loss, ms: r.ms });
        } finally {
          this.jobs.delete(job);
        }
      }
    };
    const lanes = [];
    for (let i = 0; i < this.parallel; i++) lanes.push(runOne());
    try {
      await Promise.all(lanes);
    } catch (e) {
      this.cancel();
      throw e;
    }
    if (this.cancelled) throw new CancelledError();
    done.sort((a, b) => a.m - b.m);

    const { arrays, transfer } = copies(this.frames);
    const heldout = this.heldout
      ? { frames: this.heldout.frames.map((f) => f.slice()), names: this.heldout.names }
      : null;
    const job = new WorkerJob(
      {
        type: 'finish', frames: arrays, names: this.names, options: this.options,
        candidates: done.map((c) => c.json), gt: this.gt ?? null, heldout,
      },
      transfer,
      (msg) => { if (msg.type === 'progress') this.cb.onFinishProgress?.(msg); },
    );
    this.jobs.add(job);
    try {
      const r = await job.promise;
      return {
        result: r.result, metrics: r.metrics, metricsError: r.metricsError,
        candidates: done.map(({ m, loss, ms }) => ({ m, loss, ms })), finishMs: r.ms,
      };
    } finally {
      this.jobs.delete(job);
    }
  }

  cancel() {
    this.cancelled = true;
    for (const j of this.jobs) j.cancel();
    this.jobs.clear();
  }
}
