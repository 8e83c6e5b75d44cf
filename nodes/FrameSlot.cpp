#include "nodes/FrameSlot.h"

#include <limits>

namespace pmsc::nodes {

namespace {
std::atomic<Index> gLiveSlots{0};
}

FrameSlot::FrameSlot(const FramePlan& plan, Index keyCount, Index basisSize, bool keepPm)
    : keyValues(static_cast<size_t>(keyCount * plan.channels)),
      coords(static_cast<size_t>(basisSize)),
      values(static_cast<size_t>(plan.outputCount() * plan.channels)),
      scratch(static_cast<size_t>(plan.scratchSize())),
      pmValues(keepPm ? static_cast<size_t>(plan.outputCount() * plan.channels) : 0) {
    gLiveSlots.fetch_add(1, std::memory_order_relaxed);
}

FrameSlot::~FrameSlot() { gLiveSlots.fetch_sub(1, std::memory_order_relaxed); }

void FrameSlot::enableRegions(const RegionMultiplier& regions, Index points, Index c) {
    const Index r = regions.regionCount();
    regionKeyValues.assign(regions.regionKeyPoints().size() * size_t(c), 0.0);
    regionCoords.assign(size_t(regions.coordsSize()), 0.0);
    regionKeyErrors.assign(size_t(r), 0.0);
    regionStates.assign(size_t(r), CacheState::Hit);
    regionWeights.assign(size_t(r), 0.0);
    pointWeights.assign(size_t(points), 0.0);
    localPoints.assign(size_t(points), 0);
    localFull.assign(size_t(points * c), 0.0);
}

void FrameSlot::enableSentinels(Index count, Index c) { sentinelValues.assign(size_t(count * c), 0.0); }

std::size_t FrameSlot::bytes() const {
    const auto of = [](const auto& v) { return v.capacity() * sizeof(v[0]); };
    return sizeof(*this) + of(keyValues) + of(coords) + of(values) + of(scratch) + of(pmValues) +
           of(regionKeyValues) + of(regionCoords) + of(regionKeyErrors) + of(regionStates) +
           of(regionWeights) + of(pointWeights) + of(localPoints) + of(localFull) + of(sentinelValues);
}

Index FrameSlot::liveCount() { return gLiveSlots.load(std::memory_order_relaxed); }

void FrameSlot::reset(Index sequenceNumber, Index frameNumber) {
    sequence = sequenceNumber;
    frame = frameNumber;
    keysFinite = true;
    sentinelsComputed = false;
    keyError = 0;
    decision = CacheDecision{};
    keyErrorParts = PredictedParts{};
    pmValid = false;
    estimated = false;
    local = false;
    localCount = 0;
    regionsEvaluated = false;
    pointsEvaluated = 0;
    chunksLeft.store(0, std::memory_order_relaxed);
    std::lock_guard lock(errorMutex_);
    failed_.store(false, std::memory_order_relaxed);
    errorOrder_ = std::numeric_limits<Index>::max();
    error_.clear();
}

void FrameSlot::fail(const std::string& node, const std::string& what, Index order) {
    std::lock_guard lock(errorMutex_);
    if (failed_.load(std::memory_order_relaxed) && order >= errorOrder_) return;
    errorOrder_ = order;
    error_ = "frame " + std::to_string(frame) + ": node '" + node + "': " + what;
    failed_.store(true, std::memory_order_release);
}

}  // namespace pmsc::nodes
