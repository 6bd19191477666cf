// The fit settings a link carries (www/js/settings.js; no browser needed).
import test from 'node:test';
import assert from 'node:assert/strict';
import { DEFAULTS, settingsFromParams, writeSettings, exampleSeed } from '../../www/js/settings.js';

const parse = (q) => settingsFromParams(new URLSearchParams(q));

test('a link\'s settings are read, and what cannot be used is named', () => {
  assert.deepEqual(parse(''), { values: {}, problems: [] });
  assert.deepEqual(parse('quality=fast&parts=2..4&seed=3&restarts=2&medial=1&occlusion=on&keys=0').values,
    { quality: 'fast', parts: [2, 4], seed: 3, restarts: 2, medial_init: true, occlusion: 'on', key_frames: 0 });
  assert.deepEqual(parse('parts=3-7').values, { parts: [3, 7] });
  assert.deepEqual(parse('parts=12').values, { parts: [12, 12] });
  const bad = parse('quality=best&parts=7..3&seed=-1&restarts=4&medial=yes&occlusion=maybe&parts2=1&keys=7');
  assert.deepEqual(bad.values, {});
  assert.equal(bad.problems.length, 7);
  assert.match(bad.problems.join('\n'), /keys=7: use 20, 12, 40, 0 \(0: every frame\)/);
  assert.match(bad.problems.join('\n'), /quality=best: use fast, balanced, paper/);
  assert.match(bad.problems.join('\n'), /parts=7\.\.3: use a range like 3\.\.7/);
  assert.deepEqual(parse('parts=1..4').problems.length, 1, 'a part count is at least 2');
  assert.deepEqual(parse('parts=2..41').problems.length, 1, 'and at most 40');
});

test('a link carries the settings that differ from the defaults, and reads back the same', () => {
  const url = new URL('http://x/?example=laptop&quality=paper&seed=9');
  writeSettings(url, DEFAULTS);
  assert.equal(url.search, '?example=laptop', 'the defaults write nothing, and stale settings go');
  const opts = { quality: 'fast', occlusion: 'off', seed: 2, restarts: 3, medial_init: true, key_frames: 12, parts: [2, 4] };
  writeSettings(url, opts, 0);
  const back = parse(url.search);
  assert.deepEqual(back.values, opts);
  assert.equal(url.searchParams.get('parts'), '2..4', 'the CLI\'s way of writing a range');
  // The example was generated with seed 0 and fitted with seed 2.
  assert.equal(exampleSeed(url.searchParams, 2), 0);
  writeSettings(url, opts);
  assert.equal(url.searchParams.get('example_seed'), null);
  assert.equal(exampleSeed(url.searchParams, 2), 2);
});
