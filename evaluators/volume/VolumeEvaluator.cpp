#include "evaluators/volume/VolumeEvaluator.h"

#include "evaluators/scene/Sampling.h"
#include "evaluators/scene/SpecOptions.h"
#include "evaluators/scene/VdbFrameWriter.h"
#include "pmsc/Errors.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <stdexcept>

namespace pmsc::volume {

Rgb kelvinToRgb(double kelvin) {
    if (!(kelvin >= 1000 && kelvin <= 40000))
        throw std::invalid_argument("colour temperature " + std::to_string(kelvin) +
                                    " K outside [1000, 40000]");
    constexpr double c2 = 1.4387769e-2;  // second radiation constant hc/k, m K
    auto planck = [&](double nm) {
        const double l = nm * 1e-9;
        return 1.0 / (std::pow(l, 5) * (std::exp(c2 / (l * kelvin)) - 1.0));
    };
    Rgb c{planck(610), planck(550), planck(465)};
    const double y = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    for (double& v : c) v /= y;
    return c;
}

std::shared_ptr<const VolumeWorld> VolumeWorld::create(DensityVolume density, MediumSettings medium,
                                                       std::string source) {
    auto w = std::make_shared<VolumeWorld>(VolumeWorld{std::move(density), medium, {}, 0, std::move(source)});
    const auto [lo, hi] = w->density.worldBounds();
    w->centre = (lo + hi) * 0.5;
    const Vec3 ext = hi - lo;
    w->radius = std::max(0.5 * scene::length(ext), 2 * w->density.voxelSize());
    if (!(w->medium.sigmaT > 0))
        w->medium.sigmaT = 16.0 / std::max({ext.x, ext.y, ext.z, w->density.voxelSize()});
    if (w->medium.lightSamples < 1 || !(w->medium.stepVoxels > 0) || w->medium.octaves < 0)
        throw InputError("volume: light samples, march step or octaves out of range");
    return w;
}

VolumeLight VolumeRig::light(const VolumeWorld& world, double azimuthDeg, double elevationDeg,
                             double kelvin) const {
    const double a = azimuthDeg * M_PI / 180, e = elevationDeg * M_PI / 180;
    const double d = distance * world.radius;
    VolumeLight l;
    l.position = world.centre + Vec3{std::cos(e) * std::cos(a), std::sin(e), std::cos(e) * std::sin(a)} * d;
    l.radius = lightRadius * world.radius;
    l.kelvin = kelvin;
    // Radiant intensity for an unshadowed irradiance of 1 (luminance) at the medium's centre.
    const Rgb c = kelvinToRgb(kelvin);
    for (int k = 0; k < 3; ++k) l.intensity[k] = c[k] * d * d;
    return l;
}

namespace {

constexpr double kDeg = M_PI / 180;

Vec3 direction(double azimuthDeg, double elevationDeg) {
    const double a = azimuthDeg * kDeg, e = elevationDeg * kDeg;
    return {std::cos(e) * std::cos(a), std::sin(e), std::cos(e) * std::sin(a)};
}

/// Azimuth and elevation (degrees) of the i-th of n spiral positions, even in area over the band.
std::pair<double, double> spiralPosition(int i, int n, double eLo, double eHi) {
    const double zLo = std::sin(eLo * kDeg), zHi = std::sin(eHi * kDeg);
    const double z = zLo + (zHi - zLo) * (i + 0.5) / n;
    const double golden = 180.0 * (3.0 - std::sqrt(5.0));  // degrees
    return {std::fmod(golden * i, 360.0), std::asin(z) / kDeg};
}

double angleBetween(const Vec3& a, const Vec3& b) {
    return std::acos(std::clamp(a.x * b.x + a.y * b.y + a.z * b.z, -1.0, 1.0));
}

}  // namespace

std::vector<Vec3> VolumeRig::trainingDirections() const {
    std::vector<Vec3> out;
    if (spiral > 0) {
        for (int i = 0; i < spiral; ++i) {
            const auto [a, e] = spiralPosition(i, spiral, elevations.front(), elevations.back());
            out.push_back(direction(a, e));
        }
        return out;
    }
    for (std::size_t e = 0; e < elevations.size(); ++e)
        for (int a = 0; a < azimuths; ++a)
            for (int c = 0; c < (colourPairs ? 2 : 1); ++c)
                out.push_back(direction(360.0 * a / azimuths, elevations[e]));
    return out;
}

std::vector<VolumeLight> VolumeRig::training(const VolumeWorld& world) const {
    std::vector<VolumeLight> out;
    if (spiral > 0) {
        const int k = std::max(1, colours);
        for (int i = 0; i < spiral; ++i) {
            const auto [a, e] = spiralPosition(i, spiral, elevations.front(), elevations.back());
            const double kelvin =
                k == 1 ? kelvinLow : kelvinLow + (kelvinHigh - kelvinLow) * (i % k) / (k - 1);
            out.push_back(light(world, a, e, kelvin));
        }
        return out;
    }
    for (std::size_t e = 0; e < elevations.size(); ++e)
        for (int a = 0; a < azimuths; ++a)
            if (colourPairs) {
                for (double k : {kelvinLow, kelvinHigh})
                    out.push_back(light(world, 360.0 * a / azimuths, elevations[e], k));
            } else {
                out.push_back(
                    light(world, 360.0 * a / azimuths, elevations[e], (a + e) % 2 ? kelvinHigh : kelvinLow));
            }
    return out;
}

std::vector<VolumeLight> VolumeRig::between(const VolumeWorld& world, int count) const {
    std::mt19937 rng(20130711);
    std::vector<VolumeLight> out;
    if (spiral > 0) {
        // The holes: among random candidates even in area over the band, repeatedly the one
        // farthest from every training position and every hole already taken.
        std::vector<Vec3> taken = trainingDirections();
        std::uniform_real_distribution<double> u(0, 1);
        const double zLo = std::sin(elevations.front() * kDeg), zHi = std::sin(elevations.back() * kDeg);
        std::vector<std::pair<double, double>> candidates(4096);
        for (auto& [a, e] : candidates) {
            a = 360.0 * u(rng);
            e = std::asin(zLo + (zHi - zLo) * u(rng)) / kDeg;
        }
        std::vector<double> nearest(candidates.size(), 1e9);
        auto update = [&](const Vec3& d) {
            for (std::size_t c = 0; c < candidates.size(); ++c)
                nearest[c] = std::min(nearest[c],
                                      angleBetween(d, direction(candidates[c].first, candidates[c].second)));
        };
        for (const Vec3& d : taken) update(d);
        std::uniform_real_distribution<double> k(0.25, 0.75);
        for (int i = 0; i < count; ++i) {
            const auto best =
                static_cast<std::size_t>(std::max_element(nearest.begin(), nearest.end()) - nearest.begin());
            const auto [a, e] = candidates[best];
            out.push_back(light(world, a, e, kelvinLow + k(rng) * (kelvinHigh - kelvinLow)));
            update(direction(a, e));
        }
        return out;
    }
    std::uniform_int_distribution<int> az(0, azimuths - 1);
    std::uniform_int_distribution<int> el(0, std::max(0, static_cast<int>(elevations.size()) - 2));
    std::uniform_real_distribution<double> u(0.25, 0.75);
    for (int i = 0; i < count; ++i) {
        const double a = 360.0 * (az(rng) + 0.5) / azimuths;
        const std::size_t e = static_cast<std::size_t>(el(rng));
        const double elev = elevations.size() > 1 ? 0.5 * (elevations[e] + elevations[e + 1]) : elevations[0];
        out.push_back(light(world, a, elev, kelvinLow + u(rng) * (kelvinHigh - kelvinLow)));
    }
    return out;
}

std::vector<VolumeLight> VolumeRig::path(const VolumeWorld& world, int frames) const {
    std::vector<VolumeLight> out;
    const double eLo = elevations.front(), eHi = elevations.back();
    for (int f = 0; f < frames; ++f) {
        const double t = frames > 1 ? static_cast<double>(f) / frames : 0.0;
        const double a = 20.0 + 360.0 * t;
        const double e = eLo + (eHi - eLo) * (0.5 - 0.45 * std::cos(2 * M_PI * 1.5 * t));
        const double k =
            0.5 * (kelvinLow + kelvinHigh) + 0.45 * (kelvinHigh - kelvinLow) * std::sin(2 * M_PI * 2 * t);
        out.push_back(light(world, a, e, k));
    }
    return out;
}

std::vector<VolumeLight> VolumeRig::outside(const VolumeWorld& world) const {
    std::vector<VolumeLight> out;
    const double eLo = elevations.front(), eMid = 0.5 * (elevations.front() + elevations.back());
    const double kMid = 0.5 * (kelvinLow + kelvinHigh);
    for (const double below : {20.0, 45.0})
        for (int a = 0; a < 6; ++a) out.push_back(light(world, 15.0 + 60.0 * a, eLo - below, kMid));
    for (const double kelvin : {2700.0, 12000.0})
        for (int a = 0; a < 4; ++a) out.push_back(light(world, 40.0 + 90.0 * a, eMid, kelvin));
    VolumeRig near = *this;
    near.distance = 1.3;
    for (int a = 0; a < 4; ++a) out.push_back(near.light(world, 70.0 + 90.0 * a, eMid, kMid));
    return out;
}

namespace {

/// n elevations evenly over [lo, hi] degrees.
std::vector<double> evenElevations(int n, double lo, double hi) {
    std::vector<double> e(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) e[static_cast<std::size_t>(i)] = lo + (hi - lo) * i / (n - 1);
    return e;
}

/// Up to `count` voxels spread evenly over the point order (deterministic).
std::vector<Index> voxelSample(Index n, Index count) {
    std::vector<Index> out;
    const Index k = std::min(n, count);
    for (Index i = 0; i < k; ++i) out.push_back(i * n / k);
    return out;
}

}  // namespace

double VolumeRig::cellInterpolationError(const VolumeWorld& world) const {
    if (spiral > 0 || elevations.size() < 2 || azimuths < 2) return 0;
    // 24 cells spread over the grid: each the light at its centre, then its four corners.
    const int bands = static_cast<int>(elevations.size()) - 1, cells = azimuths * bands;
    const int wanted = std::min(cells, 24);
    const double step = 360.0 / azimuths;
    std::vector<VolumeLight> lights;
    for (int i = 0; i < wanted; ++i) {
        const int c = static_cast<int>(static_cast<long>(i) * cells / wanted);
        const int a = c % azimuths;
        const auto e = static_cast<std::size_t>(c / azimuths);
        lights.push_back(light(world, (a + 0.5) * step, 0.5 * (elevations[e] + elevations[e + 1]), 5000));
        for (int corner = 0; corner < 4; ++corner)
            lights.push_back(light(world, (a + (corner & 1)) * step, elevations[e + (corner >> 1)], 5000));
    }
    const std::vector<Index> points = voxelSample(static_cast<Index>(world.density.voxelCount()), 512);
    const std::size_t width = 3 * points.size();
    std::vector<double> values(lights.size() * width);
    // A non-owning pointer: the evaluator lives only inside this call.
    const VolumeEvaluator ev(std::shared_ptr<const VolumeWorld>(std::shared_ptr<const VolumeWorld>(), &world),
                             lights, "volume-rig-probe");
    tbb::parallel_for(Index{0}, static_cast<Index>(lights.size()), [&](Index f) {
        ev.evaluate(f, points, values.data() + static_cast<std::size_t>(f) * width);
    });
    double diff = 0, norm = 0;
    for (int i = 0; i < wanted; ++i) {
        const double* centre = values.data() + static_cast<std::size_t>(5 * i) * width;
        for (std::size_t k = 0; k < width; ++k) {
            double mean = 0;
            for (int corner = 1; corner <= 4; ++corner)
                mean += centre[static_cast<std::size_t>(corner) * width + k];
            diff += (centre[k] - 0.25 * mean) * (centre[k] - 0.25 * mean);
            norm += centre[k] * centre[k];
        }
    }
    return norm > 0 ? std::sqrt(diff / norm) : 0.0;
}

VolumeRig VolumeRig::forMedium(const VolumeWorld& world) { return forMedium(world, VolumeRig{}); }

VolumeRig VolumeRig::forMedium(const VolumeWorld& world, const VolumeRig& base) {
    if (base.spiral > 0 || base.elevations.size() < 2) return base;
    const double lo = base.elevations.front(), hi = base.elevations.back();
    const int a0 = base.azimuths, e0 = static_cast<int>(base.elevations.size());
    // Both steps are the base's x 4 / (4 + k) (16 x 6: 22.5 x 14 degrees, then 18 x 11.7,
    // 15 x 10, 12.9 x 8.75, 11.25 x 7): the cells keep their shape.
    for (int k = 0; k <= 4; ++k) {
        VolumeRig rig = base;
        rig.azimuths = a0 * (4 + k) / 4;
        rig.elevations = k == 0 ? base.elevations : evenElevations(1 + (e0 - 1) * (4 + k) / 4, lo, hi);
        if (k == 4 || rig.cellInterpolationError(world) <= kCellErrorGoal) return rig;
    }
    return base;
}

void recolour(const VolumeLight& from, const VolumeLight& to, double* values, Index points) {
    if (from.position.x != to.position.x || from.position.y != to.position.y ||
        from.position.z != to.position.z || from.radius != to.radius)
        throw std::invalid_argument("recolour: the lights differ in more than their colour");
    double s[3];
    for (int c = 0; c < 3; ++c)
        s[c] = to.intensity[static_cast<std::size_t>(c)] / from.intensity[static_cast<std::size_t>(c)];
    for (Index i = 0; i < points; ++i)
        for (int c = 0; c < 3; ++c) values[3 * i + c] *= s[c];
}

VolumeEvaluator::VolumeEvaluator(std::shared_ptr<const VolumeWorld> world, std::vector<VolumeLight> lights,
                                 std::string name)
    : world_(std::move(world)), lights_(std::move(lights)), name_(std::move(name)) {}

void VolumeEvaluator::scatter(const VolumeLight& light, Index point, DensityVolume::Tracer& tracer,
                              double* rgb) const {
    const MediumSettings& m = world_->medium;
    const Vec3 p = world_->density.voxelPositions()[static_cast<std::size_t>(point)];
    const Vec3 toLight = light.position - p;
    const double d = scene::length(toLight);
    Vec3 t, b;
    scene::orthonormalBasis(toLight * (1.0 / d), t, b);
    const int s = m.lightSamples;
    const int K = m.octaves;
    double single = 0;
    double octave[16] = {};
    for (int j = 0; j < s; ++j) {
        double u, v;
        scene::hammersleyShifted(static_cast<std::uint32_t>(point), static_cast<std::uint32_t>(j),
                                 static_cast<std::uint32_t>(s), u, v);
        // Uniform on the disk the spherical light shows to p (its silhouette, r << d).
        const double r = light.radius * std::sqrt(u), phi = 2 * M_PI * v;
        const Vec3 q = light.position + t * (r * std::cos(phi)) + b * (r * std::sin(phi));
        const double tau = m.sigmaT * tracer.densityIntegral(p, q, m.stepVoxels);
        single += std::exp(-tau);
        double a = 1;
        for (int k = 0; k < K && k < 16; ++k) {
            a *= m.octaveExtinction;
            octave[k] += std::exp(-a * tau);
        }
    }
    const double e = 1.0 / (4 * M_PI * d * d * s);
    for (int c = 0; c < 3; ++c) {
        double sum = single, w = 1;
        for (int k = 0; k < K && k < 16; ++k) {
            w *= m.octaveScattering * m.albedo[static_cast<std::size_t>(c)];
            sum += w * octave[k];
        }
        rgb[c] = light.intensity[static_cast<std::size_t>(c)] * e * sum;
    }
}

void VolumeEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    if (frame < 0 || frame >= frameCount())
        throw std::out_of_range(name_ + ": frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(frameCount()) + ")");
    const Index n = pointCount();
    DensityVolume::Tracer tracer(world_->density);
    const VolumeLight& light = lights_[static_cast<std::size_t>(frame)];
    for (std::size_t i = 0; i < points.size(); ++i) {
        if (points[i] < 0 || points[i] >= n)
            throw std::out_of_range(name_ + ": point " + std::to_string(points[i]) + " outside [0, " +
                                    std::to_string(n) + ")");
        scatter(light, points[i], tracer, out + 3 * i);
    }
}

void VolumeEvaluator::evaluateAll(Index frame, double* out) const {
    if (frame < 0 || frame >= frameCount())
        throw std::out_of_range(name_ + ": frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(frameCount()) + ")");
    const VolumeLight& light = lights_[static_cast<std::size_t>(frame)];
    tbb::parallel_for(tbb::blocked_range<Index>(0, pointCount(), 512),
                      [&](const tbb::blocked_range<Index>& r) {
                          DensityVolume::Tracer tracer(world_->density);
                          for (Index p = r.begin(); p != r.end(); ++p) scatter(light, p, tracer, out + 3 * p);
                      });
}

ScatterCacheInfo VolumeEvaluator::info(Index frame, std::string state) const {
    const VolumeLight& l = lights_.at(static_cast<std::size_t>(frame));
    return {static_cast<std::int32_t>(frame),
            l.position,
            l.kelvin,
            std::move(state),
            world_->medium.sigmaT,
            world_->medium.albedo};
}

// One frame as a .vdb: the "inscatter" grid (ScatterCache) with the density's topology.
FrameSet VolumeEvaluator::pointPositions() const {
    return scene::positionsFrame(world_->density.voxelPositions());
}

std::vector<std::shared_ptr<const FrameWriter>> VolumeEvaluator::frameWriters() const {
    const std::size_t n = world().density.voxelCount();
    auto write = [this, n](const std::string& path, Index frame, const double* values) {
        ScatterCache(world().density, std::span<const double>(values, 3 * n), info(frame, "soft-cached"))
            .writeTo(path);
    };
    auto activeVoxels = [](const std::string& path) { return ScatterCache::read(path).activeVoxelCount(); };
    return {std::make_shared<scene::VdbFrameWriter>(static_cast<std::int64_t>(n), write, activeVoxels)};
}

VolumeSpec parseVolumeSpec(const std::string& args) {
    // FILE.vdb[:key=value]...: options are the trailing ':'-separated items that contain '='.
    std::string path = args;
    std::vector<std::string> options;
    for (;;) {
        const auto colon = path.rfind(':');
        if (colon == std::string::npos || path.find('=', colon) == std::string::npos) break;
        options.insert(options.begin(), path.substr(colon + 1));
        path.resize(colon);
    }
    if (path.empty()) throw InputError("evaluator 'volume' needs a file: 'volume:FILE.vdb[:grid=NAME]'");
    VolumeSpec spec;
    for (const std::string& item : options) {
        const auto eq = item.find('=');
        const std::string key = item.substr(0, eq), value = item.substr(eq + 1);
        if (key == "grid") {
            if (value.empty()) throw InputError("evaluator 'volume': grid= needs a grid name");
            spec.grid = value;
        } else if (key == "samples") {
            const long v = scene::integerOption("volume", key, value, 1, 4096);
            spec.medium.lightSamples = static_cast<int>(v);
        } else if (key == "lights") {
            if (value != "all" && value != "training" && value != "between" && value != "path" &&
                value != "outside")
                throw InputError("evaluator 'volume': lights='" + value +
                                 "' is not all, training, between, path or outside");
            spec.lights = value;
        } else {
            throw InputError("evaluator 'volume': unknown option '" + key +
                             "' (grid=NAME, samples=S, lights=SET)");
        }
    }
    spec.path = path;
    return spec;
}

std::unique_ptr<VolumeEvaluator> makeVolumeEvaluator(const std::string& args) {
    const VolumeSpec spec = parseVolumeSpec(args);
    const std::string& lights = spec.lights;
    auto world = VolumeWorld::create(DensityVolume::read(spec.path, spec.grid), spec.medium, spec.path);
    const VolumeRig rig = VolumeRig::forMedium(*world);  // the demo's rig for this medium
    std::vector<VolumeLight> set;
    auto add = [&](const std::vector<VolumeLight>& l) { set.insert(set.end(), l.begin(), l.end()); };
    if (lights == "all" || lights == "training") add(rig.training(*world));
    if (lights == "all" || lights == "between") add(rig.between(*world, 16));
    if (lights == "all" || lights == "path") add(rig.path(*world, 48));
    if (lights == "outside") add(rig.outside(*world));
    return std::make_unique<VolumeEvaluator>(std::move(world), std::move(set), "volume");
}

}  // namespace pmsc::volume
