#include "nodes/Reconstructor.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>

namespace pmsc::nodes {

namespace {

/// A frame of at least this many points reconstructs in parallel blocks of kBlockPoints. Why: a
/// hit's reconstruction is one pass over the N x M basis, the largest single step of a hit for a
/// large cache (253,972 voxels, M = 40: about 10 ms on one core), and it is what an interactive
/// client waits for; below this size the tasks' overhead outweighs the gain. The blocks depend
/// on N only, and each point's sum runs over the basis in the same order inside any block, so
/// the output is the same bit for bit at any thread count.
/// ThreadSanitizer cannot follow a parallel_for through the uninstrumented libtbb (the engine's
/// annotations cover its graph's messages only), so TSan builds reconstruct in one piece: the
/// same values.
#if defined(__SANITIZE_THREAD__)
constexpr Index kParallelPoints = std::numeric_limits<Index>::max();
#else
constexpr Index kParallelPoints = 65536;
#endif
constexpr Index kBlockPoints = 16384;

}  // namespace

bool Reconstructor::operator()(FrameSlot& slot) const {
    const bool hit = slot.decision.state == CacheState::Hit;
    if (slot.pmValid) {  // estimate() ran: the same values, computed once
        if (hit) {
            slot.values.swap(slot.pmValues);  // both hold outputCount * C; a hit keeps no PM apart
            slot.pmValid = false;
        }
        return hit;
    }
    reconstructInto(slot, hit ? slot.values.data() : slot.pmValues.data());
    slot.pmValid = !hit;
    return hit;
}

void Reconstructor::estimate(FrameSlot& slot) const {
    reconstructInto(slot, slot.pmValues.data());
    slot.pmValid = true;
}

void Reconstructor::reconstructInto(const FrameSlot& slot, double* out) const {
    if (plan_.allPoints && plan_.points >= kParallelPoints) {
        const Index n = plan_.points, c = plan_.channels;
        const Index blocks = (n + kBlockPoints - 1) / kBlockPoints;
        tbb::parallel_for(Index(0), blocks, [&](Index b) {
            const Index first = b * kBlockPoints, count = std::min(kBlockPoints, n - first);
            pm_.reconstructRange(slot.coords.data(), first, count, out + first * c);
        });
    } else if (plan_.allPoints) {
        pm_.reconstruct(slot.coords.data(), out);
    } else {
        pm_.reconstructPoints(slot.coords.data(), plan_.outputPoints, out);
    }
}

}  // namespace pmsc::nodes
