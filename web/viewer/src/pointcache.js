// The cache on the GPU, indexed by point: a 2D texture of RGBA halfs (alpha unused) holding point p
// at texel (p mod W, p div W), and a 3D texture of the dense box holding each voxel's point index + 1
// (0: no point). An update uploads only its rows of points: a chunk of fail-through branches is a
// contiguous range, and nothing is scattered on the CPU per update.

import * as THREE from 'three';

export const CACHE_WIDTH = 1024;

/** GLSL for the shaders: the cache's radiance at a voxel (ivec3), or -1 where it has no point. */
export const cacheLookupGlsl = /* glsl */ `
precision highp usampler3D;
uniform usampler3D uIndex;
uniform sampler2D uCache;
vec3 cacheAt(ivec3 voxel) {
  uint id = texelFetch(uIndex, voxel, 0).r;
  if (id == 0u) return vec3(-1.0);
  id -= 1u;
  return texelFetch(uCache, ivec2(int(id % ${CACHE_WIDTH}u), int(id / ${CACHE_WIDTH}u)), 0).rgb;
}`;

export class PointCache {
  constructor(index, dims) {
    const n = index.length;
    const [nx, ny, nz] = dims;
    const ids = new Uint32Array(nx * ny * nz);
    for (let p = 0; p < n; ++p) ids[index[p]] = p + 1;
    this.index = new THREE.Data3DTexture(ids, nx, ny, nz);
    this.index.format = THREE.RedIntegerFormat;
    this.index.type = THREE.UnsignedIntType;
    this.index.internalFormat = 'R32UI';
    this.index.minFilter = this.index.magFilter = THREE.NearestFilter;
    this.index.unpackAlignment = 1;
    this.index.needsUpdate = true;

    this.points = n;
    const rows = Math.max(1, Math.ceil(n / CACHE_WIDTH));
    this.data = new Uint16Array(CACHE_WIDTH * rows * 4);
    this.texture = new THREE.DataTexture(this.data, CACHE_WIDTH, rows, THREE.RGBAFormat, THREE.HalfFloatType);
    this.texture.minFilter = this.texture.magFilter = THREE.NearestFilter;
    this.texture.generateMipmaps = false;
    this.texture.unpackAlignment = 1;
    this.texture.needsUpdate = true;
    this.uploaded = false;
  }

  /** Copies points first..first+count-1 of an N x 3 half array to the texture's data (RGBA). */
  set(halfs, first, count) {
    const data = this.data;
    for (let p = first, end = first + count; p < end; ++p) {
      const d = p * 4;
      const s = p * 3;
      data[d] = halfs[s];
      data[d + 1] = halfs[s + 1];
      data[d + 2] = halfs[s + 2];
    }
    if (count > 0 && this.uploaded) {
      // Whole rows, so three uploads one rectangle per range.
      const row0 = Math.floor(first / CACHE_WIDTH);
      const row1 = Math.floor((first + count - 1) / CACHE_WIDTH);
      this.texture.addUpdateRange(row0 * CACHE_WIDTH * 4, (row1 - row0 + 1) * CACHE_WIDTH * 4);
    }
    if (count > 0) this.texture.needsUpdate = true;
  }

  /** Called after a draw: from now on updates upload their ranges only. */
  drawn() {
    this.uploaded = true;
  }
}
