#include "evaluators/cornell/CornellEvaluator.h"

#include "evaluators/cornell/LightingCacheGrid.h"
#include "evaluators/scene/Sampling.h"
#include "evaluators/scene/SpecOptions.h"
#include "evaluators/scene/VdbFrameWriter.h"
#include "pmsc/Errors.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <stdexcept>
#include <string>

namespace pmsc::cornell {

using scene::cosineDirection;
using scene::hammersleyShifted;
using scene::hash32;
using scene::orthonormalBasis;

namespace {

// Rays leave a surface this far along its normal, and stop this short of their target, so
// they neither hit their own surface nor the light's surroundings by float round-off
// (positions are < 600 mm, where a float's spacing is 6e-5 mm).
constexpr double kOffsetMm = 0.01;

struct Candidate {
    Vec3 y;
    int quad;
    bool fromGather;
};
struct Scratch {
    CornellEvaluator::GatherRays gatherRays;
    std::vector<Candidate> cand;
    std::vector<Ray> occ;
    std::vector<std::uint8_t> blocked;
};
Scratch& scratch() {
    thread_local Scratch s;
    return s;
}

}  // namespace

std::shared_ptr<const CornellWorld> CornellWorld::create(std::size_t points, TraceMode mode) {
    auto w = std::make_shared<CornellWorld>();
    w->scene = CornellScene::standard();
    w->tracer = std::make_shared<RayTracer>(w->scene, mode);
    w->voxels = SurfaceVoxels::voxelizeToCount(w->scene, points);
    return w;
}

std::shared_ptr<const CornellWorld> CornellWorld::withScene(const CornellWorld& base, CornellScene scene) {
    const auto& a = base.scene.quads();
    const auto& b = scene.quads();
    if (b.size() < a.size() || !std::equal(a.begin(), a.end(), b.begin(), [](const Quad& x, const Quad& y) {
            return x.name == y.name && x.area() == y.area();
        }))
        throw std::invalid_argument(
            "CornellWorld::withScene: the changed scene must begin with the base scene's quads");
    auto w = std::make_shared<CornellWorld>();
    w->scene = std::move(scene);
    w->tracer = std::make_shared<RayTracer>(w->scene, base.tracer->mode());
    w->voxels = base.voxels;
    return w;
}

void directIrradiance(const RayTracer& tracer, const PointLight& light, std::span<const Vec3> p,
                      std::span<const Vec3> n, double* out) {
    thread_local std::vector<Ray> rays;
    thread_local std::vector<std::uint8_t> blocked;
    const size_t m = p.size();
    rays.resize(m);
    blocked.assign(m, 0);
    for (size_t i = 0; i < m; ++i) {
        const Vec3 o = p[i] + n[i] * kOffsetMm;
        const Vec3 toLight = light.position - o;
        // tfar = 1 - eps in units of the (unnormalized) direction: stop just before the light.
        rays[i] = makeRay(o, toLight, 1.0 - 1e-4);
    }
    tracer.occluded(rays, blocked);
    for (size_t i = 0; i < m; ++i) {
        const Vec3 toLight = light.position - p[i];
        const double r2 = dot(toLight, toLight);
        const double cosine = dot(n[i], toLight) / std::sqrt(r2);
        const double g = (blocked[i] || cosine <= 0) ? 0.0 : cosine / r2;
        for (int c = 0; c < 3; ++c) out[3 * i + c] = light.intensity[c] * g;
    }
}

CornellEvaluator::CornellEvaluator(std::shared_ptr<const CornellWorld> world, std::vector<PointLight> lights,
                                   int samplesPerPoint, std::string name)
    : world_(std::move(world)),
      lights_(std::move(lights)),
      samples_(samplesPerPoint),
      name_(std::move(name)) {
    if (!world_) throw std::invalid_argument("CornellEvaluator: no world");
    if (lights_.empty()) throw std::invalid_argument("CornellEvaluator: no lights (frames)");
    if (samples_ < 1)
        throw std::invalid_argument("CornellEvaluator: samples per point must be >= 1, got " +
                                    std::to_string(samples_));
}

/// The light paths of one frame: kPoolSets shifted Hammersley sets of sB directions from the
/// light, traced to their first hit. Entry (set, i) is valid when it hit a front face.
struct CornellEvaluator::LightPool {
    std::uint32_t sets = 0, perSet = 0;
    std::vector<Vec3> y;
    std::vector<int> quad;  // -1: missed or back face
};

namespace {
constexpr std::uint32_t kPoolSets = 64;
constexpr std::size_t kPoolCache = 16;
}  // namespace

std::shared_ptr<const CornellEvaluator::LightPool> CornellEvaluator::lightPool(Index frame) const {
    {
        std::lock_guard<std::mutex> lock(poolMutex_);
        for (const auto& [f, p] : pools_)
            if (f == frame) return p;
    }
    // Built outside the lock: two threads may build the same pool; both results are identical.
    auto pool = std::make_shared<LightPool>();
    const PointLight& light = lights_[static_cast<std::size_t>(frame)];
    pool->sets = kPoolSets;
    pool->perSet = static_cast<std::uint32_t>(samples_ / 2);
    const std::size_t n = static_cast<std::size_t>(pool->sets) * pool->perSet;
    std::vector<Ray> rays(n);
    std::vector<Hit> hits(n);
    for (std::uint32_t set = 0; set < pool->sets; ++set)
        for (std::uint32_t i = 0; i < pool->perSet; ++i) {
            double u, v;
            hammersleyShifted(set ^ 0x5bd1e995U, i, pool->perSet, u, v);
            const double z = 1.0 - 2.0 * u, r = std::sqrt(std::max(0.0, 1.0 - z * z)), phi = 2.0 * M_PI * v;
            rays[set * pool->perSet + i] =
                makeRay(light.position, {r * std::cos(phi), r * std::sin(phi), z}, 1e30);
        }
    // Traced in fixed batches of one set, so the pool never depends on how it was scheduled.
    for (std::uint32_t set = 0; set < pool->sets && pool->perSet > 0; ++set)
        world_->tracer->intersect(
            std::span<const Ray>(rays.data() + static_cast<std::size_t>(set) * pool->perSet, pool->perSet),
            std::span<Hit>(hits.data() + static_cast<std::size_t>(set) * pool->perSet, pool->perSet));
    pool->y.resize(n);
    pool->quad.assign(n, -1);
    const auto& quads = world_->scene.quads();
    for (std::size_t k = 0; k < n; ++k) {
        if (hits[k].quad < 0) continue;
        const Quad& q = quads[static_cast<std::size_t>(hits[k].quad)];
        const Vec3 d{rays[k].dir[0], rays[k].dir[1], rays[k].dir[2]};
        if (dot(d, q.normal) >= 0) continue;
        pool->y[k] = light.position + d * static_cast<double>(hits[k].t);
        pool->quad[k] = hits[k].quad;
    }
    std::lock_guard<std::mutex> lock(poolMutex_);
    for (const auto& [f, p] : pools_)
        if (f == frame) return p;
    if (pools_.size() >= kPoolCache) pools_.erase(pools_.begin());
    pools_.emplace_back(frame, pool);
    return pool;
}

void CornellEvaluator::traceGatherRays(Index point, GatherRays& g) const {
    const SurfaceVoxels& vox = world_->voxels;
    const Vec3 nx = vox.normal[static_cast<size_t>(point)];
    Vec3 t, b;
    orthonormalBasis(nx, t, b);
    const Vec3 o = vox.position[static_cast<size_t>(point)] + nx * kOffsetMm;
    const auto id = static_cast<std::uint32_t>(point);
    const auto sA = static_cast<std::uint32_t>(samples_ / 2 + samples_ % 2);
    g.rays.resize(sA);
    g.hits.resize(sA);
    for (std::uint32_t i = 0; i < sA; ++i) {
        double u, v;
        hammersleyShifted(id, i, sA, u, v);
        g.rays[i] = makeRay(o, cosineDirection(nx, t, b, u, v), 1e30);
    }
    world_->tracer->intersect(g.rays, g.hits);
}

void CornellEvaluator::gather(const PointLight& light, const LightPool& pool, Index point,
                              double* rgb) const {
    Scratch& s = scratch();
    traceGatherRays(point, s.gatherRays);
    shade(light, pool, point, s.gatherRays, rgb);
}

void CornellEvaluator::shade(const PointLight& light, const LightPool& pool, Index point, const GatherRays& g,
                             double* rgb) const {
    const SurfaceVoxels& vox = world_->voxels;
    const auto& quads = world_->scene.quads();
    const Vec3 x = vox.position[static_cast<size_t>(point)];
    const Vec3 nx = vox.normal[static_cast<size_t>(point)];
    const Vec3 o = x + nx * kOffsetMm;
    const Vec3 lp = light.position;
    const auto id = static_cast<std::uint32_t>(point);
    const auto sA = static_cast<std::uint32_t>(g.rays.size());
    const double nA = sA, nB = pool.perSet;  // cosine gathers, light paths
    Scratch& s = scratch();

    // Candidates y: A = cosine-gather hits (need a shadow ray y -> light), B = this point's set
    // of the frame's light paths (need a connection ray x -> y). One occlusion batch for both.
    s.cand.clear();
    s.occ.clear();
    for (std::uint32_t i = 0; i < sA; ++i) {
        const Hit& h = g.hits[i];
        if (h.quad < 0) continue;
        const Quad& q = quads[static_cast<size_t>(h.quad)];
        const Ray& ray = g.rays[i];
        const Vec3 d{ray.dir[0], ray.dir[1], ray.dir[2]};
        if (dot(d, q.normal) >= 0) continue;  // back face: nothing leaves it toward x
        const Vec3 y = o + d * static_cast<double>(h.t);
        const Vec3 yo = y + q.normal * kOffsetMm;
        const Vec3 toLight = lp - yo;
        if (dot(q.normal, toLight) <= 0) continue;
        s.cand.push_back({y, h.quad, true});
        s.occ.push_back(makeRay(yo, toLight, 1.0 - 1e-4));
    }
    const std::size_t first = static_cast<std::size_t>(hash32(id ^ 0x27d4eb2fU) % pool.sets) * pool.perSet;
    for (std::uint32_t i = 0; i < pool.perSet; ++i) {
        const int qi = pool.quad[first + i];
        if (qi < 0) continue;
        const Quad& q = quads[static_cast<size_t>(qi)];
        const Vec3 y = pool.y[first + i];
        const Vec3 toY = y + q.normal * kOffsetMm - o;
        if (dot(nx, toY) <= 0 || dot(q.normal, toY) >= 0) continue;
        s.cand.push_back({y, qi, false});
        s.occ.push_back(makeRay(o, toY, 1.0 - 1e-4));
    }
    s.blocked.assign(s.occ.size(), 0);
    world_->tracer->occluded(s.occ, s.blocked);

    // Multiple importance sampling, balance heuristic, area measure: every unblocked candidate
    // adds f(y) / (nA pA(y) + nB pB(y)), with
    //   f(y)  = albedo(y)/pi * Ed(y) * G(x,y),  G = cos_x cos_y / |x-y|^2, Ed = I cos_yl / |l-y|^2
    //   pA(y) = G / pi                 (cosine gather from x, converted to area)
    //   pB(y) = cos_yl / (4 pi |l-y|^2) (uniform emission from the light, converted to area)
    // Both strategies reach the same y only if y sees both x and the light, which the other
    // strategy's ray would have to test; A's candidates are visible from x by construction and B's
    // from the light, so the missing visibility is the one ray traced above.
    double sum[3] = {0, 0, 0};
    for (size_t j = 0; j < s.cand.size(); ++j) {
        if (s.blocked[j]) continue;
        const Candidate& c = s.cand[j];
        const Quad& q = quads[static_cast<size_t>(c.quad)];
        const Vec3 xy = c.y - x;
        const double r2 = dot(xy, xy);
        const double r = std::sqrt(r2);
        const double cosX = dot(nx, xy) / r;
        const double cosY = -dot(q.normal, xy) / r;
        if (cosX <= 0 || cosY <= 0) continue;
        const Vec3 yl = lp - c.y;
        const double l2 = dot(yl, yl);
        const double cosL = dot(q.normal, yl) / std::sqrt(l2);
        if (cosL <= 0) continue;
        const double g = cosX * cosY / r2;
        const double pA = g / M_PI;
        const double pB = cosL / (4.0 * M_PI * l2);
        const double k = 1.0 / M_PI * (cosL / l2) * g / (nA * pA + nB * pB);
        for (int ch = 0; ch < 3; ++ch) sum[ch] += q.albedo[ch] * light.intensity[ch] * k;
    }
    for (int ch = 0; ch < 3; ++ch) rgb[ch] = sum[ch];
}

void CornellEvaluator::checkFrame(Index frame) const {
    if (frame < 0 || frame >= frameCount())
        throw std::out_of_range("cornell: frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(frameCount()) + ")");
}

void CornellEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    checkFrame(frame);
    const Index n = pointCount();
    const PointLight& light = lights_[static_cast<size_t>(frame)];
    const auto pool = lightPool(frame);
    for (size_t i = 0; i < points.size(); ++i) {
        if (points[i] < 0 || points[i] >= n)
            throw std::out_of_range("cornell: point " + std::to_string(points[i]) + " outside [0, " +
                                    std::to_string(n) + ")");
        gather(light, *pool, points[i], out + 3 * i);
    }
}

void CornellEvaluator::evaluateAll(Index frame, double* out) const {
    const Index one[1] = {frame};
    evaluateAllFrames(one, out);
}

void CornellEvaluator::evaluateAllFrames(std::span<const Index> frames, double* out) const {
    std::vector<std::shared_ptr<const LightPool>> pools;
    pools.reserve(frames.size());
    for (const Index frame : frames) {
        checkFrame(frame);
        pools.push_back(lightPool(frame));
    }
    const Index n = pointCount();
    tbb::parallel_for(tbb::blocked_range<Index>(0, n, 256), [&](const tbb::blocked_range<Index>& r) {
        GatherRays g;
        for (Index p = r.begin(); p != r.end(); ++p) {
            traceGatherRays(p, g);
            for (std::size_t k = 0; k < frames.size(); ++k)
                shade(lights_[static_cast<std::size_t>(frames[k])], *pools[k], p, g,
                      out + 3 * (static_cast<std::size_t>(n) * k + static_cast<std::size_t>(p)));
        }
    });
}

// One frame of the cache as a .vdb file. Its state is "soft-cached": `pmsc run` hands the writer the
// soft-cached values without the decision, so the file says what it knows.
FrameSet CornellEvaluator::pointPositions() const { return scene::positionsFrame(world_->voxels.position); }

std::vector<std::shared_ptr<const FrameWriter>> CornellEvaluator::frameWriters() const {
    const SurfaceVoxels& voxels = world().voxels;
    auto write = [this, &voxels](const std::string& path, Index frame, const double* values) {
        const PointLight& light = lights().at(static_cast<std::size_t>(frame));
        CacheMetadata meta{static_cast<std::int32_t>(frame), light.position, "soft-cached", -1, 0};
        LightingCacheGrid(voxels, std::span<const double>(values, 3 * voxels.size()), meta).writeTo(path);
    };
    auto activeVoxels = [](const std::string& path) {
        return LightingCacheGrid::read(path).activeVoxelCount();
    };
    return {std::make_shared<scene::VdbFrameWriter>(static_cast<std::int64_t>(voxels.size()), write,
                                                    activeVoxels)};
}

CornellSpec parseCornellSpec(const std::string& options) {
    CornellSpec spec;
    std::stringstream in(options);
    std::string item;
    while (std::getline(in, item, ',')) {
        if (item.empty()) continue;
        const auto eq = item.find('=');
        const std::string key = item.substr(0, eq),
                          value = eq == std::string::npos ? "" : item.substr(eq + 1);
        auto number = [&](long lo, long hi) { return scene::integerOption("cornell", key, value, lo, hi); };
        if (key == "points") {
            spec.points = static_cast<std::size_t>(number(1000, 4000000));
        } else if (key == "samples") {
            spec.samples = static_cast<int>(number(2, 65536));
        } else if (key == "lights") {
            if (value != "all" && value != "training" && value != "scattered" && value != "path" &&
                value != "outside")
                throw InputError("evaluator 'cornell': lights='" + value +
                                 "' is not all, training, scattered, path or outside");
            spec.lights = value;
        } else {
            throw InputError("evaluator 'cornell': unknown option '" + key +
                             "' (points=N, samples=S, lights=SET)");
        }
    }
    return spec;
}

std::unique_ptr<CornellEvaluator> makeCornellEvaluator(const std::string& options) {
    const CornellSpec spec = parseCornellSpec(options);
    const std::string& lights = spec.lights;
    const LightRig rig;
    std::vector<PointLight> set;
    auto add = [&](const std::vector<PointLight>& l) { set.insert(set.end(), l.begin(), l.end()); };
    if (lights == "all" || lights == "training") add(rig.trainingLights());
    if (lights == "all" || lights == "scattered") add(rig.scatteredLights(16));
    if (lights == "all" || lights == "path") add(rig.animationPath(60));
    if (lights == "outside") add(rig.outsideLights());
    return std::make_unique<CornellEvaluator>(CornellWorld::create(spec.points), std::move(set), spec.samples,
                                              "cornell");
}

}  // namespace pmsc::cornell
