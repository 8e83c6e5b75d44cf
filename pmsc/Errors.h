// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <stdexcept>
#include <string>

namespace pmsc {

/// Typed errors. The command line maps each to one line on stderr and an exit
/// code (app/ExitCodes.h): InputError -> 2, EvaluatorError -> 3, IoError -> 4.
/// Messages name the file, the frame and the value, so one line is enough.

/// Bad input a user can fix: an unreadable, truncated or corrupt file, a wrong
/// shape or dtype, a NaN in the data, an option out of range, sizes that disagree.
struct InputError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// An output could not be written (permissions, full disk, missing folder).
struct IoError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// A point evaluator failed while computing a frame.
struct EvaluatorError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// A long operation (training, a run, a replay) was asked to stop: a progress hook returned false
/// or a cancel flag was set. The command line maps it to exit code 130.
struct Cancelled : std::runtime_error {
    using std::runtime_error::runtime_error;
};

}  // namespace pmsc
