#include "pmsc/RegionChoice.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <vector>

namespace pmsc {

namespace {

// Decision: the constants of the rule, each from a measurement (docs/local-fail-through.md,
// "Regions by default", has the tables and the commands).
// Regions only when a motion moves at most 25% of the points: the face 14.8% (its novel frames
// then evaluate 44-48% of the points locally), the synthetic surface, deformed whole, 44.5%.
constexpr double kMostSupport = 0.25;
// 167 points a region: the face's 26,719 points in 160 regions. Its two novel takes evaluated
// 52.0% / 50.7% of the points with 96 regions, 47.7% / 44.3% with 159, 45.3% / 43.3% with 240
// (the feather below, every 3rd frame).
constexpr Index kPointsPerRegion = 167;
// At most 160: 240 regions saved 1-2% more of the points for 3 s more CPU (26.6 s against 23.4 s)
// and a worst error of 0.64% of the diagonal against 0.53%.
constexpr Index kMostRegions = 160;
// Fewer than 8 regions: a region is an eighth of the points or more, and a miss's feather bands
// reach most of the rest.
constexpr Index kFewestRegions = 8;
// Feather 0.25 / sqrt(R) of the diagonal: 2.0% at the face's 159 regions, which evaluated 47.7% /
// 44.3% of two novel takes' points, worst 0.49% / 0.53% of the diagonal (tolerance 1%); 3% evaluated
// 50.3% / 47.9% (worst 0.40% / 0.48%), 1.5% 46.6% / 42.9% (worst 0.59% / 0.56%).
constexpr double kFeatherTimesSqrtR = 0.25;

std::string percent(double share) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.1f%%", 100.0 * share);
    return buf;
}

}  // namespace

double basisSupport(const Model& model) {
    const Eigen::MatrixXd loadings = rotatedLoadings(model);
    const Index n = loadings.rows();
    double weighted = 0, total = 0;
    std::vector<double> energy(static_cast<size_t>(n));
    for (Index j = 0; j < loadings.cols(); ++j) {
        for (Index p = 0; p < n; ++p) energy[size_t(p)] = loadings(p, j) * loadings(p, j);
        std::sort(energy.begin(), energy.end(), std::greater<>());
        double all = 0;
        for (const double e : energy) all += e;
        if (!(all > 0)) continue;
        Index need = 0;
        for (double sum = 0; need < n && sum < 0.9 * all; ++need) sum += energy[size_t(need)];
        weighted += all * static_cast<double>(need) / static_cast<double>(n);
        total += all;
    }
    return total > 0 ? weighted / total : 1.0;
}

RegionChoice chooseRegions(const Model& model, const RegionOptions& options, double tolerance,
                           double rmsMotion) {
    RegionChoice choice;
    if (!(tolerance > 0)) {
        choice.reason = "none: without --tolerance a region's thresholds route no novel frame locally";
        return choice;
    }
    if (options.positions.size() == 0 && model.channels != 3) {
        choice.reason = "none: no point positions (" + std::to_string(model.channels) + "-channel data)";
        return choice;
    }
    if (options.positions.size() == 0) {
        const double share = motionShare(model, rmsMotion);
        if (!(share <= kMostMotion)) {
            choice.reason = "none: the values move by " + percent(std::isfinite(share) ? share : 1.0) +
                            " of their mean's extent (RMS), over " + percent(kMostMotion) +
                            ": not point positions";
            return choice;
        }
    }
    choice.support = basisSupport(model);
    const std::string support = "a motion moves " + percent(choice.support) + " of the points";
    if (choice.support > kMostSupport) {
        choice.reason = "none: " + support + " (over " + percent(kMostSupport) +
                        "): the data pose whole, a miss is cheapest whole";
        return choice;
    }
    const Index r = std::min(kMostRegions, model.points / kPointsPerRegion);
    if (r < kFewestRegions) {
        choice.reason = "none: " + std::to_string(model.points) + " points make fewer than " +
                        std::to_string(kFewestRegions) + " regions of " + std::to_string(kPointsPerRegion);
        return choice;
    }
    choice.count = r;
    choice.featherFraction = kFeatherTimesSqrtR / std::sqrt(static_cast<double>(r));
    choice.reason = std::to_string(r) + ", feather " + percent(choice.featherFraction) + " (" + support +
                    "; " + std::to_string(model.points) + " points, " + std::to_string(kPointsPerRegion) +
                    " a region, at most " + std::to_string(kMostRegions) + ")";
    return choice;
}

}  // namespace pmsc
