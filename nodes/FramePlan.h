// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"

#include <span>
#include <vector>

namespace pmsc::nodes {

/// What every frame of one run computes, decided once before the first frame:
/// which points the output holds (all N, or the consumer's subset) and how a
/// fail-through (section 5) splits those points into chunks that run as
/// parallel branches.
///
/// Decision (the paper leaves it open): a fail-through does not evaluate the
/// key points a second time. Their full values are already known from the key
/// evaluation that every frame starts with, so each chunk asks the evaluator
/// only for its non-key points and copies the key values in. This is what keeps
/// a miss within the paper's "less than 5% slower" than a plain full evaluation
/// (section 7): the key evaluation is not wasted, only the projection and the
/// error test are added. The sentinels a key node computes with the keys (Engine.cpp,
/// sentinelsWithTheKeys) are reused the same way. When a frame's key values are not finite the chunk
/// evaluates every point of its range instead (see FailThroughEvaluator).
struct FramePlan {
    /// One branch of a fail-through: output positions [firstOutput, firstOutput + outputCount).
    struct Chunk {
        Index firstOutput = 0;
        Index outputCount = 0;
        std::vector<Index> evalPoints;  ///< non-key points of the range (evaluator indices)
        std::vector<Index> evalOutput;  ///< output position of each evalPoints entry
        std::vector<Index> keyOutput;   ///< output positions in the range that are key points
        /// Their index in Model::keyPoints, or K + i for the i-th of the sentinels computed with
        /// the keys (`keySentinels` of make(); FrameSlot::sentinelValues).
        std::vector<Index> keyNumber;
    };

    Index points = 0;                 ///< N of the model and evaluator
    Index channels = 0;               ///< C
    std::vector<Index> outputPoints;  ///< the points a frame's output holds, in output order
    bool allPoints = true;            ///< outputPoints == 0 .. N-1
    bool wholeFrame = false;          ///< fail-through by one evaluateAll() call instead of chunks
    bool keySentinels = false;        ///< chunks reuse the sentinels computed with the keys too
    std::vector<Chunk> chunks;        ///< at least one

    Index outputCount() const { return static_cast<Index>(outputPoints.size()); }
    /// Doubles of the scratch buffer a frame slot needs for a fail-through.
    Index scratchSize() const { return (wholeFrame ? points : outputCount()) * channels; }

    /// @param[in] model        keys, N and C
    /// @param[in] wanted       points the consumer needs (empty = all N), any order, no duplicates
    /// @param[in] chunkPoints  output points per fail-through chunk (> 0)
    /// @param[in] wholeFrame   use PointEvaluator::evaluateAll() for a fail-through (one branch),
    ///                         for evaluators whose full evaluation shares work between points
    /// @param[in] keySentinels the sentinels the key node computes with the keys (KeyPointEvaluator;
    ///                         empty: none), reused by the chunks as the keys are
    /// @throws pmsc::InputError for a wanted point out of range or repeated, or chunkPoints <= 0.
    static FramePlan make(const Model& model, std::span<const Index> wanted, Index chunkPoints,
                          bool wholeFrame, std::span<const Index> keySentinels = {});
};

}  // namespace pmsc::nodes
