// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/cornell/CornellScene.h"

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

/// A ray from o along d (single precision, tnear 0).
inline Ray makeRay(Vec3 o, Vec3 d, double tfar) {
    Ray r;
    r.org[0] = static_cast<float>(o.x);
    r.org[1] = static_cast<float>(o.y);
    r.org[2] = static_cast<float>(o.z);
    r.dir[0] = static_cast<float>(d.x);
    r.dir[1] = static_cast<float>(d.y);
    r.dir[2] = static_cast<float>(d.z);
    r.tnear = 0.0f;
    r.tfar = static_cast<float>(tfar);
    return r;
}

/// The closest hit of a ray: the quad index into CornellScene::quads(), or -1 for a miss.
struct Hit {
    float t;
    int quad;
};

/// How batches of rays are handed to Embree. All modes return identical hits (Embree's
/// watertight triangle test is the same code); they differ only in speed. Measured on the
/// gather rays of CornellEvaluator (bench numbers in docs/cornell.md).
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
