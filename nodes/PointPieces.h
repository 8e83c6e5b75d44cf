// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/PointEvaluator.h"

#include <span>

namespace pmsc::nodes {

/// Evaluates `points` of `frame` into `out` (points.size() * channels values, in the order of
/// `points`): in one call, or, when piecePoints > 0 and there are more points than that, in
/// parallel pieces of piecePoints points (EngineOptions::keyPiecePoints), each writing its own rows,
/// so the values do not depend on the scheduling. What the key points and a hit's check points
/// share: for one frame at a time (an interactive client) they are the calculation a move waits
/// for, and one call would leave every core but one idle. Exceptions propagate (from any piece).
/// ThreadSanitizer builds evaluate in one call (it cannot follow a parallel_for through the
/// uninstrumented libtbb): the same values.
void evaluateInPieces(const PointEvaluator& evaluator, Index frame, std::span<const Index> points,
                      Index channels, Index piecePoints, double* out);

}  // namespace pmsc::nodes
