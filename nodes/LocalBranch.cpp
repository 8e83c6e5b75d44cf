#include "nodes/LocalBranch.h"

#include <cmath>
#include <string>

namespace pmsc::nodes {

void LocalBranch::operator()(FrameSlot& slot, Index region) const {
    if (slot.failed()) return;
    const double w = slot.regionWeights[size_t(region)];
    if (w < 1) regions_.reconstruct(region, slot.regionCoords.data() + regions_.coordsOffset(region), slot.values.data());
    if (!(w > 0)) return;
    const std::vector<Index>& set = regions_.failSet(region);
    double* out = slot.localFull.data() + regions_.failOffset(region) * channels_;
    try {
        evaluator_.evaluate(slot.frame, set, out);
    } catch (const std::exception& e) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': " + e.what(), region);
        return;
    } catch (...) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': unknown exception", region);
        return;
    }
    const Index n = Index(set.size()) * channels_;
    for (Index i = 0; i < n; ++i) {
        if (!std::isfinite(out[i])) {
            slot.fail(kName,
                      "evaluator '" + evaluator_.name() + "' returned " + std::to_string(out[i]) + " at point " +
                          std::to_string(set[size_t(i / channels_)]) + " channel " + std::to_string(i % channels_),
                      region);
            return;
        }
    }
}

void LocalCombiner::operator()(FrameSlot& slot) const {
    if (slot.failed()) return;
    const Index n = Index(slot.pointWeights.size());
    const Index c = channels_;
    for (Index p = 0; p < n; ++p) {
        const double w = slot.pointWeights[size_t(p)];
        if (!(w > 0)) continue;
        const Index at = regions_.fullValueAt(p, slot.regionWeights);
        const double* full = slot.localFull.data() + at * c;
        double* out = slot.values.data() + p * c;
        if (w >= 1) {
            for (Index ch = 0; ch < c; ++ch) out[ch] = full[ch];
        } else {
            for (Index ch = 0; ch < c; ++ch) out[ch] = (1.0 - w) * out[ch] + w * full[ch];
        }
    }
}

}  // namespace pmsc::nodes
