// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <chrono>
#include <cstdio>
#include <string>
#include <string_view>

namespace pmsc::cli {

/// Progress display on stderr for long commands.
///
/// On a terminal (isatty(stderr)): one line redrawn in place, at most ten times
/// a second: "train  svd        [########............]  41%  3.2 s".
/// Otherwise (a log file, a pipe, a test): plain lines "pmsc train: svd 41% (12.0 s)"
/// at most every `logSeconds`, and nothing at all for a run shorter than that,
/// so scripts see only the command's result and, on failure, its one error line.
///
/// update() returns false once SIGINT was received (cli/Interrupt.h), which is the
/// contract of pmsc::ProgressFn: the operation then stops and throws pmsc::Cancelled.
class Progress {
public:
    /// @param label   the command ("train")
    /// @param enabled false for --quiet
    explicit Progress(std::string label, bool enabled = true, double logSeconds = 10.0);
    ~Progress();
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    /// Reports `done` of `total` in `stage`. Thread-safe enough for one caller
    /// at a time. @return false if the user interrupted.
    bool update(std::string_view stage, double done, double total);

    /// Clears the terminal line (call before printing a summary).
    void finish();

    /// Whether output goes to a terminal (bar) or not (plain lines).
    bool terminal() const { return terminal_; }

private:
    using Clock = std::chrono::steady_clock;
    std::string label_;
    bool enabled_;
    bool terminal_;
    double logSeconds_;
    Clock::time_point start_;
    Clock::time_point lastDraw_;
    bool drawn_ = false;
    std::string lastStage_;
};

}  // namespace pmsc::cli
