// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <array>
#include <atomic>
#include <exception>
#include <functional>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

namespace pmsc::nodes {

/// State shared by the node bodies of one run: cancellation, the stop point of
/// a failed run, the first error, and the counters the engine's stats read.
/// Thread-safe.
class RunControl {
public:
    /// @param[in] cancelFlag  set by another thread to cancel (may be null); must outlive the run
    explicit RunControl(const std::atomic<bool>* cancelFlag = nullptr) : cancelFlag_(cancelFlag) {}

    /// Called once, by the first body that sees the cancellation (the engine
    /// passes graph.cancel()), so tasks already queued are dropped.
    void setCancelHook(std::function<void()> hook) { cancelHook_ = std::move(hook); }

    /// True once the run must stop delivering: the external flag was set, or
    /// abort() was called. The first caller that sees it fires the cancel hook.
    /// Bodies call this on entry, so a cancelled run ends within one body's time.
    bool cancelled();

    /// Ends the run at once with `error` (a writer's exception), rethrown by the engine.
    void abort(std::exception_ptr error);
    std::exception_ptr abortError() const;
    bool externallyCancelled() const { return cancelledByFlag_.load(std::memory_order_acquire); }

    /// StopRun: no frame with a sequence number above `sequence` is started any more.
    void stopAfter(Index sequence);
    Index stopSequence() const { return stopSequence_.load(std::memory_order_acquire); }

    /// The first failed frame in order under StopRun (set by the sink).
    void setRunError(std::string message);
    const std::string& runError() const { return runError_; }
    bool hasRunError() const { return hasRunError_.load(std::memory_order_acquire); }

    /// Frames between key evaluation and the sink, and the most seen at once.
    void frameStarted();
    void frameFinished();
    Index peakInFlight() const { return peakInFlight_.load(std::memory_order_relaxed); }

    /// Counters written by the sink (one thread), read by anyone.
    std::atomic<Index> delivered{0}, hits{0}, blends{0}, misses{0}, failed{0}, forcedMisses{0};
    /// Written by the sink only, read after the run: per-region states (hit, blend, miss counts),
    /// local frames, and the sum over delivered frames of the fraction of points evaluated fully.
    std::vector<std::array<Index, 3>> regionStates;
    Index localFrames = 0;
    double pointsEvaluatedFractionSum = 0;

private:
    const std::atomic<bool>* cancelFlag_;
    std::function<void()> cancelHook_;
    std::atomic<bool> aborted_{false};
    std::atomic<bool> cancelledByFlag_{false};
    std::once_flag hookOnce_;
    mutable std::mutex mutex_;
    std::exception_ptr abortError_;
    std::atomic<Index> stopSequence_{std::numeric_limits<Index>::max()};
    std::atomic<bool> hasRunError_{false};
    std::string runError_;
    std::atomic<Index> inFlight_{0};
    std::atomic<Index> peakInFlight_{0};
};

}  // namespace pmsc::nodes
