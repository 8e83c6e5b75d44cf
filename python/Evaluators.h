// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
// The two PointEvaluators the Python module adds: recorded frames in a NumPy array, and a Python callable.
#pragma once

#include "python/Arrays.h"

#include "pmsc/PointEvaluator.h"

#include <pybind11/pybind11.h>

#include <string>

namespace pmsc::python {

/// Recorded frames in a NumPy array standing in for the calculation, as evaluators::ReplayEvaluator
/// does for a .npy file (same name, "replay", so messages read the same): `pmsc.replay(model, array)`.
/// The array is read where it lies. Thread-safe; never touches the GIL.
class ArrayEvaluator final : public PointEvaluator {
public:
    explicit ArrayEvaluator(FrameArray frames) : frames_(std::move(frames)) {}

    std::string name() const override { return "replay"; }
    Index pointCount() const override { return frames_.points(); }
    Index channelCount() const override { return frames_.channels(); }
    Index frameCount() const override { return frames_.frames(); }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        frames_.read(frame, points, out);
    }
    void evaluateAll(Index frame, double* out) const override { frames_.readFrame(frame, out); }

    const FrameArray& frames() const { return frames_; }

private:
    FrameArray frames_;
};

/// A Python callable `f(frame, point_indices) -> values` as the expensive calculation: `point_indices`
/// is an int64 array of P point indices (its own copy), `values` anything NumPy reads as P x C numbers
/// (shape (P, C) or (P*C,); a C-order float64 array is read in place, anything else converted). The engine
/// calls it from its worker threads; each call takes the GIL for the call only, so the engine's own work
/// (projection, reconstruction, blending, other frames' bookkeeping) and any NumPy work that releases the GIL
/// run in parallel with it.
///
/// A Python exception becomes a std::runtime_error "TypeName: message" (the engine then names the
/// frame and the node); the first one is kept so the module can chain it as the cause.
class CallableEvaluator final : public PointEvaluator {
public:
    /// @pre the GIL is held.
    CallableEvaluator(py::object function, Index points, Index channels, Index frames,
                      FailThroughShape shape);
    /// @pre the GIL is held (drops the references).
    ~CallableEvaluator() override;

    std::string name() const override { return "python"; }
    Index pointCount() const override { return points_; }
    Index channelCount() const override { return channels_; }
    Index frameCount() const override { return frames_; }
    FailThroughShape failThroughShape() const override { return shape_; }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override;

    /// The first exception the callable raised (None if none). @pre the GIL is held.
    py::object firstError() const;

private:
    py::object function_;
    Index points_, channels_, frames_;
    FailThroughShape shape_;
    mutable py::object firstError_;  ///< set and read under the GIL
};

}  // namespace pmsc::python
