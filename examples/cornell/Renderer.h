// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/cornell/CornellEvaluator.h"
#include "evaluators/cornell/LightingCacheGrid.h"
#include "evaluators/scene/Image.h"

#include <vector>

namespace pmsc::cornell {

using scene::absDifference;
using scene::Image;
using scene::readPfm;
using scene::sideBySide;
using scene::writePfm;
using scene::writePng;

/// Renders the box from a camera: each pixel's visible surface gets its direct light exactly
/// (a shadow ray to the point light) and its indirect light looked up in world space from a
/// lighting cache (LightingCacheGrid::sample), radiance = albedo/pi * (direct + indirect).
///
/// One image per cache, from the same primary rays and the same direct light, so images
/// differ only where the caches differ (full gather vs PMSC). 2 x 2 stratified samples per
/// pixel, fixed pattern: deterministic. Parallel over rows (tbb::parallel_for).
/// @param size width = height in pixels (the measured camera's images are square).
std::vector<Image> renderWithCaches(const CornellWorld& world, const Camera& camera, const PointLight& light,
                                    const std::vector<const LightingCacheGrid*>& caches, int size);

}  // namespace pmsc::cornell
