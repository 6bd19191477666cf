// Module worker running one job of the core (wasm): parsing PLY files, generating a
// built-in example, one Step-1 candidate (one part count m), finishing (model
// selection + Steps 2–3 + metrics), or a model edited by hand (Steps 2–3 again +
// metrics). Results go back as transferable typed arrays.
//
// Messages in:  {id, type: 'parse', files: [{name, bytes: ArrayBuffer}]}
//               {id, type: 'example', name, seed}
//               {id, type: 'start', frames: [Float32Array], names, m, options}  (keeps the candidate)
//               {id, type: 'finish', m, frames, names, options, gt?, labels?}  (Steps 2–3 on candidate m)
//               {id, type: 'copy', m}     (candidate m as bytes, for another worker; kept here too)
//               {id, type: 'put', bytes}  (a candidate another worker copied, to finish here)
//               {id, type: 'edit', frames, names, result, edit, gt?, labels?}  (edited by hand, Steps 2–3 again)
//               {id, type: 'extend', frames, names, keys, result, options, gt?, labels?}  (a result fitted
//                 on the key frames `keys` of a long sequence, the other frames tracked with its model)
// Messages out: {id, type: 'progress', ...} (≤ ~20/s), {id, type: 'result', ...}, {id, type: 'error', message}
// Cancel: the page terminates the worker (a running wasm loop cannot read messages).
import init, * as gsart from './pkg/gsart.js';

const ready = init();

function buffersOf(list) {
  const out = [];
  for (const a of list) if (a && a.buffer instanceof ArrayBuffer && !out.includes(a.buffer)) out.push(a.buffer);
  return out;
}

function errorMessage(e) {
  if (e instanceof Error) return e.message;
  return String(e);
}

function postProgress(id, p) {
  const msg = { id, type: 'progress', ...p };
  const transfer = p.snapshot ? buffersOf(Object.values(p.snapshot)) : [];
  self.postMessage(msg, transfer);
}

async function handle(msg) {
  await ready;
  const { id } = msg;
  switch (msg.type) {
    case 'parse': {
      // One entry per frame (natural order; a NumPy stack gives several) and one per bad
      // file, so one bad file never hides the others.
      const out = gsart.parse_frames(msg.files.map((f) => f.name), msg.files.map((f) => new Uint8Array(f.bytes)));
      for (const r of out) {
        if (r.error) self.postMessage({ id, type: 'parsed', name: r.name, error: r.error });
        else self.postMessage({ id, type: 'parsed', name: r.name, points: r.points, labels: r.labels ?? null },
          buffersOf([r.points, r.labels]));
      }
      self.postMessage({ id, type: 'result' });
      break;
    }
    case 'example': {
      const ex = gsart.generate_example(msg.name, BigInt(msg.seed ?? 0));
      const arrays = [];
      for (const f of ex.frames) arrays.push(f.points, f.labels);
      self.postMessage({ id, type: 'result', example: ex }, buffersOf(arrays));
      break;
    }
    case 'start': {
      const working = gsart.working_clouds(msg.frames, msg.names, msg.options);
      self.postMessage({ id, type: 'working', m: msg.m, frames: working }, buffersOf(working));
      const t0 = performance.now();
      const c = gsart.fit_candidate(msg.frames, msg.names, msg.m, msg.options,
        (p) => postProgress(id, { m: msg.m, ...p }));
      self.postMessage({ id, type: 'result', m: msg.m, loss: c.loss, iterations: c.iterations,
        occlusionUsed: c.occlusion_used, ms: performance.now() - t0 });
      break;
    }
    case 'copy': {
      const bytes = gsart.candidate_bytes(msg.m);
      self.postMessage({ id, type: 'result', bytes }, [bytes.buffer]);
      break;
    }
    case 'put': {
      const m = gsart.put_candidate(msg.bytes);
      self.postMessage({ id, type: 'result', m });
      break;
    }
    case 'finish':
    case 'edit':
    case 'extend': {
      const t0 = performance.now();
      const progress = (p) => postProgress(id, p);
      const result = msg.type === 'finish'
        // Steps 2–3 on a candidate this worker holds (fitted here, or copied here by 'put').
        ? gsart.finish(msg.frames, msg.names, msg.m, msg.candidates, progress)
        : msg.type === 'edit'
          // A result edited by hand (parts joined, joint types chosen), then Steps 2–3 again.
          ? gsart.edit_model(msg.frames, msg.names, msg.result, msg.edit, progress)
          // A result fitted on key frames, the other frames tracked with its model.
          : gsart.extend_key_frames(msg.frames, msg.names, Uint32Array.from(msg.keys), msg.result,
            msg.options, progress);
      let metrics = null;
      let metricsError = null;
      if (msg.gt) {
        postProgress(id, { stage: 'metrics', iter: 0, total: 1, losses: {} });
        try {
          metrics = gsart.evaluate(result, msg.frames, msg.labels, msg.gt);
        } catch (e) {
          metricsError = errorMessage(e);
        }
        postProgress(id, { stage: 'metrics', iter: 1, total: 1, losses: {} });
      }
      self.postMessage({ id, type: 'result', result, metrics, metricsError, ms: performance.now() - t0 });
      break;
    }
    default:
      throw new Error(`unknown message type ${msg.type}`);
  }
}

self.onmessage = (ev) => {
  handle(ev.data).catch((e) => {
    self.postMessage({ id: ev.data?.id, type: 'error', message: errorMessage(e) });
  });
};
