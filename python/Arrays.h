// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
// NumPy arrays as pmsc sees them: frames (F, N, C) in float32 or float64, viewed where they lie.
#pragma once

#include "pmsc/FrameSet.h"
#include "pmsc/NpyIO.h"

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <span>
#include <string>
#include <vector>

namespace pmsc::python {

namespace py = pybind11;

/// A (frames, points, channels) array read in place: float32 and float64 arrays in C order (the .npy
/// layout pmsc reads) are not copied; any other real array is converted to float64 once.
/// Values are read as doubles, float32 widened exactly as the .npy reader does, so a replay of an
/// array and of the same array saved with numpy.save give the same bits.
class FrameArray {
public:
    /// @param name what messages call the array ("frames")
    /// @throws InputError (as the .npy reader): not 3-dimensional (the shape is shown), a zero
    ///         dimension, a complex or non-numeric dtype, or a NaN/Inf (frame, point, channel).
    FrameArray(py::handle object, std::string name);

    Index frames() const { return frames_; }
    Index points() const { return points_; }
    Index channels() const { return channels_; }
    NpyDtype dtype() const { return dtype_; }
    const std::string& name() const { return name_; }
    /// The array itself (kept alive as long as this object).
    const py::array& array() const { return array_; }
    /// The values of float64 arrays (nullptr for float32).
    const double* doubles() const {
        return dtype_ == NpyDtype::Float64 ? static_cast<const double*>(data_) : nullptr;
    }

    /// The C values of each of `points` in `frame`, point after point. Thread-safe, GIL not needed.
    void read(Index frame, std::span<const Index> points, double* out) const;
    /// All N*C values of `frame`.
    void readFrame(Index frame, double* out) const;

private:
    py::array array_;
    std::string name_;
    const void* data_ = nullptr;
    NpyDtype dtype_ = NpyDtype::Float64;
    Index frames_ = 0, points_ = 0, channels_ = 0;
};

/// "(3, 4)": a shape as NumPy prints it.
std::string shapeText(const py::array& a);

/// `object` as a C-contiguous float64 array: no copy when it already is one.
py::array_t<double, py::array::c_style> doubleArray(py::handle object);

/// A new C-order array of `shape` in float32 or float64.
py::array newArray(NpyDtype dtype, const std::vector<py::ssize_t>& shape);

/// Writes n doubles to element `offset` onward of a float32 or float64 array's buffer (float32 rounded
/// to nearest, as the .npy writer does). Thread-safe for disjoint ranges, GIL not needed.
void storeValues(void* data, NpyDtype dtype, std::size_t offset, const double* values, std::size_t n);

/// The dtype of a float32/float64 array; InputError for another one.
NpyDtype floatDtype(const py::array& a, const std::string& name);

/// A read-only NumPy view of memory owned by `owner` (kept alive by the view).
py::array readOnlyView(const double* data, std::vector<py::ssize_t> shape,
                       std::vector<py::ssize_t> stridesInValues, py::handle owner);

}  // namespace pmsc::python
