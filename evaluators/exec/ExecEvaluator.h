// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameWriter.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/PointPositions.h"

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace pmsc::evaluators::exec {

class ChildProcess;
struct Request;

/// How to run a calculation in a child process.
struct ExecOptions {
    std::string command;                         ///< run by /bin/sh -c
    std::chrono::milliseconds timeout{600'000};  ///< for the hello and for each answer
};

/// Parses the ARGS of `exec:ARGS`: `[timeout=SECONDS:]COMMAND`. Everything after the options is
/// the command, colons and spaces included. @throws InputError for an empty command or a bad
/// timeout.
ExecOptions parseExecArgs(const std::string& args);

/// A calculation that lives in another program (a renderer's bake, a DCC's rig, a simulation),
/// run as a child process that speaks the exec protocol (evaluators/exec/ExecProtocol.h,
/// docs/exec-protocol.md) on its standard input and output.
///
/// Children: the constructor starts one and reads its hello (N, C, frames). Each evaluate() takes
/// an idle child, or starts another when all are busy, so there are as many children as calls run
/// at once (one per engine worker thread) and each stays alive for the whole run. A request is one
/// message per node body: the frame and the points (a range when they are consecutive, else a list
/// of indices), answered by all the values in one message.
///
/// Faults: a child that exits, crashes, hangs past the timeout, answers the wrong size or a
/// non-finite value, or reports an error makes that call throw pmsc::EvaluatorError with one line
/// naming the command and what went wrong (and the child's last line of standard error). The child
/// is killed and dropped; the next call starts a fresh one, whose hello must agree with the first.
/// So the engine's FailurePolicy decides: StopRun ends the run (exit code 3), MarkFailedAndContinue
/// fails that frame and later frames are served by new children.
///
/// Positions: a child of protocol version 2 says where its points are (a positions request), so
/// `pmsc export-frames --positions` writes them for `pmsc train --positions`; asking a version-1
/// child, or one that answers that its points have no places, throws pmsc::InputError.
///
/// Frames as .vdb (`pmsc run --format vdb`): a child of protocol version 2 whose values have 1 or
/// 3 channels and whose points have positions offers a point light cache (scene::PointCacheGrid)
/// at them; frameWriters() asks for the positions.
///
/// Thread-safe; deterministic as far as the child is (values go through unchanged).
class ExecEvaluator final : public PointEvaluator, public PointPositionsProvider, public FrameWriterProvider {
public:
    /// Starts the first child and reads its hello. @throws EvaluatorError when it cannot start,
    /// exits, hangs or says something that is not a version-1 or version-2 hello.
    explicit ExecEvaluator(ExecOptions options);
    ~ExecEvaluator() override;

    std::string name() const override { return "exec"; }
    Index pointCount() const override { return points_; }
    Index channelCount() const override { return channels_; }
    Index frameCount() const override { return frames_; }
    /// Every request pays the child's set-up for a frame (a renderer's scene synchronisation, a
    /// rig's evaluation of its cage) besides its points: a fail-through asks once per thread.
    FailThroughShape failThroughShape() const override {
        FailThroughShape shape;
        shape.callSetUp = true;
        return shape;
    }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override;
    void evaluateAll(Index frame, double* out) const override;
    FrameSet pointPositions() const override;
    std::vector<std::shared_ptr<const FrameWriter>> frameWriters() const override;
    /// The protocol version the first child's hello gave (1 or 2).
    std::uint32_t protocolVersion() const { return version_; }

    /// Children alive now (idle ones; a busy child is counted by the call using it).
    std::size_t idleChildren() const;
    /// Children started so far, the first included (restarts after a fault count too).
    std::size_t childrenStarted() const;
    const ExecOptions& options() const { return options_; }

private:
    struct Hello;
    std::unique_ptr<ChildProcess> start(Hello& hello) const;
    std::unique_ptr<ChildProcess> acquire() const;
    void release(std::unique_ptr<ChildProcess> child) const;
    /// One request: `points`, or every point when `wholeFrame` (then `points` is not read).
    void request(Index frame, std::span<const Index> points, bool wholeFrame, double* out) const;
    /// Sends `req` (and `list`, for a list request) and reads `values` doubles into `out`.
    /// @return the error the child answered with (it serves on), or empty.
    std::string exchange(ChildProcess& child, const Request& req, std::span<const Index> list,
                         std::size_t values, double* out, const std::string& during) const;
    [[noreturn]] void fail(ChildProcess& child, const std::string& what) const;

    ExecOptions options_;
    Index points_ = 0, channels_ = 0, frames_ = 0;
    std::uint32_t version_ = 1;
    mutable std::mutex mutex_;
    mutable std::vector<std::unique_ptr<ChildProcess>> idle_;
    mutable std::size_t started_ = 0;
};

}  // namespace pmsc::evaluators::exec
