// The loss chart's axis labels (no browser needed: the module touches the DOM only
// when a chart is made).
import test from 'node:test';
import assert from 'node:assert/strict';
import { tickLabels } from '../../www/js/chart.js';

test('axis labels get the digits that tell close ticks apart', () => {
  // Step 3's refinement loss over a narrow range: one digit read 4e-3, 4e-3, 3e-3, 3e-3.
  const narrow = tickLabels([3.0e-3, 3.3e-3, 3.7e-3, 4.0e-3]);
  assert.deepEqual(narrow, ['3.0e-3', '3.3e-3', '3.7e-3', '4.0e-3']);
  // A wide range keeps the short form.
  assert.deepEqual(tickLabels([6e-3, 1.3e-2, 2.8e-2, 6e-2]), ['6e-3', '0.01', '0.03', '0.06']);
  assert.deepEqual(tickLabels([0.02, 0.03, 0.04, 0.05]), ['0.02', '0.03', '0.04', '0.05']);
  assert.deepEqual(tickLabels([1.5, 1.52, 1.54, 1.56]), ['1.50', '1.52', '1.54', '1.56']);
});
