#include "evaluators/synthetic/SyntheticSurface.h"

#include "evaluators/scene/SpecOptions.h"
#include "pmsc/Errors.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>

namespace pmsc::synthetic {

namespace {

constexpr int kModes = 4;
constexpr int kBumps = 6;
// The twist rotates points near (kTwistX, kTwistY) about it, fading out by kTwistRadius:
// the sheet's "jaw".
constexpr double kTwistX = 0.45, kTwistY = -0.5, kTwistRadius = 0.45, kTwistMaxAngle = 0.35;
// The novel motion is a pucker of the "jaw": a pinch towards the pivot that no training
// control produces, where the twist puts key points (like the paper's figure 4, lips the
// training never saw). Motion where no key point looks is invisible to the soft cache by
// construction, so a test of the fail-through must place it where keys are.
constexpr double kNovelX = kTwistX, kNovelY = kTwistY, kNovelRadius = 0.3, kNovelDepth = 0.2;

double smoothstep(double e0, double e1, double x) {
    const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
    return t * t * (3 - 2 * t);
}

}  // namespace

SyntheticSurface::SyntheticSurface(const SurfaceOptions& options) : options_(options) {
    if (options.grid < 2 || options.frames < 1 || options.novelFrames < 0 ||
        options.novelFrames > options.frames)
        throw std::invalid_argument(
            "SyntheticSurface: need grid >= 2, frames >= 1, 0 <= novelFrames <= frames (got " +
            std::to_string(options.grid) + ", " + std::to_string(options.frames) + ", " +
            std::to_string(options.novelFrames) + ")");
    // The rig: fixed placements, independent of the seed.
    std::mt19937_64 rig(20070101);
    std::uniform_real_distribution<double> pos(-0.7, 0.5), angle(0, 2 * M_PI), radius(0.15, 0.3);
    for (int i = 0; i < kBumps; ++i) {
        const double a = angle(rig);
        bumps_.push_back({pos(rig), pos(rig) + 0.1, std::cos(a), std::sin(a), radius(rig)});
    }
    // The animation: curves from the seed.
    std::mt19937_64 rng(options.seed * 0x9E3779B97F4A7C15ull + 1);
    for (int i = 0; i < kModes; ++i) modeCurves_.emplace_back(rng, 60, 240);
    for (int i = 0; i < kBumps; ++i) heightCurves_.emplace_back(rng, 40, 160);
    for (int i = 0; i < kBumps; ++i) slideCurves_.emplace_back(rng, 50, 200);
    twistCurve_ = SmoothNoise(rng, 60, 180);
}

SyntheticSurface::Controls SyntheticSurface::controls(Index frame) const {
    const double t = static_cast<double>(frame);
    Controls c;
    for (const auto& m : modeCurves_) c.modes.push_back(0.15 * m(t));
    for (const auto& h : heightCurves_) c.heights.push_back(0.12 * (0.5 + 0.5 * h(t)));
    for (const auto& s : slideCurves_) c.slides.push_back(0.12 * s(t));
    c.twist = kTwistMaxAngle * std::max(0.0, twistCurve_(t));
    const Index novelStart = options_.frames - options_.novelFrames;
    if (options_.novelFrames > 0 && frame >= novelStart) {
        // Ramps from 0 to 1 over the first half of the novel frames, then holds: the report
        // shows the key error rising through hit, blend and miss.
        const double ramp = static_cast<double>(frame - novelStart + 1) / (0.5 * options_.novelFrames);
        c.novel = std::min(1.0, ramp);
    }
    return c;
}

void SyntheticSurface::evaluatePoint(const Controls& c, Index point, double* out) const {
    const Index g = options_.grid;
    const double x0 = -1.0 + 2.0 * static_cast<double>(point % g) / static_cast<double>(g - 1);
    const Index row = point / g;  // the grid row: integer division is meant
    const double y0 = -1.0 + 2.0 * static_cast<double>(row) / static_cast<double>(g - 1);
    double x = x0, y = y0;
    // Global modes: smooth, linear in their controls.
    double z = c.modes[0] * std::sin(M_PI * x0) * std::cos(0.5 * M_PI * y0) + c.modes[1] * x0 * y0 +
               c.modes[2] * (x0 * x0 - y0 * y0) + c.modes[3] * std::cos(M_PI * (x0 + y0));
    // Sliding bumps: a Gaussian whose centre moves with its slide control.
    for (int i = 0; i < kBumps; ++i) {
        const Bump& b = bumps_[static_cast<std::size_t>(i)];
        const double cx = b.x + c.slides[static_cast<std::size_t>(i)] * b.dx;
        const double cy = b.y + c.slides[static_cast<std::size_t>(i)] * b.dy;
        const double r2 = ((x0 - cx) * (x0 - cx) + (y0 - cy) * (y0 - cy)) / (b.radius * b.radius);
        z += c.heights[static_cast<std::size_t>(i)] * std::exp(-r2);
    }
    // Twist: rotate about the pivot in the sheet's plane, fading with distance (a rigid
    // rotation inside, a smooth skin towards the rest of the sheet).
    const double dx = x0 - kTwistX, dy = y0 - kTwistY;
    const double influence = 1.0 - smoothstep(0.5 * kTwistRadius, kTwistRadius, std::sqrt(dx * dx + dy * dy));
    if (influence > 0) {
        const double a = c.twist * influence;
        x = kTwistX + std::cos(a) * dx - std::sin(a) * dy;
        y = kTwistY + std::sin(a) * dx + std::cos(a) * dy;
        z += 0.2 * c.twist * influence;
    }
    if (c.novel > 0) {
        // Pull points towards the pivot in the plane and down, strongest at the pivot.
        const double r2 = ((x0 - kNovelX) * (x0 - kNovelX) + (y0 - kNovelY) * (y0 - kNovelY)) /
                          (kNovelRadius * kNovelRadius);
        const double pull = c.novel * std::exp(-r2);
        x -= 0.5 * pull * (x - kNovelX);
        y -= 0.5 * pull * (y - kNovelY);
        z -= kNovelDepth * pull;
    }
    out[0] = x;
    out[1] = y;
    out[2] = z;
}

void SyntheticSurface::evaluate(Index frame, std::span<const Index> points, double* out) const {
    if (frame < 0 || frame >= options_.frames)
        throw std::out_of_range("synthetic: frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(options_.frames) + ")");
    const Controls c = controls(frame);
    const Index n = pointCount();
    for (std::size_t i = 0; i < points.size(); ++i) {
        if (points[i] < 0 || points[i] >= n)
            throw std::out_of_range("synthetic: point " + std::to_string(points[i]) + " outside [0, " +
                                    std::to_string(n) + ")");
        evaluatePoint(c, points[i], out + 3 * i);
    }
}

std::unique_ptr<SyntheticSurface> makeSyntheticSurface(const std::string& args) {
    SurfaceOptions options;
    std::stringstream in(args);
    std::string item;
    while (std::getline(in, item, ':')) {
        if (item.empty()) continue;
        const auto eq = item.find('=');
        const std::string key = item.substr(0, eq),
                          value = eq == std::string::npos ? "" : item.substr(eq + 1);
        if (key == "grid") {
            options.grid = scene::integerOption("synthetic", key, value, 2, 4096);
        } else if (key == "frames") {
            options.frames = scene::integerOption("synthetic", key, value, 1, 1000000);
        } else if (key == "seed") {
            options.seed = static_cast<unsigned>(scene::integerOption("synthetic", key, value, 0, 1L << 31));
        } else if (key == "novel") {
            options.novelFrames = scene::integerOption("synthetic", key, value, 0, 1000000);
        } else {
            throw InputError("evaluator 'synthetic': unknown option '" + key +
                             "' (grid=G, frames=F, seed=S, novel=N)");
        }
    }
    if (options.novelFrames > options.frames)
        throw InputError("evaluator 'synthetic': novel=" + std::to_string(options.novelFrames) +
                         " exceeds frames=" + std::to_string(options.frames));
    return std::make_unique<SyntheticSurface>(options);
}

}  // namespace pmsc::synthetic
