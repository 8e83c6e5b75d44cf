// The cache on the GPU, indexed by point: a 2D texture of RGB halfs holding point p at texel
// (p mod W, p div W), and a 3D texture of the dense box holding each voxel's point index + 1 (0: no
// point). The texture's data is the page's cache array itself (N x 3 halfs, padded to whole rows), so
// an update is neither copied nor scattered: only the rows it touched are uploaded, and a chunk of
// fail-through branches is a contiguous range of points.

import * as THREE from 'three';

export const CACHE_WIDTH = 1024;

/**
 * GLSL for the shaders. uIndex holds, per voxel, (density byte << 24) | (point index + 1), 0 where the
 * voxel has no point: one fetch gives a ray-march step both its density (nearest voxel) and its
 * point. cacheOf(v) is the radiance of that voxel's point.
 */
export const cacheLookupGlsl = /* glsl */ `
precision highp usampler3D;
uniform usampler3D uIndex;
uniform sampler2D uCache;
vec3 cacheOf(uint v) {
  uint id = (v & 0xffffffu) - 1u;
  return texelFetch(uCache, ivec2(int(id % ${CACHE_WIDTH}u), int(id / ${CACHE_WIDTH}u)), 0).rgb;
}
vec3 cacheAt(ivec3 voxel) {
  uint v = texelFetch(uIndex, voxel, 0).r;
  return v == 0u ? vec3(-1.0) : cacheOf(v);
}`;

/** The most points the packed index holds (24 bits). */
export const MAX_POINTS = 0xffffff;

export class PointCache {
  /** @param densityBytes per voxel, 0..255 (or null: 0) */
  constructor(index, dims, densityBytes = null) {
    const n = index.length;
    if (n > MAX_POINTS) throw new Error(`${n} points: the page holds at most ${MAX_POINTS}`);
    const [nx, ny, nz] = dims;
    const ids = new Uint32Array(nx * ny * nz);
    for (let p = 0; p < n; ++p) {
      const cell = index[p];
      ids[cell] = ((densityBytes ? densityBytes[cell] : 0) * 0x1000000 + p + 1) >>> 0;
    }
    this.index = new THREE.Data3DTexture(ids, nx, ny, nz);
    this.index.format = THREE.RedIntegerFormat;
    this.index.type = THREE.UnsignedIntType;
    this.index.internalFormat = 'R32UI';
    this.index.minFilter = this.index.magFilter = THREE.NearestFilter;
    this.index.unpackAlignment = 1;
    this.index.needsUpdate = true;

    this.points = n;
    const rows = Math.max(1, Math.ceil(n / CACHE_WIDTH));
    this.data = new Uint16Array(CACHE_WIDTH * rows * 3);
    this.texture = new THREE.DataTexture(this.data, CACHE_WIDTH, rows, THREE.RGBFormat, THREE.HalfFloatType);
    this.texture.internalFormat = 'RGB16F';
    this.texture.minFilter = this.texture.magFilter = THREE.NearestFilter;
    this.texture.generateMipmaps = false;
    this.texture.unpackAlignment = 2;
    this.texture.needsUpdate = true;
    this.uploaded = false;
  }

  /** The page's cache: N x 3 halfs, the first part of the texture's data. */
  get cache() {
    return this.data.subarray(0, this.points * 3);
  }

  /** Points first..first+count-1 of the shown array changed: upload their rows at the next draw. */
  touched(first, count) {
    if (count <= 0) return;
    if (this.uploaded && this.texture.image.data === this.data) {
      const row0 = Math.floor(first / CACHE_WIDTH);
      const row1 = Math.floor((first + count - 1) / CACHE_WIDTH);
      this.texture.addUpdateRange(row0 * CACHE_WIDTH * 3, (row1 - row0 + 1) * CACHE_WIDTH * 3);
    }
    this.texture.needsUpdate = true;
  }

  /** Shows another N x 3 half array (the difference view), or the cache again (null): a full upload. */
  show(halfs) {
    let data = this.data;
    if (halfs) {
      data = new Uint16Array(this.data.length);
      data.set(halfs);
    }
    this.texture.image.data = data;
    this.texture.clearUpdateRanges();
    this.texture.needsUpdate = true;
  }

  /** Called after a draw: from now on updates upload their ranges only. */
  drawn() {
    this.uploaded = true;
  }
}
