// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <string>
#include <vector>

namespace pmsc::engine {

/// Time spent in one kind of node body over a run (summed over threads, so it
/// can exceed the wall time on several cores).
struct NodeTiming {
    std::string node;    ///< "keys", "project", "monitor", "reconstruct", "fail-through", "blend", "sink"
    double seconds = 0;  ///< sum of body durations
    Index calls = 0;     ///< bodies run (one per frame; one per chunk for fail-through and blend)
};

/// What a run did and how fast.
struct RunStats {
    Index framesRequested = 0;  ///< the frame range's count
    Index framesDelivered = 0;  ///< frames handed to the sink (including failed ones under MarkFailed)
    Index hits = 0, blends = 0, misses = 0;  ///< section 5 states of delivered, non-failed frames
    Index failed = 0;  ///< frames the evaluator failed on (delivered marked, or the one that stopped the run)
    Index forcedMisses = 0;  ///< misses forced by non-finite key values (counted in misses)
    double wallSeconds = 0;
    double framesPerSecond = 0;  ///< framesDelivered / wallSeconds
    int threads = 0;
    Index maxFramesInFlight = 0;
    Index peakFramesInFlight = 0;  ///< most frames seen between key evaluation and the sink at once
    Index chunks = 0;              ///< fail-through branches per frame
    bool cancelled = false;
    std::vector<NodeTiming> nodes;

    // --- local fail-through ---
    /// Per region: how many delivered frames it hit, blended, missed in (a whole-frame hit
    /// counts as a hit of every region). Empty without regions.
    struct RegionCounts {
        Index hits = 0, blends = 0, misses = 0;
    };
    std::vector<RegionCounts> regions;
    Index localFrames = 0;  ///< frames routed region by region
    /// Mean over delivered frames of the fraction of output points evaluated fully.
    double pointsEvaluatedFraction = 0;

    /// One JSON object: {"frames_requested":..., "hits":..., "nodes":[{"node","seconds","calls"}], ...}.
    std::string toJson(int indent = 2) const;
};

}  // namespace pmsc::engine
