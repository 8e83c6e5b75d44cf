// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/SoftCache.h"

namespace pmsc::nodes {

/// Where a frame goes after the error monitor.
enum class Route : int {
    Reconstruct = 0,  ///< a hit: point multiplication only
    FailThrough = 1,  ///< a blend or a miss: the fail-through branches
    Done = 2,         ///< a failed frame: straight to the sink
};

/// Step 3 (section 5): the key points' RMS error decides hit / blend / miss
/// and the weight of the full result. Non-finite key values are a miss with
/// weight 1 (the PM result would be built from garbage). Thread-safe.
class ErrorMonitor {
public:
    static constexpr const char* kName = "monitor";

    /// @param[in] keepPm  the PM result is wanted for every frame (diagnostics), so a miss
    ///                    with finite keys still goes through reconstruction first
    ErrorMonitor(const PointMultiplier& pm, SoftCachePolicy policy, bool keepPm)
        : pm_(pm), policy_(policy), keepPm_(keepPm) {}

    Route operator()(FrameSlot& slot) const;

private:
    const PointMultiplier& pm_;
    SoftCachePolicy policy_;
    bool keepPm_;
};

}  // namespace pmsc::nodes
