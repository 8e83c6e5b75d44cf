// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

namespace pmsc::cli {

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

}  // namespace pmsc::cli
