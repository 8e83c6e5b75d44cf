// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "examples/cornell/CornellScene.h"
#include "examples/cornell/RayTracer.h"
#include "examples/cornell/SurfaceVoxels.h"
#include "pmsc/FrameWriter.h"
#include "pmsc/PointEvaluator.h"

#include <memory>
#include <string>
#include <vector>

namespace pmsc::cornell {

/// What every Cornell evaluator of a run shares: the scene, its BVH and the cache's points.
struct CornellWorld {
    CornellScene scene;
    std::shared_ptr<const RayTracer> tracer;
    SurfaceVoxels voxels;

    /// The measured box voxelized to about `points` surface voxels.
    static std::shared_ptr<const CornellWorld> create(std::size_t points, TraceMode mode = TraceMode::Stream);
};

/// Direct irradiance (RGB) from a point light at surface point p with unit normal n, with a
/// shadow ray (batch form: one shadow ray per point, traced together).
/// @param[out] out 3 doubles per point.
void directIrradiance(const RayTracer& tracer, const PointLight& light, std::span<const Vec3> p,
                      std::span<const Vec3> n, double* out);

/// Section 8's expensive calculation: one-bounce indirect diffuse irradiance (RGB) at the
/// cache's points, by a final gather with Embree, for a point light whose position is the
/// frame's animation variable.
///
/// For point x with normal n, S cosine-weighted gather rays leave x; at each hit h on a
/// front face, a shadow ray to the light gives the direct irradiance E_d(h), and
///   E_ind(x) = (1/S) * sum over rays of albedo(h) * E_d(h)
/// (the cosine-weighted estimator of the integral of L(h) cos, with L(h) = albedo/pi * E_d).
/// One bounce: light -> surface -> x. A second bounce would double the cost per frame and
/// the demo's budget (144 training frames + validation in under 5 minutes on 2 cores) is
/// spent better on samples.
///
/// Samples: a Hammersley set shifted per point id (Sampling.h), the same every frame. Each
/// point's S rays go to Embree as one batch of their own, so a point's value is bit-identical
/// whether it is evaluated alone, among all points, at any thread count.
///
/// Thread safety: evaluate() is const, uses thread-local scratch only. evaluateAll() runs a
/// tbb::parallel_for in the caller's task arena (limit threads with tbb::task_arena or
/// tbb::global_control); evaluate() itself is serial, so the engine's parallel fail-through
/// branches do not oversubscribe.
///
/// Also a FrameWriterProvider: `pmsc run` can write each frame as a lighting-cache .vdb
/// (LightingCacheGrid, grid "indirect" + "normal" + "surface_point").
class CornellEvaluator : public PointEvaluator, public FrameWriterProvider {
public:
    /// @param lights one frame per light. @param samplesPerPoint S >= 1.
    CornellEvaluator(std::shared_ptr<const CornellWorld> world, std::vector<PointLight> lights,
                     int samplesPerPoint, std::string name = "cornell");

    std::string name() const override { return name_; }
    Index pointCount() const override { return static_cast<Index>(world_->voxels.size()); }
    Index channelCount() const override { return 3; }
    Index frameCount() const override { return static_cast<Index>(lights_.size()); }

    void evaluate(Index frame, std::span<const Index> points, double* out) const override;
    void evaluateAll(Index frame, double* out) const override;

    std::vector<std::shared_ptr<const FrameWriter>> frameWriters() const override;

    const CornellWorld& world() const { return *world_; }
    const std::vector<PointLight>& lights() const { return lights_; }
    int samplesPerPoint() const { return samples_; }

private:
    void gather(const PointLight& light, Index point, double* rgb) const;

    std::shared_ptr<const CornellWorld> world_;
    std::vector<PointLight> lights_;
    int samples_;
    std::string name_;
};

/// The `cornell` evaluator of the command line (spec "cornell[:OPTIONS]"), OPTIONS a comma-separated
/// list of points=N (default 160000), samples=S (default 128) and lights=SET, SET one of
///   all (default): the 144 training lights, then 16 scattered validation lights, then the 60-frame
///                  path (frames 0-143, 144-159, 160-219), so one spec serves export-frames and run;
///   training | scattered | path: only that set, from frame 0.
/// @throws pmsc::InputError naming the bad option.
std::unique_ptr<CornellEvaluator> makeCornellEvaluator(const std::string& options);

}  // namespace pmsc::cornell
