#include "nodes/RunControl.h"

namespace pmsc::nodes {

bool RunControl::cancelled() {
    bool stop = aborted_.load(std::memory_order_acquire);
    if (!stop && cancelFlag_ && cancelFlag_->load(std::memory_order_acquire)) {
        cancelledByFlag_.store(true, std::memory_order_release);
        stop = true;
    }
    if (stop && cancelHook_) std::call_once(hookOnce_, cancelHook_);
    return stop;
}

void RunControl::abort(std::exception_ptr error) {
    {
        std::lock_guard lock(mutex_);
        if (!abortError_) abortError_ = std::move(error);
    }
    aborted_.store(true, std::memory_order_release);
    cancelled();
}

std::exception_ptr RunControl::abortError() const {
    std::lock_guard lock(mutex_);
    return abortError_;
}

void RunControl::stopAfter(Index sequence) {
    Index current = stopSequence_.load(std::memory_order_relaxed);
    while (sequence < current &&
           !stopSequence_.compare_exchange_weak(current, sequence, std::memory_order_acq_rel)) {
    }
}

void RunControl::setRunError(std::string message) {
    if (hasRunError_.load(std::memory_order_acquire)) return;  // only the sink calls this, in order
    runError_ = std::move(message);
    hasRunError_.store(true, std::memory_order_release);
}

void RunControl::frameStarted() {
    const Index now = inFlight_.fetch_add(1, std::memory_order_relaxed) + 1;
    Index peak = peakInFlight_.load(std::memory_order_relaxed);
    while (now > peak && !peakInFlight_.compare_exchange_weak(peak, now, std::memory_order_relaxed)) {
    }
}

void RunControl::frameFinished() { inFlight_.fetch_sub(1, std::memory_order_relaxed); }

}  // namespace pmsc::nodes
