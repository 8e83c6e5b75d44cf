// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "examples/cornell/CornellScene.h"

#include <cstdint>
#include <memory>
#include <span>

namespace pmsc::cornell {

/// One ray, single precision as Embree traces it. Millimetres.
struct Ray {
    float org[3];
    float dir[3];  ///< need not be normalized; t is in units of |dir|
    float tnear = 0;
    float tfar = 1e30f;
};

/// The closest hit of a ray: the quad index into CornellScene::quads(), or -1 for a miss.
struct Hit {
    float t;
    int quad;
};

/// How batches of rays are handed to Embree. All modes return identical hits (Embree's
/// watertight triangle test is the same code); they differ only in speed. Measured on the
/// gather rays of CornellEvaluator (bench numbers in the README, "Cornell box").
enum class TraceMode {
    Single,   ///< rtcIntersect1 / rtcOccluded1 per ray
    Stream,   ///< rtcIntersect1M / rtcOccluded1M over the whole batch
    Packet8,  ///< rtcIntersect8 / rtcOccluded8 packets
};

/// The Cornell box in an Embree 3 BVH (one quad geometry, primitive id = quad index).
/// The only file that includes Embree's headers is RayTracer.cpp.
///
/// Thread safety: after construction every method is const and safe to call from any
/// number of threads (Embree's committed scenes are read-only).
class RayTracer {
public:
    explicit RayTracer(const CornellScene& scene, TraceMode mode = TraceMode::Stream);
    ~RayTracer();
    RayTracer(const RayTracer&) = delete;
    RayTracer& operator=(const RayTracer&) = delete;

    TraceMode mode() const { return mode_; }
    void setMode(TraceMode mode) { mode_ = mode; }

    /// Closest hits of a batch. @pre hits.size() >= rays.size()
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    /// Occlusion of a batch: blocked[i] = 1 if anything lies in (tnear, tfar) of ray i.
    void occluded(std::span<const Ray> rays, std::span<std::uint8_t> blocked) const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
    TraceMode mode_;
};

}  // namespace pmsc::cornell
