// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "engine/RunStats.h"
#include "nodes/FrameRange.h"
#include "nodes/FrameSink.h"
#include "pmsc/Errors.h"  // pmsc::Cancelled
#include "pmsc/Model.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/PointMultiplier.h"  // BasisPrecision, PointMultiplier

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

namespace pmsc::engine {

// The run vocabulary lives below the nodes (nodes/FrameSink.h, nodes/FrameRange.h); a program
// that embeds the engine names it through the engine.
using pmsc::FailurePolicy;
using pmsc::FrameRange;
using pmsc::FrameResult;
using pmsc::FrameSink;

/// Live numbers for a progress line, passed to EngineOptions::progress after each delivered frame.
struct Progress {
    Index framesDone = 0;  ///< delivered so far
    Index framesTotal = 0;
    Index hits = 0, blends = 0, misses = 0, failed = 0;
    double elapsedSeconds = 0;
};

/// A frame that does not hit, as soon as its point multiplication is known and before its
/// fail-through starts: what an interactive client shows while the full calculation catches up
/// (and, with EngineOptions::estimateBeforeCheck, a hit before its check). The spans are valid
/// only during the call.
struct FrameEstimate {
    Index sequence = 0;
    Index frame = 0;
    CacheState state = CacheState::Miss;  ///< Blend or Miss (Hit: a hit before its check)
    double weight = 0;                    ///< weight of the full result the frame will get
    double keyError = 0;
    std::span<const Index> points;   ///< the output's points
    std::span<const double> values;  ///< their point-multiplied values, channel-minor
};

/// One fail-through branch of a frame that does not hit, finished: the final (soft-cached) values
/// of its contiguous range of output points. The spans are valid only during the call.
struct ChunkFinished {
    Index sequence = 0;
    Index frame = 0;
    CacheState state = CacheState::Miss;
    double weight = 0;
    Index chunk = 0, chunks = 0;     ///< this branch, of the frame's `chunks`
    Index firstOutput = 0;           ///< index of its first point in the output's points
    std::span<const double> values;  ///< outputCount * C final values of the range
};

/// Everything a run can be told. Defaults give a full-speed run of all points.
struct EngineOptions {
    /// Worker threads (a tbb::task_arena of this size); 0 = every core. Results are
    /// identical bit for bit whatever the value.
    int threads = 0;
    /// Frames between the source and the sink at once; 0 = 2 x threads. Memory is
    /// this many frame buffers, however long the range.
    Index maxFramesInFlight = 0;
    /// Bytes the frame buffers may hold; 0 = no limit. The frames in flight are cut to what fits
    /// (at least one): a farm task's memory cgroup then bounds the run however many threads the
    /// node has. The engine's constructor throws InputError when not even one frame fits.
    std::uint64_t memoryLimit = 0;
    FailurePolicy failurePolicy = FailurePolicy::StopRun;
    /// Output points per fail-through branch; 0 = automatic: about 64 branches per frame, at
    /// least 256 points each, or one branch per thread for an evaluator whose calls pay a set-up
    /// (PointEvaluator::FailThroughShape::callSetUp). The values do not depend on the chunking,
    /// so the output is bit-identical at any `threads`.
    Index chunkPoints = 0;
    /// > 0: a frame's key points, and the points its hit's check computes (the sentinels), are
    /// evaluated in parallel pieces of this many points instead of one call each. Latency over
    /// throughput: for one frame at a time (an interactive client, `pmsc view`), where the keys and
    /// the check are the calculation every move waits for; a batch run keeps every core busy with
    /// frames already. Needs an evaluator whose subsets are cheap and whose calls have no set-up
    /// of their own (PointEvaluator::FailThroughShape; ignored otherwise). Same values either way.
    Index keyPiecePoints = 0;
    /// What a hit's and a blend's point multiplication read the basis in. Single halves the
    /// memory a hit of a large cache reads, and its time: for outputs stored in float (`pmsc run`
    /// writing .vdb or .npy float32, the demos' grids) and clients that display the values
    /// (`pmsc view`). Double, the default, is what a double output and every comparison uses.
    BasisPrecision basisPrecision = BasisPrecision::Double;
    /// Fail through with one PointEvaluator::evaluateAll() call per frame instead of
    /// chunks (for evaluators whose full evaluation shares work between points). Also on when
    /// the evaluator declares it (PointEvaluator::failThroughShape()).
    bool wholeFrameFailThrough = false;
    /// Local fail-through for models with regions: a frame that does not hit as a whole
    /// sends only the points of its regions that blend or miss (and their feather bands) to the
    /// full calculation. Off: every frame that does not hit fails through whole, as for a
    /// version-1 model (`--whole-frame-fail-through`). Needs all output points (pointsWanted
    /// empty) and an evaluator whose subsets are cheap (PointEvaluator::FailThroughShape).
    bool localFailThrough = true;
    /// The points the consumer needs, in the order wanted (empty = all N). A hit then
    /// reconstructs only these; a fail-through evaluates only these.
    std::vector<Index> pointsWanted;
    /// Thresholds; unset = the model's [epsMin, epsMax].
    std::optional<SoftCachePolicy> policy;
    /// Also hand the sink the PM result of every frame (FrameResult::pmValues), e.g.
    /// to report PM errors on misses. Costs a reconstruction on misses.
    bool keepPointMultiplication = false;
    /// Another thread sets it to stop the run; Engine::run() then throws pmsc::Cancelled
    /// within one frame's time. Must outlive the run.
    const std::atomic<bool>* cancel = nullptr;
    /// Called after each delivered frame, from the sink's thread (keep it cheap).
    std::function<void(const Progress&)> progress;
    /// Called once for each frame that blends or misses, with its point multiplication, before its
    /// fail-through branches run (setting it keeps the point multiplication of misses, as
    /// keepPointMultiplication does). From a worker thread; frames of a range may call it
    /// concurrently. Frames routed region by region (local fail-through) do not call it.
    std::function<void(const FrameEstimate&)> onEstimate;
    /// With onEstimate: a hit whose check points must be computed (the sentinels, HitCheck) is
    /// handed to onEstimate, state Hit, before they are; a hit the check refuses then blends
    /// with weight 0 and its chunks follow, as for any blend. Why: an interactive client (`pmsc
    /// view`) shows a hit's image while the check runs, as it shows a miss's estimate while the
    /// full calculation runs, and what it waits for to see the light move is the keys and the
    /// reconstruction, not the check. The delivered frame is the same either way.
    bool estimateBeforeCheck = false;
    /// Called as each whole-frame fail-through branch finishes, with its range's final values.
    /// From worker threads, concurrently for the branches of one frame (each has its own range).
    /// Not called after the run was cancelled, nor for local frames, nor for a failed branch.
    std::function<void(const ChunkFinished&)> onChunk;
};

/// The soft-caching evaluation engine (sections 5 and 6): a oneTBB
/// flow graph that streams a frame range through key-point evaluation,
/// projection, the error monitor, and either point multiplication (a hit) or
/// the fail-through branches (a blend or a miss), then restores frame order
/// and hands each frame to a FrameSink.
///
/// Thread safety: run() may be called again after it returns; one run at a
/// time per Engine. The model and evaluator must outlive the engine.
class Engine {
public:
    /// @throws pmsc::InputError if the evaluator's N or C differ from the model's, or an option
    ///         is out of range (threads < 0, a wanted point outside [0, N) or repeated, ...).
    Engine(const Model& model, const PointEvaluator& evaluator, EngineOptions options = {});
    ~Engine();
    Engine(const Engine&) = delete;
    Engine& operator=(const Engine&) = delete;

    /// Streams `range` through the graph; the sink receives every frame in order.
    /// @return the run's stats (also in lastStats()).
    /// @throws pmsc::InputError for a range outside the evaluator's frames;
    ///         pmsc::EvaluatorError ("frame F: node 'N': ...") when an evaluator fails under
    ///         StopRun — the sink has then received exactly the frames before F;
    ///         pmsc::Cancelled when EngineOptions::cancel was set;
    ///         whatever FrameSink::write() threw, unchanged.
    RunStats run(FrameRange range, FrameSink& sink);

    /// Stats of the last run, also when it threw.
    const RunStats& lastStats() const;
    const EngineOptions& options() const;
    /// Bytes one frame in flight holds (its buffers); the memory of a run is about this times
    /// RunStats::maxFramesInFlight, beside the model and the evaluator.
    std::uint64_t frameBytes() const;
    /// Points of each output frame (all N, or EngineOptions::pointsWanted).
    const std::vector<Index>& outputPoints() const;
    /// Whether runs route frames region by region (a model with regions, and the options and the
    /// evaluator allow it).
    bool localFailThrough() const;
    /// The point multiplier the engine projects and reconstructs with, its basis copy in
    /// EngineOptions::basisPrecision: a sink that needs a frame's PM reuses it rather than holding
    /// a second copy of the basis. Safe to call from FrameSink::write().
    const PointMultiplier& pointMultiplier() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace pmsc::engine
