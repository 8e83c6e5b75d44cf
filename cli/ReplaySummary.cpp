#include "cli/ReplaySummary.h"
#include "cli/Format.h"
#include "pmsc/Cross.h"
#include "pmsc/KeyError.h"

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

namespace pmsc::cli {

namespace {

std::string row(const char* label, const Percentiles& p) {
    char buffer[160];
    std::snprintf(buffer, sizeof buffer, "    %-24s %11.5g %11.5g %11.5g %11.5g\n", label, p.p50, p.p99,
                  p.p995, p.max);
    return buffer;
}

}  // namespace

void printReplaySummary(std::ostream& out, const Model& model, const app::ReplayResult& result,
                        bool epsOverridden) {
    const double frames = static_cast<double>(result.frames.size());
    std::size_t hits = 0, blends = 0, misses = 0;
    std::vector<double> pm, soft;
    for (const auto& f : result.frames) {
        hits += f.decision.state == CacheState::Hit;
        blends += f.decision.state == CacheState::Blend;
        misses += f.decision.state == CacheState::Miss;
        pm.push_back(f.pmMaxPointError);
        soft.push_back(f.softMaxPointError);
    }
    out << "replayed " << result.frames.size() << " frames of " << model.points << " points x "
        << model.channels << " through M = " << model.basisSize() << ", K = " << model.keyCount()
        << " keys in " << fmt("%.3f", result.seconds) << " s ("
        << fmt("%.1f", frames / std::max(result.seconds, 1e-9)) << " frames/s, " << result.threads
        << " threads, " << result.framesInFlight << " frames in flight)\n";
    out << "  eps         [" << fmt("%.6g", result.epsMin) << ", " << fmt("%.6g", result.epsMax) << "] "
        << describe(model.keyErrorNorm) << " ("
        << (epsOverridden         ? "--eps"
            : model.tolerance > 0 ? "calibrated for tolerance " + fmt("%.6g", model.tolerance)
                                  : "model's, not calibrated")
        << ")\n";
    out << "  cache       hit " << fmt("%.1f", 100.0 * hits / std::max(frames, 1.0)) << "%  blend "
        << fmt("%.1f", 100.0 * blends / std::max(frames, 1.0)) << "%  miss "
        << fmt("%.1f", 100.0 * misses / std::max(frames, 1.0)) << "%  (" << hits << " / " << blends << " / "
        << misses << " frames)\n";
    out << "  largest point error per frame    p50         p99       p99.5         max\n";
    out << row("point multiplication", percentiles(pm));
    out << row("soft cached", percentiles(soft));
}

void printCrossReplaySummary(std::ostream& out, const Model& model, const app::CrossReplayResult& result) {
    const CrossState& st = *model.cross;
    const double frames = static_cast<double>(result.frames.size());
    const app::CrossTally t = app::tally(model, result);
    const std::vector<double>&key = t.key, &bound = t.bound, &error = t.error;
    const Index inside = t.inside, over = t.overTolerance;
    out << "cross replay: " << result.frames.size() << " control frames of " << st.controlPoints
        << " points -> " << model.points - st.controlPoints
        << " target points through M = " << model.basisSize() << ", K = " << model.keyCount()
        << " control keys in " << fmt("%.3f", result.seconds) << " s ("
        << fmt("%.1f", frames / std::max(result.seconds, 1e-9)) << " frames/s, " << result.threads
        << " threads)\n";
    out << "  fail-through impossible (cross point multiplication): every frame is the reconstruction\n";
    out << "  bound       target's largest point error <= " << fmt("%.6g", st.quantile) << " x (key RMS + "
        << fmt("%.6g", st.scale) << ") for " << fmt("%.0f", 100 * st.coverage)
        << "% of frames like the held-out training pairs (" << st.keyRms.size() << ")\n";
    const Percentiles k = percentiles(key), b = percentiles(bound);
    out << "  per frame                        p50         p99       p99.5         max\n";
    out << "    control key RMS         " << fmt(" %11.5g", k.p50) << fmt(" %11.5g", k.p99)
        << fmt(" %11.5g", k.p995) << fmt(" %11.5g", k.max) << "\n";
    out << "    bound                   " << fmt(" %11.5g", b.p50) << fmt(" %11.5g", b.p99)
        << fmt(" %11.5g", b.p995) << fmt(" %11.5g", b.max) << "\n";
    if (result.measured) {
        const Percentiles e = percentiles(error);
        out << "    target error (measured) " << fmt(" %11.5g", e.p50) << fmt(" %11.5g", e.p99)
            << fmt(" %11.5g", e.p995) << fmt(" %11.5g", e.max) << "\n";
        out << "  coverage    " << inside << " of " << result.frames.size() << " frames inside their bound ("
            << fmt("%.1f", 100.0 * static_cast<double>(inside) / std::max(frames, 1.0)) << "%; stated "
            << fmt("%.0f", 100 * st.coverage) << "%)\n";
    }
    if (model.tolerance > 0)
        out << "  tolerance   " << over << " frames have a bound over " << fmt("%.6g", model.tolerance)
            << "\n";
}

}  // namespace pmsc::cli
