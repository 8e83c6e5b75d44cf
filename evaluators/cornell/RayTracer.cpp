// The one translation unit that includes Embree (its headers are heavy; see STYLE.md).
#include "evaluators/cornell/RayTracer.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace pmsc::cornell {

struct RayTracer::Impl {
    RTCDevice device = nullptr;
    RTCScene scene = nullptr;

    ~Impl() {
        if (scene) rtcReleaseScene(scene);
        if (device) rtcReleaseDevice(device);
    }
};

namespace {

void throwOnError(RTCDevice device, const char* what) {
    const RTCError err = rtcGetDeviceError(device);
    if (err != RTC_ERROR_NONE)
        throw std::runtime_error(std::string("cornell: Embree failed in ") + what + " (error " +
                                 std::to_string(static_cast<int>(err)) + ")");
}

void toEmbree(const Ray& r, RTCRay& e) {
    e.org_x = r.org[0];
    e.org_y = r.org[1];
    e.org_z = r.org[2];
    e.tnear = r.tnear;
    e.dir_x = r.dir[0];
    e.dir_y = r.dir[1];
    e.dir_z = r.dir[2];
    e.time = 0;
    e.tfar = r.tfar;
    e.mask = 0xFFFFFFFFu;
    e.id = 0;
    e.flags = 0;
}

// Batches go through a thread-local buffer: no allocation per call after warm-up.
constexpr size_t kChunk = 256;

/// Fills a packet of 8 from rays[first, first + m), m <= 8; lanes past m repeat the last ray
/// and are masked off in `valid`.
void packRays8(std::span<const Ray> rays, size_t first, size_t m, RTCRay8& p, int* valid) {
    for (size_t i = 0; i < 8; ++i) {
        valid[i] = i < m ? -1 : 0;
        const Ray& r = rays[first + std::min(i, m - 1)];
        p.org_x[i] = r.org[0];
        p.org_y[i] = r.org[1];
        p.org_z[i] = r.org[2];
        p.dir_x[i] = r.dir[0];
        p.dir_y[i] = r.dir[1];
        p.dir_z[i] = r.dir[2];
        p.tnear[i] = r.tnear;
        p.tfar[i] = r.tfar;
        p.time[i] = 0;
        p.mask[i] = 0xFFFFFFFFu;
        p.id[i] = 0;
        p.flags[i] = 0;
    }
}

Hit toHit(float tfar, unsigned geomID, unsigned primID) {
    return {tfar, geomID == RTC_INVALID_GEOMETRY_ID ? -1 : static_cast<int>(primID)};
}

}  // namespace

RayTracer::RayTracer(const CornellScene& scene, TraceMode mode)
    : impl_(std::make_unique<Impl>()), mode_(mode) {
    // No "threads=N" in the configuration: Debian's Embree 3 runs on oneTBB, and a thread count
    // makes it install tbb::global_control(max_allowed_parallelism, N) for the whole process while
    // the device lives. "threads=1" once did exactly that and silently ran every parallel_for and
    // the engine's flow graph on one core. With the default, Embree leaves oneTBB alone; the
    // callers' arenas (the engine's, the demo's) decide how many threads trace.
    impl_->device = rtcNewDevice("set_affinity=0");
    if (!impl_->device) throw std::runtime_error("cornell: cannot create an Embree device");
    impl_->scene = rtcNewScene(impl_->device);
    rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);

    const auto& quads = scene.quads();
    RTCGeometry geom = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_QUAD);
    auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 4 * quads.size()));
    auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, 4 * sizeof(unsigned), quads.size()));
    for (size_t q = 0; q < quads.size(); ++q) {
        for (int c = 0; c < 4; ++c) {
            vertices[3 * (4 * q + c) + 0] = static_cast<float>(quads[q].corners[c].x);
            vertices[3 * (4 * q + c) + 1] = static_cast<float>(quads[q].corners[c].y);
            vertices[3 * (4 * q + c) + 2] = static_cast<float>(quads[q].corners[c].z);
            indices[4 * q + c] = static_cast<unsigned>(4 * q + c);
        }
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(impl_->scene, geom, 0);
    rtcReleaseGeometry(geom);
    rtcCommitScene(impl_->scene);
    throwOnError(impl_->device, "building the scene");
}

RayTracer::~RayTracer() = default;

void RayTracer::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    if (hits.size() < rays.size()) throw std::invalid_argument("RayTracer::intersect: hits too small");
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    const size_t n = rays.size();
    if (mode_ == TraceMode::Single) {
        for (size_t i = 0; i < n; ++i) {
            RTCRayHit rh;
            toEmbree(rays[i], rh.ray);
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(impl_->scene, &ctx, &rh);
            hits[i] = toHit(rh.ray.tfar, rh.hit.geomID, rh.hit.primID);
        }
    } else if (mode_ == TraceMode::Stream) {
        thread_local std::vector<RTCRayHit> buf(kChunk);
        for (size_t first = 0; first < n; first += kChunk) {
            const size_t m = std::min(kChunk, n - first);
            for (size_t i = 0; i < m; ++i) {
                toEmbree(rays[first + i], buf[i].ray);
                buf[i].hit.geomID = RTC_INVALID_GEOMETRY_ID;
            }
            rtcIntersect1M(impl_->scene, &ctx, buf.data(), static_cast<unsigned>(m), sizeof(RTCRayHit));
            for (size_t i = 0; i < m; ++i) {
                hits[first + i] = toHit(buf[i].ray.tfar, buf[i].hit.geomID, buf[i].hit.primID);
            }
        }
    } else {
        alignas(32) RTCRayHit8 p;
        alignas(32) int valid[8];
        for (size_t first = 0; first < n; first += 8) {
            const size_t m = std::min<size_t>(8, n - first);
            packRays8(rays, first, m, p.ray, valid);
            for (size_t i = 0; i < 8; ++i) p.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect8(valid, impl_->scene, &ctx, &p);
            for (size_t i = 0; i < m; ++i)
                hits[first + i] = toHit(p.ray.tfar[i], p.hit.geomID[i], p.hit.primID[i]);
        }
    }
}

void RayTracer::occluded(std::span<const Ray> rays, std::span<std::uint8_t> blocked) const {
    if (blocked.size() < rays.size()) throw std::invalid_argument("RayTracer::occluded: blocked too small");
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    const size_t n = rays.size();
    // Embree marks an occluded ray by setting tfar to -inf.
    if (mode_ == TraceMode::Single) {
        for (size_t i = 0; i < n; ++i) {
            RTCRay r;
            toEmbree(rays[i], r);
            rtcOccluded1(impl_->scene, &ctx, &r);
            blocked[i] = r.tfar < 0 ? 1 : 0;
        }
    } else if (mode_ == TraceMode::Stream) {
        thread_local std::vector<RTCRay> buf(kChunk);
        for (size_t first = 0; first < n; first += kChunk) {
            const size_t m = std::min(kChunk, n - first);
            for (size_t i = 0; i < m; ++i) toEmbree(rays[first + i], buf[i]);
            rtcOccluded1M(impl_->scene, &ctx, buf.data(), static_cast<unsigned>(m), sizeof(RTCRay));
            for (size_t i = 0; i < m; ++i) blocked[first + i] = buf[i].tfar < 0 ? 1 : 0;
        }
    } else {
        alignas(32) RTCRay8 p;
        alignas(32) int valid[8];
        for (size_t first = 0; first < n; first += 8) {
            const size_t m = std::min<size_t>(8, n - first);
            packRays8(rays, first, m, p, valid);
            rtcOccluded8(valid, impl_->scene, &ctx, &p);
            for (size_t i = 0; i < m; ++i) blocked[first + i] = p.tfar[i] < 0 ? 1 : 0;
        }
    }
}

}  // namespace pmsc::cornell
