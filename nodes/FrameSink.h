// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

// What a run hands its consumer: the vocabulary the nodes that deliver frames (nodes/OrderedSink)
// and the engine share. Header-only; the engine re-exports these names as pmsc::engine::*.

#include "pmsc/PointEvaluator.h"  // Index
#include "pmsc/SoftCache.h"

#include <span>
#include <string>

namespace pmsc {

/// One finished frame as a sink sees it. The spans point into the engine's
/// frame buffer and are valid only during FrameSink::write(); copy what you keep.
struct FrameResult {
    Index sequence = 0;   ///< 0, 1, 2, ... in the run's order (frames arrive in this order)
    Index frame = 0;      ///< the evaluator's frame number
    bool failed = false;  ///< MarkFailedAndContinue: the evaluator failed; values are empty
    std::string error;    ///< why, when failed ("frame F: node 'N': ...")

    CacheState state = CacheState::Hit;  ///< section 5 decision
    double weight = 0;                   ///< weight of the full result in values
    double keyError = 0;                 ///< the key points' RMS error (NaN if keys not finite)
    bool keysFinite = true;              ///< false: NaN/Inf in key values forced a full evaluation

    std::span<const Index> points;   ///< the output's points (all N, or the wanted subset)
    std::span<const double> values;  ///< points.size() * C soft-cached values, channel-minor
    /// The point-multiplication result for the same points, only when
    /// EngineOptions::keepPointMultiplication is set (empty otherwise, and
    /// empty for a frame whose key values were not finite).
    std::span<const double> pmValues;
    std::span<const double> keyValues;  ///< K*C evaluated key values, model key order

    // --- local fail-through ---
    /// The frame was routed region by region: only the points with pointWeights > 0 were
    /// evaluated fully; `state` and `weight` are the whole frame's (not hit) decision.
    bool local = false;
    /// Points whose full value the frame's fail-through computed (0 for a hit, all output points
    /// for a whole-frame fail-through).
    Index pointsEvaluated = 0;
    /// Per region (models with regions, empty otherwise): its decision and key RMS error. On a
    /// whole-frame hit the regions are not tested: all Hit, errors 0.
    std::span<const CacheState> regionStates;
    std::span<const double> regionKeyErrors;
    /// Local frames only: each point's feathered weight of the full result (N).
    std::span<const double> pointWeights;
    /// Local frames only: the points evaluated fully (ascending; pointsEvaluated of them) and
    /// their full values (channel-minor), before the feathered blend: what a learning step
    /// needs from a frame that missed in places.
    std::span<const Index> fullPoints;
    std::span<const double> fullValues;
};

/// The consumer of a run, implemented by the user: a file writer, a renderer's
/// output driver, a collector. Called from one thread at a time, strictly in
/// frame-range order, never for a frame that did not finish (StopRun). An
/// exception thrown by write() ends the run and is rethrown by Engine::run()
/// unchanged (so an IoError stays an IoError).
class FrameSink {
public:
    virtual ~FrameSink() = default;
    virtual void write(const FrameResult& frame) = 0;
};

/// What the sink does with a failed frame.
enum class FailurePolicy : int {
    StopRun = 0,                ///< the first failed frame (in order) ends the run with its error
    MarkFailedAndContinue = 1,  ///< the sink receives the frame marked failed; the run goes on
};

}  // namespace pmsc
