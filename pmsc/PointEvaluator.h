// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <span>
#include <string>

namespace pmsc {

/// The expensive per-point calculation that point multiplication accelerates:
/// posing a face's points, gathering indirect light at scene points, or reading
/// a recorded frame (section 2, figure 3: "the standard posing engine").
///
/// An evaluator computes any subset of points of one frame without computing
/// the others, so the runtime can evaluate only the key points (a hit), a chunk
/// of points (one branch of a parallel fail-through), or all of them (a miss).
///
/// Thread safety: evaluate() is const and must be safe to call concurrently
/// from several threads, for different frames and for disjoint chunks of the
/// same frame. Results must be deterministic: a point's value may not depend
/// on which other points are evaluated with it, nor on the thread count.
class PointEvaluator {
public:
    /// How this evaluator is best failed through: a property of the calculation, not
    /// an engine option, because only the evaluator knows whether its full evaluation shares work
    /// between points and whether a subset costs in proportion to its size.
    struct FailThroughShape {
        /// A whole-frame fail-through is one evaluateAll() call (its full pose shares work
        /// between points), not parallel chunks.
        bool wholeFrame = false;
        /// Points per chunk of a chunked fail-through; 0 = the engine's automatic size.
        Index chunkPoints = 0;
        /// evaluate() on a subset costs about in proportion to the subset (plus its dependencies),
        /// so local fail-through (only the points of regions that miss) pays off.
        bool cheapSubsets = true;
        /// Every call pays a set-up its points do not (a child process's frame change, a
        /// renderer's scene synchronisation and bake set-up): a fail-through asks in as few calls
        /// as the engine's threads run at once, one chunk per thread, and the keys and a hit's
        /// check are never cut into pieces.
        bool callSetUp = false;
    };

    virtual ~PointEvaluator() = default;

    virtual FailThroughShape failThroughShape() const { return {}; }

    /// Short name for logs and error messages ("replay", "cornell", "face").
    virtual std::string name() const = 0;
    /// N, the number of points of a full evaluation.
    virtual Index pointCount() const = 0;
    /// C, values per point (3 for positions or RGB).
    virtual Index channelCount() const = 0;
    /// Number of frames this evaluator can produce (frames are 0 .. frameCount()-1).
    virtual Index frameCount() const = 0;

    /// Evaluates frame `frame` at `points` (indices in [0, N), any order, no
    /// duplicates required) into `out`, point-major, channel-minor:
    /// out[i*C + c] is channel c of points[i].
    /// @param[out] out caller's buffer of points.size() * channelCount() doubles.
    /// @throws std::out_of_range for a bad frame or point index; evaluators may
    ///         throw std::runtime_error for their own failures.
    virtual void evaluate(Index frame, std::span<const Index> points, double* out) const = 0;

    /// Evaluates all N points of a frame into out (N*C doubles). The default
    /// calls evaluate() with 0..N-1; evaluators override it when a full pose
    /// shares work between points.
    virtual void evaluateAll(Index frame, double* out) const;

    /// Evaluates all N points of each of `frames` into out, frame after frame (frames.size() * N * C
    /// doubles; frame k at out + k*N*C), with the values evaluateAll() gives each. The default
    /// calls evaluateAll() per frame; evaluators override it when frames share work that no
    /// control changes (a renderer's gather rays traced once for a set of lights), which is how
    /// training frames are best made.
    virtual void evaluateAllFrames(std::span<const Index> frames, double* out) const;

    /// How many frames one evaluateAllFrames() call is best given (1: frames share no work, and
    /// callers spread frames over threads instead). `pmsc export-frames` asks in groups of this many.
    virtual Index framesSharingWork() const { return 1; }
};

/// Evaluates frames [first, first+count) at all points into a FrameSet
/// (used to produce training data from an evaluator).
FrameSet evaluateFrames(const PointEvaluator& evaluator, Index first, Index count);

}  // namespace pmsc
