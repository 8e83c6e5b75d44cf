#include "nodes/LocalBranch.h"

#include "pmsc/SoftCache.h"

#include <algorithm>
#include <cmath>
#include <span>
#include <string>

namespace pmsc::nodes {

Index LocalBranch::piecePoints(const FrameSlot& slot) const {
    if (pieceCount_ > 0) return (slot.localCount + pieceCount_ - 1) / pieceCount_;
    return piecePoints_;
}

Index LocalBranch::messages(const FrameSlot& slot) const {
    const Index size = piecePoints(slot);
    const Index pieces = slot.localCount == 0 ? 0 : size <= 0 ? 1 : (slot.localCount + size - 1) / size;
    return regions_.regionCount() + pieces;
}

void LocalBranch::operator()(FrameSlot& slot, Index message) const {
    if (slot.failed()) return;
    const Index regions = regions_.regionCount();
    if (message >= regions) {
        evaluatePiece(slot, message - regions);
        return;
    }
    if (slot.regionWeights[size_t(message)] < 1)
        regions_.reconstruct(message, slot.regionCoords.data() + regions_.coordsOffset(message),
                             slot.values.data());
}

void LocalBranch::evaluatePiece(FrameSlot& slot, Index piece) const {
    const Index size = piecePoints(slot);
    const Index first = size <= 0 ? 0 : piece * size;
    const Index last = size <= 0 ? slot.localCount : std::min(slot.localCount, first + size);
    const std::span<const Index> set(slot.localPoints.data() + first, size_t(last - first));
    double* out = slot.localFull.data() + first * channels_;
    const Index order = regions_.regionCount() + piece;  // the lowest failing message names the frame's error
    try {
        evaluator_.evaluate(slot.frame, set, out);
    } catch (const std::exception& e) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': " + e.what(), order);
        return;
    } catch (...) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': unknown exception", order);
        return;
    }
    const Index n = Index(set.size()) * channels_;
    for (Index i = 0; i < n; ++i) {
        if (!std::isfinite(out[i])) {
            slot.fail(kName,
                      "evaluator '" + evaluator_.name() + "' returned " + std::to_string(out[i]) +
                          " at point " + std::to_string(set[size_t(i / channels_)]) + " channel " +
                          std::to_string(i % channels_),
                      order);
            return;
        }
    }
}

void LocalCombiner::operator()(FrameSlot& slot) const {
    if (slot.failed()) return;
    const Index c = channels_;
    for (Index i = 0; i < slot.localCount; ++i) {
        const Index p = slot.localPoints[size_t(i)];
        const double w = slot.pointWeights[size_t(p)];
        const double* full = slot.localFull.data() + i * c;
        double* out = slot.values.data() + p * c;
        if (w >= 1) {
            for (Index ch = 0; ch < c; ++ch) out[ch] = full[ch];
        } else {
            blendPoints(w, tolerance_, c, out, full, out, 1);
        }
    }
}

}  // namespace pmsc::nodes
