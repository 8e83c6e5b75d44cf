// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <exception>
#include <string>

namespace pmsc::app {

/// Exit codes of the `pmsc` program. Scripts (and the render farm) branch on
/// them, so they never change meaning.
enum ExitCode : int {
    kExitOk = 0,            ///< success
    kExitInternal = 1,      ///< a bug or an unexpected failure (out of memory, ...)
    kExitBadInput = 2,      ///< usage, unreadable / corrupt / mismatched input (pmsc::InputError)
    kExitEvaluator = 3,     ///< a point evaluator failed (pmsc::EvaluatorError)
    kExitIo = 4,            ///< an output could not be written (pmsc::IoError)
    kExitInterrupted = 130  ///< SIGINT or a cancelled run (128 + SIGINT, as shells report it)
};

/// What an exception means for the program: one place maps the error types to exit codes, so
/// main()'s exit code and a stats file's `exit_code`/`status` (pmsc run) always agree.
struct ExitReason {
    ExitCode code = kExitInternal;
    std::string status;   ///< "bad input", "evaluator failure", "io failure", "interrupted", "internal error"
    std::string what;     ///< the exception's own message
    std::string message;  ///< the one line to print after "pmsc: " (what, with a prefix by kind)
};
/// @param error a thrown exception (std::current_exception() in a catch block); never null.
ExitReason exitReason(const std::exception_ptr& error);

}  // namespace pmsc::app
