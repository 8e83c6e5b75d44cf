#include "examples/cornell/Renderer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pmsc::cornell {

std::vector<Image> renderWithCaches(const CornellWorld& world, const Camera& camera, const PointLight& light,
                                    const std::vector<const LightingCacheGrid*>& caches, int size) {
    if (size < 1) throw std::invalid_argument("render: image size must be positive");
    std::vector<Image> images(caches.size(), Image(size, size));
    const Vec3 forward = normalize(camera.target - camera.eye);
    const Vec3 right = normalize(cross(forward, camera.up));
    const Vec3 up = cross(right, forward);
    const double tanHalf = std::tan(0.5 * camera.fovYDegrees * M_PI / 180.0);
    const auto& quads = world.scene.quads();
    constexpr int kSub = 2;  // kSub x kSub stratified samples per pixel

    tbb::parallel_for(tbb::blocked_range<int>(0, size, 4), [&](const tbb::blocked_range<int>& rows) {
        const int m = size * kSub * kSub;
        std::vector<Ray> rays(static_cast<size_t>(m));
        std::vector<Hit> hits(static_cast<size_t>(m));
        std::vector<Vec3> p, n;
        std::vector<int> pixelOf, quadOf;
        std::vector<double> direct, indirect;
        for (int y = rows.begin(); y != rows.end(); ++y) {
            for (int x = 0; x < size; ++x)
                for (int s = 0; s < kSub * kSub; ++s) {
                    const double sx = (x + (s % kSub + 0.5) / kSub) / size * 2.0 - 1.0;
                    const double sy = 1.0 - (y + (s / kSub + 0.5) / kSub) / size * 2.0;
                    const Vec3 d = normalize(forward + right * (sx * tanHalf) + up * (sy * tanHalf));
                    rays[static_cast<size_t>(x * kSub * kSub + s)] = makeRay(camera.eye, d, 1e30);
                }
            world.tracer->intersect(rays, hits);
            p.clear();
            n.clear();
            pixelOf.clear();
            quadOf.clear();
            for (int i = 0; i < m; ++i) {
                const Hit& h = hits[static_cast<size_t>(i)];
                if (h.quad < 0) continue;
                const Quad& q = quads[static_cast<size_t>(h.quad)];
                const Vec3 d{rays[i].dir[0], rays[i].dir[1], rays[i].dir[2]};
                if (dot(d, q.normal) >= 0) continue;  // back face: black
                p.push_back(camera.eye + d * static_cast<double>(h.t));
                n.push_back(q.normal);
                pixelOf.push_back(i / (kSub * kSub));
                quadOf.push_back(h.quad);
            }
            direct.resize(3 * p.size());
            indirect.resize(3 * p.size());
            directIrradiance(*world.tracer, light, p, n, direct.data());
            const float w = 1.0f / (kSub * kSub);
            for (size_t c = 0; c < caches.size(); ++c) {
                caches[c]->sample(p, n, indirect.data());
                for (size_t j = 0; j < p.size(); ++j) {
                    const Rgb& albedo = quads[static_cast<size_t>(quadOf[j])].albedo;
                    float* px = images[c].pixel(pixelOf[j], y);
                    for (int k = 0; k < 3; ++k)
                        // A PM reconstruction may undershoot a dark voxel slightly below zero; light
                        // is never negative, so the lookup is clamped (the cache keeps the raw values).
                        px[k] +=
                            w * static_cast<float>(albedo[k] / M_PI *
                                                   (direct[3 * j + k] + std::max(0.0, indirect[3 * j + k])));
                }
            }
        }
    });
    return images;
}

}  // namespace pmsc::cornell
