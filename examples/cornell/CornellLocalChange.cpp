#include "examples/cornell/CornellLocalChange.h"

#include "examples/common/LocalFailThroughReport.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace pmsc::cornell {

LocalChangeBox LocalChangeBox::againstBackWall(double edgeMm) {
    // The back wall stands at z = 559.2; 549.2 leaves 10 mm. Centred on x = 200: clear of the short
    // block (z < 273) and of the tall block (x > 264) for edges up to 150 mm.
    const double xc = 200, z1 = 549.2;
    return {{xc - 0.5 * edgeMm, 0, z1 - edgeMm}, {xc + 0.5 * edgeMm, edgeMm, z1}};
}

namespace {

// Distance from p to the box (0 inside).
double distanceTo(const LocalChangeBox& b, Vec3 p) {
    const double dx = std::max({b.lo.x - p.x, 0.0, p.x - b.hi.x});
    const double dy = std::max({b.lo.y - p.y, 0.0, p.y - b.hi.y});
    const double dz = std::max({b.lo.z - p.z, 0.0, p.z - b.hi.z});
    return std::sqrt(dx * dx + dy * dy + dz * dz);
}

// The cube's footprint, 5 x 5 samples, stays 5 mm clear of both blocks.
bool clearOfBlocks(const CornellScene& scene, const LocalChangeBox& b) {
    for (int i = 0; i <= 4; ++i)
        for (int k = 0; k <= 4; ++k) {
            const Vec3 p{b.lo.x + (b.hi.x - b.lo.x) * i / 4, 1, b.lo.z + (b.hi.z - b.lo.z) * k / 4};
            if (scene.insideBlock(p, -5)) return false;
        }
    return true;
}

}  // namespace

LocalChangeBox LocalChangeBox::whereKeysSee(double edgeMm, const CornellWorld& world,
                                            const std::vector<Index>& keys, Index* keysNear) {
    // Candidates every 10 mm along the foot of the back wall (z = 559.2), the green wall (x = 0) and
    // the red wall (x = 549.6-552.8), each 10 mm from its wall.
    std::vector<LocalChangeBox> candidates;
    for (double c = 10 + 0.5 * edgeMm; c <= 540 - 0.5 * edgeMm; c += 10) {
        const double h = 0.5 * edgeMm;
        candidates.push_back({{c - h, 0, 549.2 - edgeMm}, {c + h, edgeMm, 549.2}});  // back wall, x = c
        candidates.push_back({{10, 0, c - h}, {10 + edgeMm, edgeMm, c + h}});        // green wall, z = c
        candidates.push_back({{540 - edgeMm, 0, c - h}, {540, edgeMm, c + h}});      // red wall, z = c
    }
    const double reach = 0.5 * edgeMm;
    LocalChangeBox best = againstBackWall(edgeMm);
    Index bestCount = -1;
    for (const LocalChangeBox& b : candidates) {
        if (!clearOfBlocks(world.scene, b)) continue;
        Index count = 0;
        for (const Index k : keys) count += distanceTo(b, world.voxels.position[size_t(k)]) <= reach;
        if (count > bestCount) {
            bestCount = count;
            best = b;
        }
    }
    if (keysNear) *keysNear = std::max<Index>(bestCount, 0);
    return best;
}

namespace {

nlohmann::json mm(Vec3 p) { return {p.x, p.y, p.z}; }

examples::LocalReportScale toleranceScale(double tolerance) {
    examples::LocalReportScale s;
    s.unit = tolerance;
    s.limit = 1;
    s.maxErrorKey = "soft_max_error_over_tolerance";
    s.rmsErrorKey = "soft_rms_error_over_tolerance";
    s.overKey = "frames_over_tolerance";
    return s;
}

examples::FullValues lookUp(const std::map<Index, std::vector<double>>& gathers) {
    return [&gathers](Index frame, double* out) {
        const std::vector<double>& v = gathers.at(frame);
        std::copy(v.begin(), v.end(), out);
    };
}

// The local-change set: the changed scene's full gathers, how far they are from the unchanged
// ones, and the report both ways against them.
nlohmann::json measureLocalChange(const LocalFailThroughInputs& in) {
    const CornellWorld& base = in.validation.world();
    Index keysNear = 0;
    const LocalChangeBox box =
        LocalChangeBox::whereKeysSee(in.changeEdgeMm, base, in.model.keyPoints, &keysNear);
    const auto world = CornellWorld::withScene(base, base.scene.withBox("local change", box.lo, box.hi));
    const std::vector<PointLight> lights(in.validation.lights().begin(),
                                         in.validation.lights().begin() + in.changeLights);
    const CornellEvaluator changed(world, lights, in.validation.samplesPerPoint(), "cornell-local-change");
    const Index n = changed.pointCount(), frames = changed.frameCount();

    std::map<Index, std::vector<double>> full;
    double largestMove = 0;
    Index moved = 0;
    for (Index f = 0; f < frames; ++f) {
        in.progress("local change: full gathers", double(f), double(frames));
        std::vector<double>& v = full[f];
        v.resize(size_t(3 * n));
        in.inArena([&] { changed.evaluateAll(f, v.data()); });
        const std::vector<double>& before = in.fullGathers.at(f);
        for (Index p = 0; p < n; ++p) {
            const size_t i = size_t(3 * p);
            const double d = std::hypot(v[i] - before[i], v[i + 1] - before[i + 1], v[i + 2] - before[i + 2]);
            largestMove = std::max(largestMove, d);
            moved += d > 0.1 * in.tolerance;
        }
    }
    Index covered = 0;
    for (Index p = 0; p < n; ++p) {
        const Vec3 x = base.voxels.position[size_t(p)];
        covered += x.x > box.lo.x && x.x < box.hi.x && x.z > box.lo.z && x.z < box.hi.z && x.y < box.hi.y;
    }
    std::vector<Index> all(static_cast<size_t>(frames));
    for (Index f = 0; f < frames; ++f) all[size_t(f)] = f;
    nlohmann::json j = examples::localFailThroughReport(
        in.model, changed, all, toleranceScale(in.tolerance), in.threads,
        [&](double d) { in.progress("local fail-through: local change", d, 1); }, lookUp(full), true);
    j["box_lo_mm"] = mm(box.lo);
    j["box_hi_mm"] = mm(box.hi);
    j["lights"] = "the first " + std::to_string(in.changeLights) + " scattered validation lights";
    j["points_covered"] = covered;
    j["key_points_within_half_an_edge"] = keysNear;
    j["change_max_over_tolerance"] = largestMove / in.tolerance;
    j["points_changed_over_tenth_tolerance_fraction"] = double(moved) / (double(frames) * double(n));
    return j;
}

}  // namespace

nlohmann::json measureLocalFailThrough(const LocalFailThroughInputs& in) {
    nlohmann::json j;
    const LocalRegions& regions = *in.model.regions;
    j["regions"] = regions.regionCount();
    j["feather_width_mm"] = regions.featherWidth;
    j["max_local_fraction"] = regions.maxLocalFraction;
    j["tolerance"] = in.tolerance;
    std::vector<Index> scattered(static_cast<size_t>(in.scattered));
    for (Index f = 0; f < in.scattered; ++f) scattered[size_t(f)] = f;
    j["validation"] = examples::localFailThroughReport(
        in.model, in.validation, scattered, toleranceScale(in.tolerance), in.threads,
        [&](double d) { in.progress("local fail-through: validation", d, 1); }, lookUp(in.fullGathers), true);
    if (in.changeEdgeMm > 0 && in.changeLights > 0) j["local_change"] = measureLocalChange(in);
    return j;
}

}  // namespace pmsc::cornell
