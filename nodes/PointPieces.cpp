#include "nodes/PointPieces.h"

#include <tbb/parallel_for.h>

#include <algorithm>

namespace pmsc::nodes {

void evaluateInPieces(const PointEvaluator& evaluator, Index frame, std::span<const Index> points,
                      Index channels, Index piecePoints, double* out) {
    const auto n = static_cast<Index>(points.size());
#if defined(__SANITIZE_THREAD__)
    const bool pieces = false;
#else
    const bool pieces = piecePoints > 0 && n > piecePoints;
#endif
    if (!pieces) {
        evaluator.evaluate(frame, points, out);
        return;
    }
    const Index count = (n + piecePoints - 1) / piecePoints;
    tbb::parallel_for(Index(0), count, [&](Index p) {
        const Index first = p * piecePoints, size = std::min(piecePoints, n - first);
        evaluator.evaluate(frame, points.subspan(size_t(first), size_t(size)), out + first * channels);
    });
}

}  // namespace pmsc::nodes
