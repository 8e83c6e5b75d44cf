// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/cornell/CornellScene.h"
#include "evaluators/cornell/RayTracer.h"
#include "evaluators/cornell/SurfaceVoxels.h"
#include "pmsc/FrameWriter.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/PointPositions.h"

#include <memory>
#include <mutex>
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
    /// The same points (voxels, ids, normals) in a changed scene (its own BVH, the same trace
    /// mode): a scene whose quads begin with `base`'s, as CornellScene::withBox makes.
    /// @throws std::invalid_argument if `scene` does not begin with base's quads.
    static std::shared_ptr<const CornellWorld> withScene(const CornellWorld& base, CornellScene scene);
};

/// Direct irradiance (RGB) from a point light at surface point p with unit normal n, with a
/// shadow ray (batch form: one shadow ray per point, traced together).
/// @param[out] out 3 doubles per point.
void directIrradiance(const RayTracer& tracer, const PointLight& light, std::span<const Vec3> p,
                      std::span<const Vec3> n, double* out);

/// Section 8's expensive calculation: one-bounce indirect diffuse irradiance (RGB) at the
/// cache's points, by a final gather with Embree, for a point light whose position is the
/// frame's animation variable. One bounce: light -> surface y -> point x. (A second bounce
/// would double the cost per frame; the demo's budget, 144 training frames and the validation
/// in under 5 minutes on 2 cores, is spent better on samples.)
///
/// E_ind(x) = integral over surfaces of albedo(y)/pi * Ed(y) * G(x,y) V(x,y) dA(y), with
/// Ed(y) = I cos_yl / |l-y|^2 (shadow-tested) and G = cos_x cos_y / |x-y|^2, estimated by two
/// strategies combined with the balance heuristic (multiple importance sampling):
///  - A, S/2 gather rays: cosine-weighted directions from x; the hit y gets a shadow ray to
///    the light. Good where y is near x (corners), poor for the hot spot the point light makes
///    on the ceiling just above it (pure gathering had 15% RMS noise at 64 samples there).
///  - B, S/2 light paths: points y where rays from the light first hit the box (density
///    proportional to Ed), connected to x by a visibility ray. Good for the hot spot.
/// With MIS the noise at 64 samples is 4%, at 128 about 2%.
///
/// Samples: A uses a Hammersley set shifted per point id (Sampling.h), the same every frame.
/// B's light paths depend on the frame only: a per-frame pool of 64 shifted Hammersley sets of
/// S/2 directions from the light, traced once per frame and cached; point x uses set
/// hash(id) mod 64. So a point's value depends on its id and the frame alone, bit-identical
/// whether it is evaluated alone, among all points, at any thread count, and each point
/// traces only S/2 closest-hit rays of its own.
///
/// Thread safety: evaluate() is const and safe to call concurrently; it uses thread-local
/// scratch and a mutex-guarded cache of light-path pools (the last 16 frames). evaluateAll()
/// runs a tbb::parallel_for in the caller's task arena (limit threads with tbb::task_arena);
/// evaluate() itself is serial, so the engine's parallel fail-through branches do not
/// oversubscribe.
///
/// Also a FrameWriterProvider: `pmsc run` can write each frame as a lighting-cache .vdb
/// (LightingCacheGrid, grid "indirect" + "normal" + "surface_point").
class CornellEvaluator : public PointEvaluator, public FrameWriterProvider, public PointPositionsProvider {
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
    /// Traces each point's cosine-gather rays once for all of `frames` (they depend on the point
    /// alone) and shades them with each frame's light: the same values as evaluateAll() per frame,
    /// bit for bit, with strategy A's closest-hit rays paid once instead of once per frame.
    void evaluateAllFrames(std::span<const Index> frames, double* out) const override;
    /// 12: the gather rays' share of a frame falls to a twelfth (a row of the training rig).
    Index framesSharingWork() const override { return 12; }

    std::vector<std::shared_ptr<const FrameWriter>> frameWriters() const override;
    /// The gather points: each voxel's nearest surface point, in millimetres.
    FrameSet pointPositions() const override;

    const CornellWorld& world() const { return *world_; }
    const std::vector<PointLight>& lights() const { return lights_; }
    int samplesPerPoint() const { return samples_; }

    /// A point's cosine-gather rays and what they hit (scratch of evaluate and evaluateFrames).
    struct GatherRays {
        std::vector<Ray> rays;
        std::vector<Hit> hits;
    };

private:
    struct LightPool;
    std::shared_ptr<const LightPool> lightPool(Index frame) const;
    /// @throws std::out_of_range for a frame outside [0, frameCount()).
    void checkFrame(Index frame) const;
    void gather(const PointLight& light, const LightPool& pool, Index point, double* rgb) const;
    /// Strategy A's cosine-gather rays from `point` and their first hits: the frame's light
    /// plays no part in them.
    void traceGatherRays(Index point, GatherRays& g) const;
    /// One frame's estimate at `point` from its traced gather rays `g` and the frame's light paths.
    void shade(const PointLight& light, const LightPool& pool, Index point, const GatherRays& g,
               double* rgb) const;

    mutable std::mutex poolMutex_;
    mutable std::vector<std::pair<Index, std::shared_ptr<const LightPool>>> pools_;  // most recent last

    std::shared_ptr<const CornellWorld> world_;
    std::vector<PointLight> lights_;
    int samples_;
    std::string name_;
};

/// The parts of a `cornell` spec's OPTIONS (below). @throws pmsc::InputError naming a bad option.
struct CornellSpec {
    std::size_t points = 160000;
    int samples = 160;
    std::string lights = "all";  ///< all, training, scattered, path or outside
};
CornellSpec parseCornellSpec(const std::string& options);

/// The `cornell` evaluator of the command line (spec "cornell[:OPTIONS]"), OPTIONS a comma-separated
/// list of points=N (default 160000), samples=S (default 160) and lights=SET, SET one of
///   all (default): the 144 training lights, then 16 scattered validation lights, then the 60-frame
///                  path (frames 0-143, 144-159, 160-219), so one spec serves export-frames and run;
///   training | scattered | path: only that set, from frame 0;
///   outside: 24 lights outside the trained range (LightRig::outsideLights), not part of all.
/// @throws pmsc::InputError naming the bad option.
std::unique_ptr<CornellEvaluator> makeCornellEvaluator(const std::string& options);

}  // namespace pmsc::cornell
