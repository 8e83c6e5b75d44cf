// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/scene/Image.h"
#include "evaluators/volume/VolumeEvaluator.h"

#include <vector>

namespace pmsc::volume {

using scene::Camera;
using scene::Image;

/// The demo's three moving cameras at animation time t in [0, 1]: "front" (orbiting slowly at eye
/// height, 1.9 radii out), "above" (looking down at 55 degrees) and "inside" (in the medium, near
/// its centre, turning as it looks across the smoke).
std::vector<Camera> volumeCameras(const VolumeWorld& world, double t);

/// Renders the medium from a camera, once per cache: an emission-absorption ray march of the
/// density (half-voxel steps inside the active leaf spans that OpenVDB's VolumeRayIntersector
/// finds), whose source term is sigma_s(x) x the in-scattered radiance looked up in the cache
/// (ScatterCache::Sampler, trilinear): per step L += T (1 - exp(-sigma_t dt)) albedo Lin,
/// T *= exp(-sigma_t dt). The cache is view-independent, so one cache serves every camera.
///
/// All caches share the primary rays and the transmittance, so the images differ only where the
/// caches do. One ray per pixel centre (the medium is soft; no edges to antialias): deterministic.
/// Parallel over rows (tbb::parallel_for in the caller's arena). The background is black.
/// @throws std::invalid_argument for size < 1.
std::vector<Image> renderVolume(const VolumeWorld& world, const Camera& camera,
                                const std::vector<const ScatterCache*>& caches, int size);

}  // namespace pmsc::volume
