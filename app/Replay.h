// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/OptionError.h"

#include "pmsc/KeptFrames.h"
#include "pmsc/Metrics.h"
#include "pmsc/Model.h"
#include "pmsc/NpyIO.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/SoftCache.h"

#include <nlohmann/json.hpp>

#include <atomic>
#include <functional>
#include <optional>
#include <utility>
#include <vector>

namespace pmsc::app {

/// What replaying one frame through the soft cache gave (a row of the report).
struct ReplayFrame {
    Index frame = 0;
    double keyRms = 0;             ///< PointMultiplier::keyError of the recorded key values
    CacheDecision decision;        ///< section 5: hit, blend (with the weight of the full result) or miss
    double pmMaxPointError = 0;    ///< largest point error of the PM reconstruction alone
    double softMaxPointError = 0;  ///< largest point error of the soft-cached output
    // Models with regions (local fail-through):
    bool local = false;                  ///< routed region by region
    double pointsEvaluatedFraction = 0;  ///< fraction of the points evaluated fully (read from the recording)
    std::vector<CacheState> regionStates;  ///< per region
};

struct ReplayOptions {
    /// Overrides the model's [eps_min, eps_max] (`--eps`).
    std::optional<std::pair<double, double>> eps;
    /// Worker threads (the engine's task arena); 0 = every core. Results do not depend on it.
    int threads = 0;
    /// Local fail-through for models with regions (`--whole-frame-fail-through` turns it off).
    bool localFailThrough = true;
    /// Bytes the frames in flight may hold (engine::EngineOptions::memoryLimit); 0 = no limit.
    std::uint64_t memoryLimit = 0;
    /// Set by another thread (SIGINT) to stop; replay() then throws pmsc::Cancelled.
    const std::atomic<bool>* cancel = nullptr;
    /// Called now and then with (frames done, frames total), from one thread at a time.
    std::function<void(Index, Index)> progress;
    /// If set, every frame that blends or misses is kept (its recorded values) for `pmsc learn`
    /// (`--keep-misses`); the caller commits it.
    KeptFrames* keep = nullptr;
    /// If set, also called with each soft-cached frame (N*C doubles), in frame order, from one
    /// thread at a time: an in-memory output (the Python module's array) instead of or besides `out`.
    std::function<void(Index sequence, const double* values)> frameOut;
};

/// An --eps override [MIN, MAX] (replay, run, Python's eps=): finite, 0 <= MIN <= MAX.
/// @throws OptionError naming the option as `spelling` names it.
void checkEps(const std::pair<double, double>& eps, Spelling spelling);

struct ReplayResult {
    double epsMin = 0, epsMax = 0;    ///< thresholds used
    std::vector<ReplayFrame> frames;  ///< in frame order
    double seconds = 0;               ///< wall time of the per-frame loop (input already read)
    int threads = 0;                  ///< worker threads allowed
    bool localFailThrough = false;    ///< frames were routed region by region when they did not hit
    Index framesInFlight = 0;         ///< the engine's bound (cut by ReplayOptions::memoryLimit)
};

/// Per-worker buffers, sized for one frame of a model.
struct ReplayScratch {
    std::vector<double> keys, coords, pm, full;
    explicit ReplayScratch(const Model& model);
};

/// Replays ONE frame (sections 5 and 6): reads the key points' recorded values,
/// projects them onto the basis, takes the key RMS error, decides hit / blend /
/// miss, reconstructs all points by point multiplication, reads the recorded
/// frame (the fail-through, and the reference for the errors) and writes the
/// soft-cached output: PM for a hit, the recorded frame for a miss,
/// (1 - w) PM + w recorded for a blend.
///
/// Kept as one function of (frame) -> (output, row) with no shared state, so
/// frames can run in any order on any thread (and on the engine's flow graph)
/// with bit-identical results.
/// @param[out] out N*C doubles: the soft-cached frame.
ReplayFrame replayFrame(const PointMultiplier& multiplier, const SoftCachePolicy& policy,
                        const PointEvaluator& recorded, Index frame, ReplayScratch& scratch, double* out);

/// Replays every frame of `recorded` on the evaluation engine (engine/Engine.h),
/// writing each soft-cached frame to `out` when given.
/// @pre recorded's N and C equal the model's (the command checks and names the files).
/// @throws std::invalid_argument for bad eps; pmsc::Cancelled when options.cancel is raised.
ReplayResult replay(const Model& model, const PointEvaluator& recorded, const ReplayOptions& options,
                    NpyFrameWriter* out = nullptr);

/// p50, p99, p99.5 (nearest rank) and max of a sample: the project's one definition (pmsc/Metrics.h).
using pmsc::Percentiles;
using pmsc::percentiles;

/// The REPORT.json of `pmsc replay`: {"summary": {...}, "frames": [...]} with exactly
/// the fields documented in docs/replay-report.md.
nlohmann::ordered_json replayReport(const Model& model, const ReplayResult& result);

}  // namespace pmsc::app
