// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
// The Python module's errors and its way of running long calls.
#pragma once

#include <pybind11/pybind11.h>

#include <atomic>
#include <exception>
#include <functional>

namespace pmsc::python {

namespace py = pybind11;

/// Defines pmsc.Error and its subclasses InputError (ValueError), EvaluatorError (RuntimeError),
/// IoError (OSError) and Cancelled in `m`, each with the command line's exit code as `exit_code`, and
/// translates pmsc's C++ exceptions (and std::invalid_argument: bad options) into them.
void registerErrors(py::module_& m);

/// Sets the Python error for a pmsc exception: the class by kind, the message exactly as the command
/// line prints it after "pmsc: " (app::exitReason), and an optional __cause__.
void setPythonError(const std::exception_ptr& error, const py::object& cause = py::none());

/// Runs fn() on a worker thread with the GIL released while this thread waits, checking Python's
/// signals every 50 ms: Ctrl-C sets `cancel` (the engine then stops within a node body's time) and
/// raises KeyboardInterrupt once the worker has stopped. The engine's threads, and a Python evaluator's
/// calls, never wait for this thread. fn's exceptions are rethrown here.
/// @pre the GIL is held.
void runReleased(std::atomic<bool>& cancel, const std::function<void()>& fn);

}  // namespace pmsc::python
