// The Cornell box: its quads, shaded by the cache's indirect irradiance (nearest voxel).
//
// A fragment at world position x on a quad with normal n reads voxel round((x - 0.5 h n - origin) / h)
// (voxel (i,j,k)'s centre is origin + h (i,j,k)): half a voxel into the surface's shell of points;
// where that voxel holds no point, the nearest along the normal that does.
// Radiance shown = albedo / pi x cache irradiance: indirect light only, no direct term.

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
uniform vec3 uOrigin;
uniform float uVoxel;
uniform ivec3 uDims;
uniform vec3 uNormal;
uniform vec3 uAlbedo;
${displayGlsl}
in vec3 vWorld;
out vec4 fragColor;

void main() {
  // Half a voxel behind the surface first; where that voxel holds no point (thin or slanted shells
  // on a coarse grid), the voxel at the surface, then one a whole voxel behind, then in front.
  const float depths[4] = float[4](0.5, 0.0, 1.0, -0.5);
  vec3 irradiance = vec3(-1.0);
  for (int k = 0; k < 4 && irradiance.r < 0.0; ++k) {
    vec3 cell = (vWorld - depths[k] * uVoxel * uNormal - uOrigin) / uVoxel;
    irradiance = cacheAt(clamp(ivec3(floor(cell + 0.5)), ivec3(0), uDims - 1));
  }
  irradiance = max(irradiance, vec3(0.0));  // no point near: black
  fragColor = vec4(display(uAlbedo / 3.14159265 * irradiance, irradiance.r), 1.0);
}`;

export class CornellView {
  constructor(renderer, info) {
    const {scene, index} = info;
    const [nx, ny, nz] = scene.grid.dims;
    this.dims = [nx, ny, nz];
    this.cache = new PointCache(renderer, index, this.dims);

    this.shared = {
      uCache: {value: this.cache.texture},
      uIndex: {value: this.cache.index},
      uOrigin: {value: new THREE.Vector3(...scene.grid.origin)},
      uVoxel: {value: scene.grid.voxel},
      uDims: {value: new THREE.Vector3(nx, ny, nz)},
      uExposure: {value: 1},
      uGamma: {value: 2.2},
      uDifference: {value: 0},
      uDifferenceScale: {value: 1},
    };
    this.object = new THREE.Group();
    for (const quad of scene.quads) {
      const c = quad.corners;
      const positions = new Float32Array([...c[0], ...c[1], ...c[2], ...c[0], ...c[2], ...c[3]]);
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
      const material = new THREE.ShaderMaterial({
        glslVersion: THREE.GLSL3,
        vertexShader,
        fragmentShader,
        side: THREE.DoubleSide,
        uniforms: {
          ...this.shared,
          uNormal: {value: new THREE.Vector3(...quad.normal)},
          uAlbedo: {value: new THREE.Vector3(...quad.albedo)},
        },
      });
      this.object.add(new THREE.Mesh(geometry, material));
    }
  }

  setExposure(exposure, gamma) {
    this.shared.uExposure.value = exposure;
    this.shared.uGamma.value = gamma;
  }

  setStep() {}

  showDifference(on, max) {
    this.shared.uDifference.value = on ? 1 : 0;
    this.shared.uDifferenceScale.value = max > 0 ? 1 / max : 1;
  }
}

