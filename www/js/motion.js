// Joint motions that show a model's articulation: every joint swept through its fitted
// range, one at a time or all together, starting and ending at the pose on view. The
// video export records them (video.js) and `play=joints` / `play=together` plays them
// live (app.js).

/** Seconds a joint takes in "each joint in turn", and one cycle of "all joints together". */
export const JOINT_S = 2, TOGETHER_S = 4;

/**
 * A joint's state along its sweep: `q(u)` for u ∈ [0, 1] starts and ends at `start` and
 * reaches both limits, as a sine about the range's middle phased to pass through `start`.
 */
export function sweep(start, [lo, hi]) {
  const mid = (lo + hi) / 2, amp = (hi - lo) / 2;
  if (!(amp > 0)) return () => start;
  const phase = Math.asin(Math.max(-1, Math.min(1, (start - mid) / amp)));
  // Outside the range, the sweep first comes back into it.
  const off = start - (mid + amp * Math.sin(phase));
  return (u) => mid + amp * Math.sin(2 * Math.PI * u + phase) + off * (1 - Math.sin(Math.PI * u));
}

/**
 * Every coupled joint's state (`mimic`: `{joint, multiplier, offset}`, the URDF's) set
 * from its leader's, as the URDF moves it. `states` is indexed by child part; returned.
 */
export function follow(joints, states) {
  for (const j of joints) {
    if (j.mimic) states[j.child] = j.mimic.multiplier * states[j.mimic.joint] + j.mimic.offset;
  }
  return states;
}

/**
 * The motion of `joints` (the model's, each `{child, limits}`, and `mimic` when it
 * follows another joint) from the states `base`
 * (indexed by child part): `mode` 'joints' sweeps each in turn, 'together' all at once.
 * `seconds` is one loop; `at(t)` gives the states t seconds in (wrapping) and `moving`,
 * the child part of the joint that moves alone (-1 when all do).
 */
export function jointMotion(joints, base, mode) {
  // A joint that follows another (`mimic`) moves with its leader, by the coupling, from
  // its own state on view; it has no sweep of its own.
  const followers = joints.filter((j) => j.mimic);
  const paths = joints.filter((j) => !j.mimic).map((j) => ({ child: j.child, q: sweep(base[j.child], j.limits) }));
  const per = mode === 'joints' ? JOINT_S : TOGETHER_S;
  const seconds = mode === 'joints' ? per * paths.length : per;
  const at = (t) => {
    const cycle = (((t % seconds) + seconds) % seconds) / per;
    const n = mode === 'joints' ? Math.min(paths.length - 1, Math.floor(cycle)) : -1;
    const u = cycle - Math.floor(cycle);
    const states = base.slice();
    paths.forEach((p, i) => { if (n < 0 || i === n) states[p.child] = p.q(u); });
    for (const f of followers) {
      const lead = f.mimic.joint;
      states[f.child] = base[f.child] + f.mimic.multiplier * (states[lead] - base[lead]);
    }
    return { states, moving: n < 0 ? -1 : paths[n].child };
  };
  return { seconds, at };
}
