#include "nodes/KeyPointEvaluator.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <span>

namespace pmsc::nodes {

void KeyPointEvaluator::operator()(FrameSlot& slot) const {
    const Index k = model_.keyCount(), c = model_.channels;
    // ThreadSanitizer cannot follow a parallel_for through the uninstrumented libtbb: TSan builds
    // evaluate the keys in one call (the same values).
#if defined(__SANITIZE_THREAD__)
    const bool pieces = false;
#else
    const bool pieces = piecePoints_ > 0 && k > piecePoints_;
#endif
    try {
        if (pieces) {
            // Fixed pieces, each writing its own rows: the values do not depend on scheduling.
            const Index count = (k + piecePoints_ - 1) / piecePoints_;
            tbb::parallel_for(Index(0), count, [&](Index p) {
                const Index first = p * piecePoints_, n = std::min(piecePoints_, k - first);
                evaluator_.evaluate(
                    slot.frame, std::span<const Index>(model_.keyPoints).subspan(size_t(first), size_t(n)),
                    slot.keyValues.data() + first * c);
            });
        } else {
            evaluator_.evaluate(slot.frame, model_.keyPoints, slot.keyValues.data());
        }
    } catch (const std::exception& e) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': " + e.what());
        return;
    } catch (...) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': unknown exception");
        return;
    }
    bool finite = true;
    for (const double v : slot.keyValues) finite = finite && std::isfinite(v);
    slot.keysFinite = finite;
}

}  // namespace pmsc::nodes
