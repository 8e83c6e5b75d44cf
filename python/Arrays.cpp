#include "python/Arrays.h"

#include "pmsc/Errors.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pmsc::python {

std::string shapeText(const py::array& a) {
    std::string s = "(";
    for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
    return s + (a.ndim() == 1 ? ",)" : ")");
}

namespace {

bool isFloat(const py::array& a, char kind, int bytes) {
    const py::dtype dt = a.dtype();
    return dt.kind() == kind && dt.itemsize() == bytes && dt.attr("isnative").cast<bool>();
}

/// The first NaN/Inf of a frame array, reported as the .npy reader reports one in a file.
template <class T>
void checkFinite(const T* values, std::size_t count, const std::string& name, Index points, Index channels) {
    const T* bad = std::find_if(values, values + count, [](T v) { return !std::isfinite(v); });
    if (bad == values + count) return;
    const std::size_t i = static_cast<std::size_t>(bad - values);
    const std::size_t c = static_cast<std::size_t>(channels), n = static_cast<std::size_t>(points);
    const std::string what = std::isnan(*bad) ? "NaN" : (*bad > 0 ? "+Inf" : "-Inf");
    throw InputError(name + ": " + what + " at frame " + std::to_string(i / (n * c)) + ", point " +
                     std::to_string((i / c) % n) + ", channel " + std::to_string(i % c) +
                     " (frames must be finite)");
}

}  // namespace

NpyDtype floatDtype(const py::array& a, const std::string& name) {
    if (isFloat(a, 'f', 4)) return NpyDtype::Float32;
    if (isFloat(a, 'f', 8)) return NpyDtype::Float64;
    throw InputError(name + ": unsupported dtype " + py::str(a.dtype()).cast<std::string>() +
                     " (pmsc reads float32 or float64)");
}

FrameArray::FrameArray(py::handle object, std::string name) : name_(std::move(name)) {
    py::array a = py::array::ensure(object);
    if (!a) throw InputError(name_ + ": not an array (expected shape (frames, points, channels))");
    const char kind = a.dtype().kind();
    if (kind != 'f' && kind != 'i' && kind != 'u' && kind != 'b')
        throw InputError(name_ + ": unsupported dtype " + py::str(a.dtype()).cast<std::string>() +
                         " (pmsc reads float32 or float64)");
    if (a.ndim() != 3)
        throw InputError(name_ + ": shape " + shapeText(a) + " has " + std::to_string(a.ndim()) +
                         " dimensions; frames are (frames, points, channels)");
    if (a.shape(0) == 0 || a.shape(1) == 0 || a.shape(2) == 0)
        throw InputError(name_ + ": shape " + shapeText(a) + " has a zero dimension");
    const bool contiguous = (a.flags() & py::array::c_style) != 0;
    if (contiguous && isFloat(a, 'f', 4)) {
        dtype_ = NpyDtype::Float32;
    } else if (contiguous && isFloat(a, 'f', 8)) {
        dtype_ = NpyDtype::Float64;
    } else {
        // Another layout or type: one conversion to C-order float64 (float32 keeps its type).
        const bool f32 = isFloat(a, 'f', 4);
        a = f32 ? py::array(py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(a))
                : py::array(py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(a));
        dtype_ = f32 ? NpyDtype::Float32 : NpyDtype::Float64;
    }
    array_ = a;
    data_ = array_.data();
    frames_ = a.shape(0);
    points_ = a.shape(1);
    channels_ = a.shape(2);
    const std::size_t count = static_cast<std::size_t>(a.size());
    py::gil_scoped_release nogil;
    if (dtype_ == NpyDtype::Float32) {
        checkFinite(static_cast<const float*>(data_), count, name_, points_, channels_);
    } else {
        checkFinite(static_cast<const double*>(data_), count, name_, points_, channels_);
    }
}

void FrameArray::read(Index frame, std::span<const Index> points, double* out) const {
    if (frame < 0 || frame >= frames_)
        throw std::out_of_range(name_ + ": frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(frames_) + ")");
    const std::size_t base = static_cast<std::size_t>(frame * points_ * channels_);
    for (std::size_t i = 0; i < points.size(); ++i) {
        const Index p = points[i];
        if (p < 0 || p >= points_)
            throw std::out_of_range(name_ + ": point " + std::to_string(p) + " outside [0, " +
                                    std::to_string(points_) + ")");
        const std::size_t at = base + static_cast<std::size_t>(p * channels_);
        for (Index c = 0; c < channels_; ++c) {
            out[i * static_cast<std::size_t>(channels_) + static_cast<std::size_t>(c)] =
                dtype_ == NpyDtype::Float32 ? static_cast<double>(static_cast<const float*>(data_)[at + c])
                                            : static_cast<const double*>(data_)[at + c];
        }
    }
}

void FrameArray::readFrame(Index frame, double* out) const {
    if (frame < 0 || frame >= frames_)
        throw std::out_of_range(name_ + ": frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(frames_) + ")");
    const std::size_t n = static_cast<std::size_t>(points_ * channels_);
    const std::size_t base = static_cast<std::size_t>(frame) * n;
    if (dtype_ == NpyDtype::Float32) {
        const float* in = static_cast<const float*>(data_) + base;
        std::transform(in, in + n, out, [](float v) { return static_cast<double>(v); });
    } else {
        std::copy_n(static_cast<const double*>(data_) + base, n, out);
    }
}

py::array_t<double, py::array::c_style> doubleArray(py::handle object) {
    auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(object);
    if (!a) throw py::error_already_set();
    return a;
}

py::array newArray(NpyDtype dtype, const std::vector<py::ssize_t>& shape) {
    if (dtype == NpyDtype::Float32) return py::array_t<float>(shape);
    return py::array_t<double>(shape);
}

void storeValues(void* data, NpyDtype dtype, std::size_t offset, const double* values, std::size_t n) {
    if (dtype == NpyDtype::Float32) {
        std::transform(values, values + n, static_cast<float*>(data) + offset,
                       [](double v) { return static_cast<float>(v); });
    } else {
        std::copy_n(values, n, static_cast<double*>(data) + offset);
    }
}

py::array readOnlyView(const double* data, std::vector<py::ssize_t> shape,
                       std::vector<py::ssize_t> stridesInValues, py::handle owner) {
    for (auto& s : stridesInValues) s *= static_cast<py::ssize_t>(sizeof(double));
    py::array view(py::dtype::of<double>(), std::move(shape), std::move(stridesInValues), data, owner);
    py::detail::array_proxy(view.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
    return view;
}

}  // namespace pmsc::python
