#include "examples/volume/VolumeRenderer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <memory>
#include <stdexcept>

namespace pmsc::volume {

std::vector<Camera> volumeCameras(const VolumeWorld& w, double t) {
    const double r = w.radius;
    auto orbit = [&](double azDeg, double elDeg, double dist) {
        const double a = azDeg * M_PI / 180, e = elDeg * M_PI / 180;
        return w.centre +
               Vec3{std::cos(e) * std::cos(a), std::sin(e), std::cos(e) * std::sin(a)} * (dist * r);
    };
    Camera front{"front", orbit(-100 + 40 * t, 8, 1.9), w.centre, {0, 1, 0}, 45};
    Camera above{"above", orbit(-40 + 30 * t, 55, 1.9), w.centre, {0, 1, 0}, 45};
    const double look = (200 + 70 * t) * M_PI / 180;
    const Vec3 eye = w.centre + Vec3{0.08 * r, -0.05 * r, 0.05 * r};
    Camera inside{"inside", eye, eye + Vec3{std::cos(look), 0.1, std::sin(look)}, {0, 1, 0}, 75};
    return {front, above, inside};
}

std::vector<Image> renderVolume(const VolumeWorld& world, const Camera& camera,
                                const std::vector<const ScatterCache*>& caches, int size) {
    if (size < 1) throw std::invalid_argument("render: image size must be positive");
    std::vector<Image> images(caches.size(), Image(size, size));
    const Vec3 forward = scene::normalize(camera.target - camera.eye);
    const Vec3 right = scene::normalize(scene::cross(forward, camera.up));
    const Vec3 up = scene::cross(right, forward);
    const double tanHalf = std::tan(0.5 * camera.fovYDegrees * M_PI / 180.0);
    const double sigmaT = world.medium.sigmaT;
    const Rgb albedo = world.medium.albedo;
    const double dt = 0.5 * world.density.voxelSize();
    const double tMax = 4 * (scene::length(camera.eye - world.centre) + world.radius);

    tbb::parallel_for(tbb::blocked_range<int>(0, size, 2), [&](const tbb::blocked_range<int>& rows) {
        DensityVolume::Tracer tracer(world.density);
        std::vector<std::unique_ptr<ScatterCache::Sampler>> samplers;
        for (const ScatterCache* c : caches) samplers.push_back(std::make_unique<ScatterCache::Sampler>(*c));
        std::vector<std::pair<double, double>> spans;
        std::vector<Rgb> radiance(caches.size());
        for (int y = rows.begin(); y != rows.end(); ++y) {
            for (int x = 0; x < size; ++x) {
                const double sx = (x + 0.5) / size * 2.0 - 1.0, sy = 1.0 - (y + 0.5) / size * 2.0;
                const Vec3 d = scene::normalize(forward + right * (sx * tanHalf) + up * (sy * tanHalf));
                tracer.spans(camera.eye, d, tMax, spans);
                for (auto& l : radiance) l = {0, 0, 0};
                double trans = 1;
                for (const auto& [t0, t1] : spans) {
                    const int n = std::max(1, static_cast<int>(std::ceil((t1 - t0) / dt)));
                    const double h = (t1 - t0) / n;
                    for (int i = 0; i < n && trans > 1e-4; ++i) {
                        const Vec3 p = camera.eye + d * (t0 + (i + 0.5) * h);
                        const double sigma = sigmaT * tracer.density(p);
                        if (sigma <= 0) continue;
                        const double absorbed = trans * (1 - std::exp(-sigma * h));
                        for (std::size_t c = 0; c < caches.size(); ++c) {
                            const Rgb lin = samplers[c]->at(p);
                            // A PM reconstruction may undershoot a dark voxel slightly below zero;
                            // light is never negative, so the lookup is clamped (the cache keeps it).
                            for (int k = 0; k < 3; ++k)
                                radiance[c][k] += absorbed * albedo[k] * std::max(0.0, lin[k]);
                        }
                        trans *= std::exp(-sigma * h);
                    }
                    if (trans <= 1e-4) break;
                }
                for (std::size_t c = 0; c < caches.size(); ++c) {
                    float* px = images[c].pixel(x, y);
                    for (int k = 0; k < 3; ++k) px[k] = static_cast<float>(radiance[c][k]);
                }
            }
        }
    });
    return images;
}

}  // namespace pmsc::volume
