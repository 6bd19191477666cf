// Coupled joints (the core's `kinematics::mimic`, URDF `<mimic>`) in the page: the
// bench-dev panda gripper's true segmentation and poses, with Steps 2–3 done on them
// by the CLI (`gsart truth`, then `gsart edit`), give a model whose second finger
// follows the first. Its row says so and its slider moves with the leader's; "Unlink"
// frees it, changing nothing else, and "Undo edit" couples it again. The joint
// motions of play=joints and the video sweep only the leaders (motion.js).
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { execFileSync } from 'node:child_process';
import { startServer, launch, newPage, waitLoaded, benchDev, ROOT, ARTIFACTS } from './helpers.mjs';
import { follow, jointMotion } from '../../www/js/motion.js';

const PANDA = benchDev() && path.join(benchDev(), 'full', 'panda_gripper_00');
// The CLI the native tests built (same core).
const CLI = ['release', 'debug'].map((p) => path.join(ROOT, 'target', p, 'gsart')).find((p) => fs.existsSync(p));

test('a follower moves with its leader in the joint motions', () => {
  const joints = [
    { child: 1, limits: [0, 1] },
    { child: 2, limits: [-1, 0], mimic: { joint: 1, multiplier: -1, offset: 0.1 } },
    { child: 3, limits: [0, 2] },
  ];
  assert.deepEqual(follow(joints, [0, 0.5, 9, 0.3]), [0, 0.5, -0.4, 0.3]);
  const base = [0, 0.5, -0.45, 1];
  const m = jointMotion(joints, base, 'joints');
  assert.equal(m.seconds, 4, 'two sweeps: the follower has none of its own');
  for (const t of [0.3, 0.9, 1.4, 2.5, 3.7]) {
    const { states, moving } = m.at(t);
    assert.notEqual(moving, 2);
    // From its own state on view, by the coupling.
    assert.ok(Math.abs(states[2] - (base[2] - (states[1] - base[1]))) < 1e-12, `t ${t}`);
  }
  assert.ok(Math.abs(m.at(0.5).states[2] - base[2]) > 0.1, 'it moves while its leader does');
  assert.ok(Math.abs(m.at(2.5).states[2] - base[2]) < 1e-12, 'and stays while another joint moves');
});

let srv, browser;
before(async () => { srv = await startServer(); browser = await launch(); });
after(async () => { await browser?.close(); srv?.server.close(); });

test('the gripper\'s second finger follows the first; Unlink frees it, Undo couples it again', { timeout: 300_000 }, async (t) => {
  if (!PANDA || !CLI) { t.skip(!PANDA ? 'bench-dev not present' : 'the gsart CLI is not built'); return; }
  const truth = path.join(ARTIFACTS, 'panda-truth.json');
  const model = path.join(ARTIFACTS, 'panda-mimic.json');
  execFileSync(CLI, ['truth', PANDA, '--out', truth], { stdio: 'ignore' });
  execFileSync(CLI, ['edit', truth, PANDA, '--out', model, '--quiet'], { stdio: 'ignore' });
  const fitted = JSON.parse(fs.readFileSync(model, 'utf8'));
  const follower = fitted.joints.find((j) => j.mimic);
  assert.ok(follower, 'the fingers, whose true states are equal, are coupled');
  const leaderIdx = fitted.joints.findIndex((j) => j.child === follower.mimic.joint);
  const followerIdx = fitted.joints.indexOf(follower);

  const { page, errors, context } = await newPage(browser, { width: 1100, height: 800 });
  await page.goto(`${srv.base}/`);
  await waitLoaded(page);
  const files = fs.readdirSync(PANDA).filter((f) => /^frame_\d+\.ply$/.test(f)).map((f) => path.join(PANDA, f));
  await page.locator('#file-input').setInputFiles(files);
  await page.waitForFunction((n) => document.querySelectorAll('#frame-list li[data-index]').length === n, files.length);
  await page.locator('#file-input').setInputFiles(model);
  await page.waitForFunction(() => window.gsart.state.model?.joints().length === 2);

  const rows = page.locator('.joint');
  const followerRow = rows.nth(followerIdx);
  assert.match(await followerRow.locator('.jdetail').innerText(), new RegExp(`follows joint ${leaderIdx + 1}: -?[\\d.]+ × its state`));
  assert.equal(await followerRow.locator('input[type=range]').isDisabled(), true);
  assert.equal(await rows.nth(leaderIdx).locator('input[type=range]').isDisabled(), false);
  assert.match(await page.locator('#result-summary').innerText(), /follows the joint of part \d+ \(URDF mimic/);

  // The leader's slider moves the follower by the coupling.
  const moved = await page.evaluate(([li, fc]) => {
    const el = document.querySelectorAll('.joint input[type=range]')[li];
    el.value = String((Number(el.min) + Number(el.max)) / 2 + 0.1 * (Number(el.max) - Number(el.min)));
    el.dispatchEvent(new Event('input', { bubbles: true }));
    const s = window.gsart.state.states;
    return { lead: s[window.gsart.state.model.joints()[li].child], follower: s[fc],
      slider: Number(document.querySelectorAll('.joint input[type=range]')[1 - li].value) };
  }, [leaderIdx, follower.child]);
  const want = follower.mimic.multiplier * moved.lead + follower.mimic.offset;
  assert.ok(Math.abs(moved.follower - want) < 1e-9, `${JSON.stringify(moved)} against ${want}`);
  assert.ok(Math.abs(moved.slider - want) < 1e-3 * Math.abs(want) + 1e-4, 'its slider shows it');

  // Unlink: an edit that keeps the finger free of the coupling; undo couples it again.
  const unlink = followerRow.locator('.junlink');
  assert.equal(await page.locator('.joint .junlink').count(), 1, 'only the follower can be unlinked');
  await unlink.click();
  await page.waitForFunction(() => !window.gsart.state.editJob
    && window.gsart.state.model.joints().every((j) => !j.mimic), null, { timeout: 120_000 });
  assert.match(await page.locator('#toast').innerText(), /Joint \d unlinked in [\d.]+ s/);
  const json = await page.evaluate(() => JSON.parse(window.gsart.state.model.to_json(false)));
  assert.deepEqual(json.info.unlinked, [follower.child]);
  // Nothing but the coupling changed (the model is not built again).
  assert.deepEqual(json.joints, fitted.joints.map(({ mimic, ...j }) => j));
  assert.deepEqual(json.labels, fitted.labels);
  assert.deepEqual(json.info.edits.at(-1).unlink, [follower.child]);
  assert.equal(await page.locator('.joint input[type=range]:disabled').count(), 0);
  assert.equal(await page.locator('.joint .junlink').count(), 0);
  await page.locator('#btn-undo-edit').click();
  assert.equal(await page.evaluate(() => window.gsart.state.model.joints().filter((j) => j.mimic).length), 1);
  assert.equal(await page.locator('.joint input[type=range]:disabled').count(), 1);
  assert.deepEqual(errors, []);
  await context.close();
});
