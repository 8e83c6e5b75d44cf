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

/**
 * GLSL both scenes display with: tone mapping of a linear value (exposure, gamma) or, in the
 * difference view, a heat map of a difference scaled to its largest.
 */
export const displayGlsl = /* glsl */ `
uniform float uExposure;
uniform float uGamma;
uniform int uDifference;
uniform float uDifferenceScale;
vec3 heat(float x) {
  x = clamp(x, 0.0, 1.0);
  return clamp(vec3(3.0 * x, 3.0 * x - 1.0, 3.0 * x - 2.0), 0.0, 1.0);
}
vec3 display(vec3 linear, float difference) {
  return uDifference == 1 ? heat(difference * uDifferenceScale)
                          : pow(clamp(linear * uExposure, 0.0, 1.0), vec3(1.0 / uGamma));
}`;

/** The most points the packed index holds (24 bits). */
export const MAX_POINTS = 0xffffff;

export class PointCache {
  /** @param densityBytes per voxel, 0..255 (or null: 0) */
  constructor(renderer, index, dims, densityBytes = null) {
    const n = index.length;
    if (n > MAX_POINTS) throw new Error(`${n} points: the page holds at most ${MAX_POINTS}`);
    this.renderer = renderer;
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
    this.rows = Math.max(1, Math.ceil(n / CACHE_WIDTH));
    this.data = new Uint16Array(CACHE_WIDTH * this.rows * 3);
    this.texture = new THREE.DataTexture(this.data, CACHE_WIDTH, this.rows, THREE.RGBFormat, THREE.HalfFloatType);
    this.texture.internalFormat = 'RGB16F';
    this.texture.minFilter = this.texture.magFilter = THREE.NearestFilter;
    this.texture.generateMipmaps = false;
    this.texture.unpackAlignment = 2;
    this.texture.needsUpdate = true;
    this.rowLow = Infinity;  // rows changed since the last upload
    this.rowHigh = -1;
  }

  /** The page's cache: N x 3 halfs, the first part of the texture's data. */
  get cache() {
    return this.data.subarray(0, this.points * 3);
  }

  /** Points first..first+count-1 of the shown array changed: upload their rows at the next upload(). */
  touched(first, count) {
    if (count <= 0 || this.texture.image.data !== this.data) return;
    this.rowLow = Math.min(this.rowLow, Math.floor(first / CACHE_WIDTH));
    this.rowHigh = Math.max(this.rowHigh, Math.floor((first + count - 1) / CACHE_WIDTH));
  }

  /** Shows another N x 3 half array (the difference view), or the cache again (null). */
  show(halfs) {
    let data = this.data;
    if (halfs) {
      data = new Uint16Array(this.data.length);
      data.set(halfs);
    }
    this.texture.image.data = data;
    this.rowLow = 0;
    this.rowHigh = this.rows - 1;
  }

  /**
   * Uploads the changed rows: texSubImage2D of whole rows on three's texture (three's own update
   * ranges take RGBA rows only), then three's record of the GL state is reset. The first upload,
   * before three has made the texture, is three's.
   */
  upload() {
    const renderer = this.renderer;
    const properties = renderer.properties.get(this.texture);
    if (!properties.__webglTexture || properties.__version !== this.texture.version) {
      this.texture.needsUpdate = true;
      renderer.initTexture(this.texture);
    } else if (this.rowHigh >= this.rowLow) {
      const gl = renderer.getContext();
      const low = this.rowLow;
      const rows = this.rowHigh - low + 1;
      gl.bindTexture(gl.TEXTURE_2D, properties.__webglTexture);
      gl.pixelStorei(gl.UNPACK_ALIGNMENT, 2);
      gl.pixelStorei(gl.UNPACK_ROW_LENGTH, 0);
      gl.pixelStorei(gl.UNPACK_SKIP_PIXELS, 0);
      gl.pixelStorei(gl.UNPACK_SKIP_ROWS, 0);
      gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
      gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
      const data = this.texture.image.data;
      gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, low, CACHE_WIDTH, rows, gl.RGB, gl.HALF_FLOAT,
        data.subarray(low * CACHE_WIDTH * 3, (low + rows) * CACHE_WIDTH * 3));
      gl.bindTexture(gl.TEXTURE_2D, null);
      renderer.resetState();
    }
    this.rowLow = Infinity;
    this.rowHigh = -1;
  }
}
