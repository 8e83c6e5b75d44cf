// Errors as Python exceptions with the command line's messages, and long calls with the GIL released.
#include "python/PyErrors.h"

#include "app/ExitCodes.h"
#include "pmsc/Errors.h"

#include <stdexcept>

#include <pybind11/eval.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <thread>

namespace pmsc::python {
namespace {

// --- errors -----------------------------------------------------------------------------------------

/// The exception classes, made once at import (Python code, so they subclass the builtins naturally).
const char* kExceptions = R"(
class Error(Exception):
    """A pmsc failure; str(e) is the line `pmsc` prints after "pmsc: ", e.exit_code its exit code."""
    exit_code = 1
class InputError(Error, ValueError):
    """Bad input: a file, an array's shape/dtype/values, an option, sizes that disagree (exit code 2)."""
    exit_code = 2
class EvaluatorError(Error, RuntimeError):
    """A point evaluator failed; a Python evaluator's own exception is the __cause__ (exit code 3)."""
    exit_code = 3
class IoError(Error, OSError):
    """An output could not be written (exit code 4)."""
    exit_code = 4
class Cancelled(Error):
    """A run or a training was cancelled (exit code 130)."""
    exit_code = 130
)";

py::object exceptionClass(const char* name) { return py::module_::import("pmsc").attr(name); }

}  // namespace

void setPythonError(const std::exception_ptr& error, const py::object& cause) {
    const app::ExitReason reason = app::exitReason(error);
    const char* name = "Error";
    switch (reason.code) {
        case app::kExitBadInput:
            name = "InputError";
            break;
        case app::kExitEvaluator:
            name = "EvaluatorError";
            break;
        case app::kExitIo:
            name = "IoError";
            break;
        case app::kExitInterrupted:
            name = "Cancelled";
            break;
        default:
            break;
    }
    py::object type = exceptionClass(name);
    py::object value = type(reason.message);
    if (!cause.is_none()) PyException_SetCause(value.ptr(), cause.inc_ref().ptr());
    PyErr_SetObject(type.ptr(), value.ptr());
}

namespace {

// NOLINTNEXTLINE(performance-unnecessary-value-param): the signature pybind11 registers
void translate(std::exception_ptr p) {
    try {
        std::rethrow_exception(p);
    } catch (const InputError&) {
        setPythonError(p);
    } catch (const EvaluatorError&) {
        setPythonError(p);
    } catch (const IoError&) {
        setPythonError(p);
    } catch (const Cancelled&) {
        setPythonError(p);
    } catch (const std::invalid_argument&) {
        setPythonError(p);  // bad options: exit code 2 on the command line too
    }
    // Anything else goes on to pybind11's own translators.
}

}  // namespace

void registerErrors(py::module_& m) {
    py::exec(kExceptions, m.attr("__dict__"));
    py::register_exception_translator(&translate);
}

// --- running with the GIL released, interruptible ---------------------------------------------------------

void runReleased(std::atomic<bool>& cancel, const std::function<void()>& fn) {
    std::mutex mutex;
    std::condition_variable finished;
    bool done = false;
    std::exception_ptr error;
    std::optional<py::error_already_set> interrupt;
    {
        py::gil_scoped_release nogil;
        std::thread worker([&] {
            try {
                // A Python thread state for this thread while it works (released at once): the
                // evaluator's calls on it reuse it, and it is deleted when the run ends.
                py::gil_scoped_acquire state;
                py::gil_scoped_release released;
                fn();
            } catch (...) {
                error = std::current_exception();
            }
            std::lock_guard lock(mutex);
            done = true;
            finished.notify_all();
        });
        for (;;) {
            {
                std::unique_lock lock(mutex);
                if (finished.wait_for(lock, std::chrono::milliseconds(50), [&] { return done; })) break;
            }
            py::gil_scoped_acquire gil;
            if (!interrupt && PyErr_CheckSignals() != 0) {
                interrupt.emplace();  // fetches KeyboardInterrupt (or whatever the handler raised)
                cancel = true;
            }
        }
        worker.join();
    }
    if (interrupt) {
        error = nullptr;
        throw std::move(*interrupt);
    }
    if (error) std::rethrow_exception(error);
}

}  // namespace pmsc::python
