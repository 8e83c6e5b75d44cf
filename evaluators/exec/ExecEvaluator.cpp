// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "evaluators/exec/ExecEvaluator.h"

#include "evaluators/exec/ChildProcess.h"
#include "evaluators/exec/ExecProtocol.h"
#include "evaluators/scene/PointCacheGrid.h"
#include "evaluators/scene/VdbFrameWriter.h"
#include "pmsc/Errors.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>

namespace pmsc::evaluators::exec {

using Clock = ChildProcess::Clock;

namespace {

/// A child's standard error is emptied between requests once it passes this size.
constexpr std::size_t kErrorLogLimit = 1 << 20;
/// How long a child that failed gets to exit on its own before it is killed (for its status).
constexpr std::chrono::milliseconds kExitGrace{500};

/// "2 s", "0.5 s".
std::string seconds(std::chrono::milliseconds ms) {
    char text[32];
    std::snprintf(text, sizeof text, "%g s", static_cast<double>(ms.count()) / 1000.0);
    return text;
}

std::string shortCommand(const std::string& command) {
    return command.size() <= 80 ? command : command.substr(0, 77) + "...";
}

}  // namespace

ExecOptions parseExecArgs(const std::string& args) {
    ExecOptions options;
    std::string rest = args;
    constexpr std::string_view kTimeout = "timeout=";
    if (rest.starts_with(kTimeout)) {
        const auto colon = rest.find(':');
        const std::string value = rest.substr(
            kTimeout.size(), colon == std::string::npos ? std::string::npos : colon - kTimeout.size());
        double seconds = 0;
        const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), seconds);
        if (ec != std::errc() || end != value.data() + value.size() || !(seconds > 0) || seconds > 1e6)
            throw InputError("exec: timeout must be a number of seconds in (0, 1e6], not '" + value + "'");
        options.timeout = std::chrono::milliseconds(static_cast<long long>(std::ceil(seconds * 1000)));
        rest = colon == std::string::npos ? "" : rest.substr(colon + 1);
    }
    if (rest.find_first_not_of(" \t") == std::string::npos)
        throw InputError("exec needs a command: 'exec:[timeout=SECONDS:]COMMAND'");
    options.command = rest;
    return options;
}

struct ExecEvaluator::Hello {
    Index points = 0, channels = 0, frames = 0;
    std::uint32_t version = 1;
};

ExecEvaluator::ExecEvaluator(ExecOptions options) : options_(std::move(options)) {
    Hello hello;
    auto child = start(hello);
    points_ = hello.points;
    channels_ = hello.channels;
    frames_ = hello.frames;
    version_ = hello.version;
    idle_.push_back(std::move(child));
}

ExecEvaluator::~ExecEvaluator() {
    // Close every socket first, so the children exit together instead of one after another.
    std::vector<std::unique_ptr<ChildProcess>> children;
    children.swap(idle_);
    children.clear();
}

std::unique_ptr<ChildProcess> ExecEvaluator::start(Hello& hello) const {
    auto child = std::make_unique<ChildProcess>(options_.command);
    {
        std::lock_guard lock(mutex_);
        ++started_;
    }
    const auto deadline = Clock::now() + options_.timeout;
    exec::Hello wire{};
    bool complete = false;
    try {
        complete = child->readAll(&wire, sizeof wire, deadline);
    } catch (const TimedOut&) {
        fail(*child, "sent no hello within " + seconds(options_.timeout));
    }
    if (!complete) fail(*child, child->reap(kExitGrace) + " before its hello");
    if (std::memcmp(wire.magic, kMagic, sizeof kMagic) != 0)
        fail(*child, "did not start with the hello 'PMSCEXEC' (is it an exec-protocol program?)");
    if (wire.version < 1 || wire.version > kProtocolVersion)
        fail(*child, "speaks protocol version " + std::to_string(wire.version) + ", pmsc speaks 1 to " +
                         std::to_string(kProtocolVersion));
    constexpr std::uint64_t kMaxPoints = std::uint64_t{1} << 40;
    if (wire.points == 0 || wire.points > kMaxPoints || wire.channels == 0 || wire.channels > 4096 ||
        wire.frames == 0 || wire.frames > kMaxPoints)
        fail(*child, "said it has " + std::to_string(wire.points) + " points, " +
                         std::to_string(wire.channels) + " channels and " + std::to_string(wire.frames) +
                         " frames (each must be at least 1)");
    hello.points = static_cast<Index>(wire.points);
    hello.channels = static_cast<Index>(wire.channels);
    hello.frames = static_cast<Index>(wire.frames);
    hello.version = wire.version;
    return child;
}

std::unique_ptr<ChildProcess> ExecEvaluator::acquire() const {
    {
        std::lock_guard lock(mutex_);
        if (!idle_.empty()) {
            auto child = std::move(idle_.back());
            idle_.pop_back();
            return child;
        }
    }
    Hello hello;
    auto child = start(hello);
    if (hello.points != points_ || hello.channels != channels_ || hello.frames != frames_)
        fail(*child, "started again with " + std::to_string(hello.points) + " points x " +
                         std::to_string(hello.channels) + " channels, " + std::to_string(hello.frames) +
                         " frames; the first had " + std::to_string(points_) + " x " +
                         std::to_string(channels_) + ", " + std::to_string(frames_));
    return child;
}

void ExecEvaluator::release(std::unique_ptr<ChildProcess> child) const {
    child->trimErrorLog(kErrorLogLimit);
    std::lock_guard lock(mutex_);
    idle_.push_back(std::move(child));
}

void ExecEvaluator::fail(ChildProcess& child, const std::string& what) const {
    std::string message = "exec '" + shortCommand(options_.command) + "': the child " + what;
    child.reap(kExitGrace);  // let a crashing child finish writing its last words
    const std::string said = child.lastErrorLine();
    if (!said.empty()) message += " (its stderr: " + said + ")";
    throw EvaluatorError(message);
}

void ExecEvaluator::request(Index frame, std::span<const Index> points, bool wholeFrame, double* out) const {
    if (frame < 0 || frame >= frames_)
        throw std::out_of_range("exec: frame " + std::to_string(frame) + " is not in [0, " +
                                std::to_string(frames_) + ")");
    // A whole frame, or a run of consecutive points (a fail-through chunk), goes as a range.
    bool consecutive = wholeFrame;
    if (!wholeFrame) {
        for (const Index p : points)
            if (p < 0 || p >= points_)
                throw std::out_of_range("exec: point " + std::to_string(p) + " is not in [0, " +
                                        std::to_string(points_) + ")");
        if (points.empty()) return;
        consecutive = true;
        for (std::size_t i = 1; i < points.size() && consecutive; ++i)
            consecutive = points[i] == points[i - 1] + 1;
    }
    const auto count = wholeFrame ? static_cast<std::size_t>(points_) : points.size();
    const Index first = wholeFrame ? 0 : points.front();
    Request req{};
    req.kind = consecutive ? kRequestRange : kRequestList;
    req.frame = frame;
    req.count = count;
    req.first = consecutive ? static_cast<std::uint64_t>(first) : 0;
    std::unique_ptr<ChildProcess> child = acquire();
    const std::size_t values = count * static_cast<std::size_t>(channels_);
    const std::string during = " during frame " + std::to_string(frame);
    const std::string reported =
        exchange(*child, req, consecutive ? std::span<const Index>{} : points, values, out, during);
    if (!reported.empty()) {
        release(std::move(child));
        throw EvaluatorError("exec '" + shortCommand(options_.command) + "': frame " + std::to_string(frame) +
                             ": " + reported);
    }
    for (std::size_t i = 0; i < values; ++i)
        if (!std::isfinite(out[i])) {
            const std::size_t at = i / static_cast<std::size_t>(channels_);
            const Index point = consecutive ? first + static_cast<Index>(at) : points[at];
            fail(*child, "answered a non-finite value (" + std::to_string(out[i]) + ") for point " +
                             std::to_string(point) + " channel " + std::to_string(i % channels_) + during);
        }
    release(std::move(child));
}

std::string ExecEvaluator::exchange(ChildProcess& child, const Request& req, std::span<const Index> list,
                                    std::size_t values, double* out, const std::string& during) const {
    const auto deadline = Clock::now() + options_.timeout;
    std::string reported;  // an error the child answered with; it serves on
    try {
        bool open = child.writeAll(&req, sizeof req, deadline);
        if (open && !list.empty()) {
            static_assert(sizeof(Index) == sizeof(std::uint64_t));
            open = child.writeAll(list.data(), list.size_bytes(), deadline);
        }
        Response resp{};
        if (!open || !child.readAll(&resp, sizeof resp, deadline))
            fail(child, child.reap(kExitGrace) + during);
        if (resp.status == kResponseError) {
            if (resp.length > kMaxErrorBytes)
                fail(child, "answered an error of " + std::to_string(resp.length) + " bytes" + during);
            reported.assign(resp.length, '\0');
            if (!child.readAll(reported.data(), reported.size(), deadline))
                fail(child, child.reap(kExitGrace) + during);
            if (const auto nl = reported.find('\n'); nl != std::string::npos) reported.resize(nl);
            if (reported.empty()) reported = "(an empty error message)";
            return reported;
        }
        if (resp.status != kResponseValues || resp.reserved != 0)
            fail(child, "answered garbage (status " + std::to_string(resp.status) + ")" + during);
        if (resp.length != values)
            fail(child, "answered " + std::to_string(resp.length) + " values for " +
                            std::to_string(req.count) + " points x " +
                            std::to_string(values / std::max<std::uint64_t>(req.count, 1)) + " channels" +
                            during);
        if (!child.readAll(out, values * sizeof(double), deadline))
            fail(child, "wrote too few bytes and " + child.reap(kExitGrace) + during);
    } catch (const TimedOut&) {
        fail(child, "did not answer within " + seconds(options_.timeout) + during);
    }
    return reported;
}

FrameSet ExecEvaluator::pointPositions() const {
    if (version_ < kPositionsVersion)
        throw InputError("exec '" + shortCommand(options_.command) + "': the child speaks protocol version " +
                         std::to_string(version_) + ", which has no positions request (version " +
                         std::to_string(kPositionsVersion) + " children say where their points are)");
    Request req{};
    req.kind = kRequestPositions;
    req.count = static_cast<std::uint64_t>(points_);
    FrameSet positions(1, points_, 3);
    std::unique_ptr<ChildProcess> child = acquire();
    const std::string reported =
        exchange(*child, req, {}, positions.values.size(), positions.values.data(), " asked for positions");
    release(std::move(child));
    if (!reported.empty())
        throw InputError("exec '" + shortCommand(options_.command) + "': no positions: " + reported);
    for (const double v : positions.values)
        if (!std::isfinite(v))
            throw EvaluatorError("exec '" + shortCommand(options_.command) +
                                 "': the child answered a non-finite position");
    return positions;
}

std::vector<std::shared_ptr<const FrameWriter>> ExecEvaluator::frameWriters() const {
    if (version_ < kPositionsVersion || (channels_ != 1 && channels_ != 3)) return {};
    // The positions and the voxel size, asked now: a child whose points have no places offers no
    // .vdb, and `pmsc run --format vdb` says so before any frame.
    auto positions = std::make_shared<FrameSet>();
    try {
        *positions = pointPositions();
    } catch (const InputError&) {
        return {};
    }
    const double cellSize = scene::PointCacheGrid::cellSizeFor(positions->values);
    auto write = [this, positions, cellSize](const std::string& path, Index frame, const double* values) {
        scene::PointCacheGrid::write(path, positions->values,
                                     std::span<const double>(values, size_t(points_ * channels_)), channels_,
                                     cellSize, frame);
    };
    auto points = [](const std::string& path) { return scene::PointCacheGrid::pointCount(path); };
    return {std::make_shared<scene::VdbFrameWriter>(static_cast<std::int64_t>(points_), write, points)};
}

void ExecEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    request(frame, points, false, out);
}

void ExecEvaluator::evaluateAll(Index frame, double* out) const { request(frame, {}, true, out); }

std::size_t ExecEvaluator::idleChildren() const {
    std::lock_guard lock(mutex_);
    return idle_.size();
}

std::size_t ExecEvaluator::childrenStarted() const {
    std::lock_guard lock(mutex_);
    return started_;
}

}  // namespace pmsc::evaluators::exec
