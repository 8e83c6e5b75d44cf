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
    const LocalChangeBox box = LocalChangeBox::againstBackWall(in.changeEdgeMm);
    const CornellWorld& base = in.validation.world();
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
        [&](double d) { in.progress("local fail-through: local change", d, 1); }, lookUp(full));
    j["box_lo_mm"] = mm(box.lo);
    j["box_hi_mm"] = mm(box.hi);
    j["lights"] = "the first " + std::to_string(in.changeLights) + " scattered validation lights";
    j["points_covered"] = covered;
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
        [&](double d) { in.progress("local fail-through: validation", d, 1); }, lookUp(in.fullGathers));
    if (in.changeEdgeMm > 0 && in.changeLights > 0) j["local_change"] = measureLocalChange(in);
    return j;
}

}  // namespace pmsc::cornell
