// IEEE half floats, and the checksums: the cache's (wordChecksum, sent by the server with every
// update) and the canvas's (fnv1a64, for the test's image comparisons).

// Every half bit pattern decoded once: 65,536 floats (256 KiB).
export const HALF_TO_FLOAT = (() => {
  const table = new Float32Array(65536);
  for (let h = 0; h < 65536; ++h) {
    const sign = h & 0x8000 ? -1 : 1;
    const exponent = (h >> 10) & 0x1f;
    const mantissa = h & 0x3ff;
    let v;
    if (exponent === 0) v = mantissa * 2 ** -24;
    else if (exponent === 31) v = mantissa ? NaN : Infinity;
    else v = (1 + mantissa / 1024) * 2 ** (exponent - 15);
    table[h] = sign * v;
  }
  return table;
})();

const f32 = new Float32Array(1);
const u32 = new Uint32Array(f32.buffer);

/** The nearest half to a float (round to nearest even), as its bit pattern. */
export function floatToHalf(value) {
  f32[0] = value;
  const x = u32[0];
  const sign = (x >>> 16) & 0x8000;
  const exponent = (x >>> 23) & 0xff;
  let mantissa = x & 0x7fffff;
  if (exponent === 0xff) return sign | 0x7c00 | (mantissa ? 0x200 : 0);
  let e = exponent - 127 + 15;
  if (e >= 31) return sign | 0x7c00;
  if (e <= 0) {
    if (e < -10) return sign;
    mantissa |= 0x800000;
    const shift = 14 - e;
    let half = mantissa >>> shift;
    const rest = mantissa & ((1 << shift) - 1);
    const halfway = 1 << (shift - 1);
    if (rest > halfway || (rest === halfway && half & 1)) ++half;
    return sign | half;
  }
  let half = (e << 10) | (mantissa >>> 13);
  const rest = mantissa & 0x1fff;
  if (rest > 0x1000 || (rest === 0x1000 && half & 1)) ++half;  // may carry into the exponent: correct
  return sign | half;
}

// FNV-1a 64 (offset 0xcbf29ce484222325, prime 0x100000001b3) with the 64-bit state kept as two
// 32-bit halves: the prime is 2^40 + 0x1b3, so h * prime = h * 0x1b3 + (h << 40), every partial
// product exact in a double.
const FNV_OFFSET_HI = 0xcbf29ce4;
const FNV_OFFSET_LO = 0x84222325;

/** One FNV-1a 64 step: state [hi, lo] xor a value of up to 32 bits, times the prime. */
function fnvStep(state, value) {
  const lo = (state[1] ^ value) >>> 0;
  const a = (lo & 0xffff) * 0x1b3;
  const b = (lo >>> 16) * 0x1b3;
  const t = a + (b & 0xffff) * 65536;
  const carry = Math.floor(t / 4294967296) + Math.floor(b / 65536);
  state[0] = (Math.imul(state[0], 0x1b3) + carry + (lo << 8)) >>> 0;
  state[1] = t >>> 0;
}

function hex(state) {
  return state[0].toString(16).padStart(8, '0') + state[1].toString(16).padStart(8, '0');
}

/** FNV-1a 64 over the bytes of a typed array, as 16 lowercase hex digits. */
export function fnv1a64(typedArray) {
  const bytes = new Uint8Array(typedArray.buffer, typedArray.byteOffset, typedArray.byteLength);
  const state = [FNV_OFFSET_HI, FNV_OFFSET_LO];
  for (let n = 0; n < bytes.length; ++n) fnvStep(state, bytes[n]);
  return hex(state);
}

/**
 * The checksum the server sends with a cache: FNV-1a 64 stepped once per 32-bit little-endian word
 * of a Uint16Array (two halves), the last word zero-padded when the count is odd. A quarter of the
 * byte-wise steps: the page verifies every update.
 */
export function wordChecksum(halfs) {
  const state = [FNV_OFFSET_HI, FNV_OFFSET_LO];
  const n = halfs.length;
  let i = 0;
  for (; i + 2 <= n; i += 2) fnvStep(state, (halfs[i] | (halfs[i + 1] << 16)) >>> 0);
  if (i < n) fnvStep(state, halfs[i]);
  return hex(state);
}
