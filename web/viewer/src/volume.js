// The volume: an emission-absorption ray march of the dense box on the GPU, lit by the cache.
//
// Per step, as the CPU renderer does: L += T (1 - exp(-sigma_t dt)) albedo Lin; T *= exp(-sigma_t dt),
// with sigma_t = volume.sigma_t x density and Lin the cache's in-scattered radiance
// at the voxel's point (nearest voxel: the cache is kept by point, see pointcache.js).

import * as THREE from 'three';
import {PointCache, cacheLookupGlsl, displayGlsl} from './pointcache.js';

const vertexShader = /* glsl */ `
out vec3 vWorld;
void main() {
  vec4 world = modelMatrix * vec4(position, 1.0);
  vWorld = world.xyz;
  gl_Position = projectionMatrix * viewMatrix * world;
}`;

const fragmentShader = /* glsl */ `
precision highp float;
precision highp sampler3D;
${cacheLookupGlsl}
uniform sampler3D uDensity;   // density / maxDensity (the difference view: |cache - reference| instead of Lin)
uniform vec3 uBoxMin;
uniform vec3 uDims;
uniform vec3 uBoxMax;
uniform float uSigmaT;        // volume.sigma_t x maxDensity
uniform vec3 uAlbedo;
uniform float uStep;          // world units
uniform int uMaxSteps;
uniform int uSmooth;          // 1: density trilinear (the refined image), 0: the voxel's own
${displayGlsl}
in vec3 vWorld;
out vec4 fragColor;

void main() {
  vec3 origin = cameraPosition;
  vec3 dir = normalize(vWorld - origin);
  vec3 inv = 1.0 / dir;
  vec3 t0 = (uBoxMin - origin) * inv;
  vec3 t1 = (uBoxMax - origin) * inv;
  vec3 tLow = min(t0, t1);
  vec3 tHigh = max(t0, t1);
  float tNear = max(max(max(tLow.x, tLow.y), tLow.z), 0.0);
  float tFar = min(min(tHigh.x, tHigh.y), tHigh.z);
  if (tFar <= tNear) discard;
  int steps = min(int(ceil((tFar - tNear) / uStep)), uMaxSteps);
  float dt = (tFar - tNear) / float(steps);
  vec3 toUvw = 1.0 / (uBoxMax - uBoxMin);
  vec3 p = (origin + (tNear + 0.5 * dt) * dir - uBoxMin) * toUvw;
  vec3 dp = dir * dt * toUvw;
  float T = 1.0;
  vec3 L = vec3(0.0);
  float largest = 0.0;
  ivec3 top = ivec3(uDims) - 1;
  for (int s = 0; s < steps; ++s, p += dp) {
    // The voxel's point and density in one fetch; the refined image takes the density trilinear.
    uint v = texelFetch(uIndex, clamp(ivec3(p * uDims), ivec3(0), top), 0).r;
    if (v == 0u) continue;
    float density = uSmooth == 1 ? texture(uDensity, p).r : float(v >> 24) / 255.0;
    float alpha = 1.0 - exp(-uSigmaT * density * dt);
    vec3 lin = cacheOf(v);
    if (uDifference == 1) {  // the largest difference along the ray, wherever the medium is
      if (density > 0.0) largest = max(largest, lin.r);
      continue;
    }
    L += T * alpha * uAlbedo * lin;
    T *= 1.0 - alpha;
    if (T < 0.004) break;
  }
  fragColor = vec4(display(L, largest), 1.0);
}`;

export class VolumeView {
  /** @param info {scene, index, density} from loadScene */
  constructor(renderer, info) {
    const {scene, index, density} = info;
    const [nx, ny, nz] = scene.grid.dims;
    this.dims = [nx, ny, nz];
    const h = scene.grid.voxel;
    const origin = new THREE.Vector3(...scene.grid.origin);
    const boxMin = origin.clone().addScalar(-0.5 * h);
    const boxMax = origin.clone().add(new THREE.Vector3(nx, ny, nz).multiplyScalar(h)).addScalar(-0.5 * h);

    // Density, normalised by its largest value, one byte a voxel: uploaded once.
    let maxDensity = 0;
    for (let p = 0; p < density.length; ++p) maxDensity = Math.max(maxDensity, density[p]);
    const densityBytes = new Uint8Array(nx * ny * nz);
    if (maxDensity > 0)
      for (let p = 0; p < index.length; ++p) densityBytes[index[p]] = Math.round((255 * density[p]) / maxDensity);
    const densityTexture = new THREE.Data3DTexture(densityBytes, nx, ny, nz);
    densityTexture.format = THREE.RedFormat;
    densityTexture.type = THREE.UnsignedByteType;
    densityTexture.minFilter = densityTexture.magFilter = THREE.LinearFilter;
    densityTexture.unpackAlignment = 1;
    densityTexture.needsUpdate = true;

    // The cache, by point; uploaded per update (the range it changed).
    this.cache = new PointCache(renderer, index, this.dims, densityBytes);

    this.material = new THREE.ShaderMaterial({
      glslVersion: THREE.GLSL3,
      vertexShader,
      fragmentShader,
      side: THREE.BackSide,  // the box's far faces: the march works with the camera inside too
      uniforms: {
        uDensity: {value: densityTexture},
        uCache: {value: this.cache.texture},
        uIndex: {value: this.cache.index},
        uDims: {value: new THREE.Vector3(nx, ny, nz)},
        uBoxMin: {value: boxMin},
        uBoxMax: {value: boxMax},
        uSigmaT: {value: scene.volume.sigma_t * maxDensity},
        uAlbedo: {value: new THREE.Vector3(...scene.volume.albedo)},
        uStep: {value: h},
        uMaxSteps: {value: 512},
        uSmooth: {value: 1},
        uExposure: {value: 1},
        uGamma: {value: 2.2},
        uDifference: {value: 0},
        uDifferenceScale: {value: 1},
      },
    });
    const size = boxMax.clone().sub(boxMin);
    const box = new THREE.Mesh(new THREE.BoxGeometry(size.x, size.y, size.z), this.material);
    box.position.copy(boxMin.clone().add(boxMax).multiplyScalar(0.5));
    this.object = new THREE.Group();
    this.object.add(box);
    this.boxSize = size;
  }

  setExposure(exposure, gamma) {
    this.material.uniforms.uExposure.value = exposure;
    this.material.uniforms.uGamma.value = gamma;
  }

  /** Step length in voxels (1 = one voxel); larger is cheaper and coarser. Smooth: trilinear density. */
  setStep(voxels, smooth = true) {
    this.material.uniforms.uSmooth.value = smooth ? 1 : 0;
    this.material.uniforms.uStep.value = voxels * this.voxel();
  }

  voxel() {
    return this.boxSize.x / this.dims[0];
  }

  /** The difference view: the cache texture then holds |cache - reference|, shown as heat / max. */
  showDifference(on, max) {
    const uniforms = this.material.uniforms;
    uniforms.uDifference.value = on ? 1 : 0;
    uniforms.uDifferenceScale.value = max > 0 ? 1 / max : 1;
  }
}
