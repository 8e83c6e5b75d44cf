// The page's half floats and checksums against values computed independently (Python integers,
// and the server's tests of the same inputs): node --test web/viewer/tests/half.test.mjs
import assert from 'node:assert/strict';
import test from 'node:test';
import {HALF_TO_FLOAT, floatToHalf, fnv1a64, wordChecksum} from '../src/half.js';

test('wordChecksum steps FNV-1a 64 per 32-bit word, zero-padding an odd count', () => {
  assert.equal(wordChecksum(new Uint16Array(6)), 'd94d12186c0f2fb7');
  assert.equal(wordChecksum(new Uint16Array([1, 2, 3])), '3c2f2501ee9691dd');
  assert.equal(wordChecksum(new Uint16Array([0x3c00, 0xc000, 0x7bff, 0xffff, 0x8000])), '5bda643e5916f520');
  assert.equal(wordChecksum(new Uint16Array(0)), 'cbf29ce484222325');
});

test('wordChecksum reads a view at its offset', () => {
  const buffer = new Uint16Array([9, 9, 1, 2, 3]);
  assert.equal(wordChecksum(buffer.subarray(2)), '3c2f2501ee9691dd');
});

test('fnv1a64 is FNV-1a 64 over bytes', () => {
  assert.equal(fnv1a64(new Uint8Array(0)), 'cbf29ce484222325');
  assert.equal(fnv1a64(new Uint8Array(12)), '5467b0da1d106495');
  assert.equal(fnv1a64(new TextEncoder().encode('a')), 'af63dc4c8601ec8c');
});

test('floatToHalf rounds to nearest even and HALF_TO_FLOAT decodes it', () => {
  assert.equal(floatToHalf(1), 0x3c00);
  assert.equal(floatToHalf(-2), 0xc000);
  assert.equal(floatToHalf(65504), 0x7bff);
  assert.equal(floatToHalf(1 + 2 ** -11), 0x3c00);  // a tie: down to even
  assert.equal(floatToHalf(1 + 3 * 2 ** -11), 0x3c02);  // a tie: up to even
  assert.equal(HALF_TO_FLOAT[0x3c00], 1);
  assert.equal(HALF_TO_FLOAT[floatToHalf(0.1)], HALF_TO_FLOAT[0x2e66]);
});
