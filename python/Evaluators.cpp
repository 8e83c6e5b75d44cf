#include "python/Evaluators.h"

#include <algorithm>
#include <stdexcept>

namespace pmsc::python {

CallableEvaluator::CallableEvaluator(py::object function, Index points, Index channels, Index frames,
                                     FailThroughShape shape)
    : function_(std::move(function)), points_(points), channels_(channels), frames_(frames), shape_(shape) {}

CallableEvaluator::~CallableEvaluator() = default;

py::object CallableEvaluator::firstError() const { return firstError_ ? firstError_ : py::none(); }

void CallableEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    if (frame < 0 || frame >= frames_)
        throw std::out_of_range("frame " + std::to_string(frame) + " outside [0, " + std::to_string(frames_) +
                                ")");
    const std::size_t count = points.size() * static_cast<std::size_t>(channels_);
    std::string error;
    {
        // The engine's TBB workers are not Python threads: the first call on each creates its Python
        // thread state, which is then kept for the (pooled) thread's life instead of being created
        // and destroyed around every call. Threads Python knows keep theirs as they are.
        const bool foreign = PyGILState_GetThisThreadState() == nullptr &&
                             PYBIND11_TLS_GET_VALUE(py::detail::get_internals().tstate) == nullptr;
        py::gil_scoped_acquire gil;
        if (foreign) gil.inc_ref();
        try {
            // The indices are copied: the span is the engine's buffer, valid only during this call,
            // and a callable may keep what it is given.
            py::array_t<std::int64_t> indices(static_cast<py::ssize_t>(points.size()));
            std::copy(points.begin(), points.end(), indices.mutable_data());
            py::object result = function_(frame, indices);
            auto values = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(result);
            if (!values) throw py::error_already_set();
            if (static_cast<std::size_t>(values.size()) != count) {
                std::string shape = "(";
                for (py::ssize_t d = 0; d < values.ndim(); ++d)
                    shape += (d ? ", " : "") + std::to_string(values.shape(d));
                shape += values.ndim() == 1 ? ",)" : ")";
                throw std::runtime_error("returned shape " + shape + " for " + std::to_string(points.size()) +
                                         " points x " + std::to_string(channels_) + " channels");
            }
            std::copy_n(values.data(), count, out);
            return;
        } catch (py::error_already_set& e) {
            error = py::str(e.type().attr("__name__")).cast<std::string>() + ": " +
                    py::str(e.value()).cast<std::string>();
            if (!firstError_) firstError_ = e.value();  // the GIL orders the engine's threads here
        }
    }
    throw std::runtime_error(error);
}

}  // namespace pmsc::python
