// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "engine/Engine.h"
#include "pmsc/Errors.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace pmsc::examples {

// What the demos that validate a lighting cache against full calculations share (the Cornell
// box, section 8, and the volumetric lighting cache): a relative RMS error and the engine's sink that
// records each validation frame.

/// Squared-error accumulators for a relative RMS error: sqrt(sum (a-b)^2 / sum b^2).
struct RelError {
    double err2 = 0, ref2 = 0;
    void add(const double* a, const double* b, std::size_t n) {
        for (std::size_t i = 0; i < n; ++i) {
            err2 += (a[i] - b[i]) * (a[i] - b[i]);
            ref2 += b[i] * b[i];
        }
    }
    void add(const RelError& o) {
        err2 += o.err2;
        ref2 += o.ref2;
    }
    double value() const { return ref2 > 0 ? std::sqrt(err2 / ref2) : 0.0; }
};

/// The points and frames a demo computes a converged reference on: a random subset of the points
/// (sorted) and the first frames of the validation set.
struct ReferenceSubset {
    std::vector<Index> points;
    Index frames = 0;
    std::set<Index> frameSet;  ///< the same frames, as ValidationSink takes them
};

/// Up to `wantedPoints` of `points` points, drawn with the demo's own fixed `seed`, and the first
/// min(frames, wantedFrames) frames.
inline ReferenceSubset chooseReferenceSubset(Index points, Index wantedPoints, Index frames,
                                             Index wantedFrames, unsigned seed) {
    ReferenceSubset r;
    r.points.resize(static_cast<std::size_t>(points));
    std::iota(r.points.begin(), r.points.end(), Index{0});
    std::mt19937 rng(seed);
    std::shuffle(r.points.begin(), r.points.end(), rng);
    r.points.resize(
        std::min<std::size_t>(r.points.size(), static_cast<std::size_t>(std::max<Index>(0, wantedPoints))));
    std::sort(r.points.begin(), r.points.end());
    r.frames = std::min(frames, wantedFrames);
    for (Index f = 0; f < r.frames; ++f) r.frameSet.insert(f);
    return r;
}

/// What the validation run needs from each frame, gathered in the engine's sink (one thread).
class ValidationSink : public engine::FrameSink {
public:
    struct FrameRecord {
        Index frame = 0;
        CacheState state = CacheState::Hit;
        double weight = 0, keyRms = 0;
        double pmRelError = -1, softRelError = -1;  // -1: no full gather for this frame
    };

    ValidationSink(std::string name, const std::map<Index, std::vector<double>>& full,
                   const std::set<Index>& keepFrames, const std::vector<Index>& subset,
                   const std::set<Index>& subsetFrames)
        : name_(std::move(name)),
          full_(full),
          keepFrames_(keepFrames),
          subset_(subset),
          subsetFrames_(subsetFrames) {}

    void write(const engine::FrameResult& r) override {
        if (r.failed)
            throw EvaluatorError(name_ + ": frame " + std::to_string(r.frame) + " failed: " + r.error);
        FrameRecord rec{r.frame, r.state, r.weight, r.keyError};
        // Point multiplication proper (what a hit delivers), even on frames the soft cache
        // sent to the full gather: the error of the model itself, not flattered by misses.
        const double* pm = r.pmValues.empty() ? r.values.data() : r.pmValues.data();
        if (auto it = full_.find(r.frame); it != full_.end()) {
            RelError pe, se;
            pe.add(pm, it->second.data(), it->second.size());
            se.add(r.values.data(), it->second.data(), it->second.size());
            rec.pmRelError = pe.value();
            rec.softRelError = se.value();
            pmError.add(pe);
            softError.add(se);
            (r.frame < scatteredCount ? pmScattered : pmPath).add(pe);
        }
        if (keepFrames_.count(r.frame)) {
            soft[r.frame].assign(r.values.begin(), r.values.end());
        }
        if (subsetFrames_.count(r.frame)) {
            auto& v = pmAtSubset[r.frame];
            v.resize(3 * subset_.size());
            for (std::size_t i = 0; i < subset_.size(); ++i)
                for (int c = 0; c < 3; ++c) v[3 * i + c] = pm[3 * subset_[i] + c];
        }
        records.push_back(rec);
    }

    Index scatteredCount = 0;
    RelError pmError, softError, pmScattered, pmPath;
    std::vector<FrameRecord> records;
    std::map<Index, std::vector<double>> soft;        // soft-cached values of kept frames
    std::map<Index, std::vector<double>> pmAtSubset;  // PM values at the reference subset

private:
    std::string name_;
    const std::map<Index, std::vector<double>>& full_;
    const std::set<Index>& keepFrames_;
    const std::vector<Index>& subset_;
    const std::set<Index>& subsetFrames_;
};

}  // namespace pmsc::examples
