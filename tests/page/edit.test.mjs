// Editing a model by hand (www/js/app.js `editModel`, the core's `edit_model`): the
// fitted laptop's hinge joined away in a worker gives one part and no joint, with the
// metrics against the example's ground truth; "Undo edit" puts the fitted model back
// exactly; "Make prismatic" makes the hinge a slide; the lid made the root turns the
// hinge round; a join can be cancelled; an edited model is not shared as the example's
// fit; a model whose frames are not loaded offers no edit.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { startServer, launch, newPage, waitLoaded } from './helpers.mjs';

let srv, browser, page, errors, context;
before(async () => {
  srv = await startServer();
  browser = await launch();
  ({ page, errors, context } = await newPage(browser, { width: 1100, height: 800 }));
  await page.goto(`${srv.base}/?example=laptop&fit=1&quality=fast&parts=2..4`);
  await waitLoaded(page);
  await page.waitForFunction(() => /Done in/.test(document.querySelector('#fit-status').innerText), null, { timeout: 300_000 });
});
after(async () => { await context?.close(); await browser?.close(); srv?.server.close(); });

/** Parts, joints, TED and the canonical frame's labels of the model on view. */
function modelState() {
  return page.evaluate(() => {
    const s = window.gsart.state;
    const c = s.model.canonical_frame();
    return {
      parts: s.model.parts(),
      joints: s.model.joints().length,
      ted: s.metrics?.tree_edit_distance ?? null,
      labels: Array.from(s.model.labels(c)),
      source: s.modelSource,
      json: JSON.parse(s.model.to_json(false)),
    };
  });
}

test('joining the hinge leaves one part; undo puts the fit back', { timeout: 300_000 }, async () => {
  const fitted = await modelState();
  assert.equal(fitted.joints, 1);
  assert.equal(fitted.ted, 0, 'the example has ground truth, so the fit has metrics');
  assert.equal(await page.locator('#btn-undo-edit').isVisible(), false);
  const join = page.locator('.joint .jjoin');
  assert.equal(await join.count(), 1);
  await join.click();
  await page.waitForFunction(() => window.gsart.state.model?.joints().length === 0 && !window.gsart.state.editJob,
    null, { timeout: 120_000 });
  const joined = await modelState();
  assert.equal(joined.parts, 1);
  assert.ok(joined.labels.every((l) => l === 0), 'every point is in the one part');
  assert.equal(joined.ted, 1, 'the metrics follow the edit: one joint of the truth is missing');
  assert.equal(joined.json.info.edits.length, 1);
  assert.deepEqual(joined.json.info.edits[0].join, [[fitted.json.joints[0].parent, fitted.json.joints[0].child]]);
  assert.match(await page.locator('#result-summary').innerText(), /edited by hand: parts \d \+ \d of the previous model joined/);
  assert.match(await page.locator('#toast').innerText(), /joined in [\d.]+ s: 2 → 1 parts, 0 joints/);
  assert.equal(await page.locator('#edit-status').isVisible(), false);
  assert.equal(await page.locator('#joint-list').innerText(), 'No joints.');
  // An edited model is not the example's fit: a link must not refit it.
  await page.evaluate(() => { window.copied = null; navigator.clipboard.writeText = async (t) => { window.copied = t; }; });
  await page.locator('#btn-share').click();
  await page.waitForFunction(() => /An edited model has no link yet/.test(document.querySelector('#toast').innerText));
  assert.equal(await page.evaluate(() => window.copied), null, 'nothing copied');

  await page.locator('#btn-undo-edit').click();
  const back = await modelState();
  assert.equal(back.parts, fitted.parts);
  assert.equal(back.joints, 1);
  assert.equal(back.ted, 0);
  assert.equal(back.source, 'fit');
  assert.deepEqual(back.labels, fitted.labels);
  assert.deepEqual(back.json.joints, fitted.json.joints);
  assert.equal(await page.locator('#btn-undo-edit').isVisible(), false);
  assert.equal(await page.locator('.joint .jjoin').count(), 1);

  // The hinge made a slide, and back by undo.
  await page.locator('.joint .jtype').click();
  await page.waitForFunction(() => window.gsart.state.model?.joints()[0]?.type === 'prismatic' && !window.gsart.state.editJob,
    null, { timeout: 120_000 });
  assert.match(await page.locator('#toast').innerText(), /Joint 1 made prismatic in [\d.]+ s/);
  assert.equal(await page.locator('.joint .jtype').innerText(), 'Make revolute');
  assert.deepEqual((await modelState()).json.info.edits.at(-1).joint_types, [[fitted.json.joints[0].child, 'prismatic']]);
  await page.locator('#btn-undo-edit').click();
  assert.deepEqual((await modelState()).json.joints, fitted.json.joints);

  // The lid made the root: the hinge turns round (the base is now its child), and
  // stays a hinge.
  const lid = fitted.json.joints[0].child;
  const base = fitted.json.joints[0].parent;
  assert.equal(await page.locator('#root-part').inputValue(), String(base));
  await page.selectOption('#root-part', String(lid));
  await page.waitForFunction((lid) => window.gsart.state.model?.root() === lid && !window.gsart.state.editJob,
    lid, { timeout: 120_000 });
  const rooted = await modelState();
  assert.equal(rooted.json.joints.length, 1);
  assert.equal(rooted.json.joints[0].parent, lid);
  assert.equal(rooted.json.joints[0].child, base);
  assert.equal(rooted.json.joints[0].type, 'revolute');
  assert.equal(rooted.json.info.edits.at(-1).root, lid);
  assert.equal(await page.locator('#root-part').inputValue(), String(lid));
  await page.locator('#btn-undo-edit').click();
  assert.equal(await page.locator('#root-part').inputValue(), String(base));
  assert.deepEqual((await modelState()).json.joints, fitted.json.joints);

  // A join cancelled while it runs leaves the model as it was.
  await page.locator('.joint .jjoin').click();
  await page.locator('#btn-cancel-edit').click();
  const kept = await modelState();
  assert.equal(kept.joints, 1);
  assert.deepEqual(kept.labels, fitted.labels);
  assert.equal(await page.locator('#edit-status').isVisible(), false);
  assert.equal(await page.locator('.joint .jjoin').isEnabled(), true);
  assert.equal(await page.locator('#btn-undo-edit').isVisible(), false);
  await page.waitForTimeout(4000); // longer than the join took: nothing arrives late
  assert.equal((await modelState()).joints, 1);
  assert.deepEqual(errors, []);
});

test('a model whose frames are not loaded offers no join', { timeout: 120_000 }, async () => {
  const json = await page.evaluate(() => window.gsart.state.model.to_json(true));
  const other = await newPage(browser, { width: 1100, height: 800 });
  await other.context.route((url) => url.pathname === '/shared/model.json',
    (r) => r.fulfill({ body: json, contentType: 'application/json' }));
  await other.page.goto(`${srv.base}/?model=/shared/model.json`);
  await waitLoaded(other.page);
  await other.page.waitForSelector('#explore:not([hidden])');
  assert.equal(await other.page.locator('.joint').count(), 1);
  assert.equal(await other.page.locator('.joint .jedits').count(), 0);
  assert.deepEqual(other.errors, []);
  await other.context.close();
});
