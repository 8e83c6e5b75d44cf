// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "engine/Engine.h"
#include "pmsc/FrameSet.h"

#include <vector>

namespace pmsc::engine {

/// A FrameSink that keeps every frame of a run in memory: the soft-cached
/// values as a FrameSet (frames in range order) plus each frame's decision.
/// Handy for tests, `pmsc replay` and short ranges; a long range wants a
/// streaming sink instead.
class FrameSetSink : public FrameSink {
public:
    /// Per-frame record of the soft-cache decision.
    struct FrameInfo {
        Index frame = 0;
        bool failed = false;
        CacheState state = CacheState::Hit;
        double weight = 0;
        double keyError = 0;
        bool keysFinite = true;
    };

    /// @param[in] frames         frames of the range
    /// @param[in] outputPoints   points per frame (Engine::outputPoints().size())
    /// @param[in] channels       C
    /// @param[in] keepPm         also keep FrameResult::pmValues (needs keepPointMultiplication)
    FrameSetSink(Index frames, Index outputPoints, Index channels, bool keepPm = false);

    void write(const FrameResult& frame) override;

    const FrameSet& values() const { return values_; }
    const FrameSet& pmValues() const { return pm_; }  ///< empty unless keepPm
    const std::vector<FrameInfo>& info() const { return info_; }

private:
    FrameSet values_;
    FrameSet pm_;
    bool keepPm_;
    std::vector<FrameInfo> info_;
};

}  // namespace pmsc::engine
