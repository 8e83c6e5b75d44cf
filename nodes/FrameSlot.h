// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FramePlan.h"
#include "pmsc/KeyError.h"
#include "pmsc/RegionMultiplier.h"
#include "pmsc/SoftCache.h"

#include <atomic>
#include <mutex>
#include <string>
#include <vector>

namespace pmsc::nodes {

/// The working state of one frame in flight, passed by pointer from node to
/// node. The engine allocates a fixed pool of maxFramesInFlight slots before a
/// run and recycles them, so the slots ARE the tokens that bound the work in
/// flight: memory stays constant however long the frame range.
///
/// Thread safety: a slot is owned by one node body at a time, except during a
/// fail-through, when chunk bodies write disjoint ranges of `values` and
/// `scratch` and meet again through `chunksLeft` (acquire/release) and fail().
struct FrameSlot {
    /// @param[in] plan         sizes the buffers (output points, scratch)
    /// @param[in] keyCount     K of the model
    /// @param[in] basisSize    Model::coordCount(): M, or M x C when the channels share the basis
    /// @param[in] keepPm       also hold the point-multiplication result of every frame
    FrameSlot(const FramePlan& plan, Index keyCount, Index basisSize, bool keepPm);
    ~FrameSlot();
    FrameSlot(const FrameSlot&) = delete;
    FrameSlot& operator=(const FrameSlot&) = delete;

    /// Bytes the slot's buffers hold (what one more frame in flight costs).
    std::size_t bytes() const;
    /// Prepares the slot for a new frame (keeps the buffers' memory).
    void reset(Index sequenceNumber, Index frameNumber);

    /// Records a failure of `node` on this frame. Several chunks of one frame
    /// may fail at once; the one with the lowest `order` wins, so the message
    /// does not depend on scheduling. Thread-safe.
    void fail(const std::string& node, const std::string& what, Index order = 0);
    bool failed() const { return failed_.load(std::memory_order_acquire); }
    /// "frame F: node 'N': what" (empty unless failed()).
    const std::string& error() const { return error_; }

    Index sequence = 0;  ///< position in the run, stamped by the source (restores order)
    Index frame = 0;     ///< frame number given to the evaluator

    std::vector<double> keyValues;  ///< K*C, model key order, channel-minor
    bool keysFinite = true;         ///< false forces a fail-through of every point
    std::vector<double> coords;     ///< Model::coordCount() pose-space coordinates
    double keyError = 0;            ///< section 5's key-point error (NaN if keys not finite)
    PredictedParts keyErrorParts;   ///< its parts (the RMS and leave-one-out errors of the keys)
    CacheDecision decision;         ///< hit / blend / miss and the weight of the full result
    /// The sentinels' values (HitCheck::sentinels() order, S*C), when the key node computed them in
    /// the keys' call (KeyPointEvaluator); sized by enableSentinels(), empty otherwise.
    std::vector<double> sentinelValues;
    bool sentinelsComputed = false;  ///< sentinelValues belong to this frame
    /// Sizes sentinelValues for `count` sentinels (once, before the slot's first run).
    void enableSentinels(Index count, Index channels);

    std::vector<double> values;    ///< output: plan.outputCount() * C
    std::vector<double> scratch;   ///< fail-through / blend workspace (plan.scratchSize())
    std::vector<double> pmValues;  ///< PM result of the output points (only when kept)
    bool pmValid = false;          ///< pmValues holds this frame's PM result
    bool estimated = false;        ///< EngineOptions::onEstimate has had this frame

    std::atomic<Index> chunksLeft{0};  ///< fail-through branches still running

    // --- local fail-through; sized by enableRegions(), empty otherwise ---
    /// Sizes the local buffers for `regions` (once, before the slot's first run).
    void enableRegions(const RegionMultiplier& regions, Index points, Index channels);
    bool local = false;                    ///< this frame is routed region by region
    std::vector<double> regionKeyValues;   ///< E*C values of the region keys (frames that do not hit)
    std::vector<double> regionCoords;      ///< every region's coordinates (RegionMultiplier::coordsOffset)
    std::vector<double> regionKeyErrors;   ///< R key RMS errors (empty entries 0 on a global hit)
    std::vector<CacheState> regionStates;  ///< R decisions (all Hit on a global hit)
    std::vector<double> regionWeights;     ///< R weights of the full result
    std::vector<double> pointWeights;      ///< N feathered weights w_p (local frames)
    std::vector<Index> localPoints;        ///< N: the points evaluated fully, ascending (first localCount)
    Index localCount = 0;                  ///< how many of localPoints this frame uses
    std::vector<double> localFull;         ///< N*C: full values of localPoints[i] at i*C
    bool regionsEvaluated = false;         ///< the region decisions above belong to this frame
    /// Points whose full value this frame computed in its fail-through (0 for a hit, N for a
    /// whole-frame fail-through, the points with w_p > 0 for a local frame).
    Index pointsEvaluated = 0;

    /// Live slots in the process (instrument for the bounded-memory test).
    static Index liveCount();

private:
    std::atomic<bool> failed_{false};
    std::mutex errorMutex_;
    Index errorOrder_ = 0;
    std::string error_;
};

}  // namespace pmsc::nodes
