// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "evaluators/exec/ExecProtocol.h"

#include "evaluators/exec/ChildProcess.h"
#include "pmsc/PointPositions.h"

#include <unistd.h>
#include <algorithm>
#include <cerrno>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <exception>
#include <limits>
#include <mutex>
#include <numeric>
#include <span>
#include <string>
#include <thread>
#include <vector>

namespace pmsc::evaluators::exec {

namespace {

/// @return false on end of file before the first byte; throws on a short or failed read.
bool readExactly(int fd, void* bytes, std::size_t size) {
    auto* p = static_cast<char*>(bytes);
    std::size_t got = 0;
    while (got < size) {
        const ssize_t n = ::read(fd, p + got, size - got);
        if (n > 0) {
            got += static_cast<std::size_t>(n);
        } else if (n == 0) {
            if (got == 0) return false;
            throw std::runtime_error("a request ended after " + std::to_string(got) + " of " +
                                     std::to_string(size) + " bytes");
        } else if (errno != EINTR) {
            throw std::runtime_error(std::string("read: ") + std::strerror(errno));
        }
    }
    return true;
}

void writeExactly(int fd, const void* bytes, std::size_t size) {
    if (!writeFully(fd, bytes, size)) throw std::runtime_error(std::string("write: ") + std::strerror(errno));
}

/// The points a request names: a range (first, count), or a list of indices. A range is never
/// spelled out as indices beyond the block being computed: a whole frame of 160,000 points would
/// otherwise cost 1.3 MB of indices on every request.
struct Asked {
    Index first = 0;
    std::size_t count = 0;
    std::vector<Index> list;  ///< a list request's indices; empty for a range
    bool isRange = true;

    /// The indices of points [at, at + n), written to `scratch` for a range.
    std::span<const Index> block(std::size_t at, std::size_t n, std::vector<Index>& scratch) const {
        if (!isRange) return std::span<const Index>(list).subspan(at, n);
        scratch.resize(n);
        std::iota(scratch.begin(), scratch.end(), first + static_cast<Index>(at));
        return scratch;
    }
};

/// The points a request names, checked against N (an unknown kind or a bad index is malformed:
/// the stream cannot be trusted past it).
Asked requestPoints(int in, const Request& request, Index pointCount) {
    const auto n = static_cast<std::uint64_t>(pointCount);
    if (request.count > n)
        throw std::runtime_error("a request asks for " + std::to_string(request.count) + " points of " +
                                 std::to_string(n));
    Asked asked;
    asked.count = request.count;
    if (request.kind == kRequestRange) {
        if (request.first > n - request.count)
            throw std::runtime_error("a range request goes past the last point");
        asked.first = static_cast<Index>(request.first);
        return asked;
    }
    if (request.kind != kRequestList)
        throw std::runtime_error("unknown request kind " + std::to_string(request.kind));
    asked.isRange = false;
    std::vector<std::uint64_t> wire(request.count);
    if (request.count > 0 && !readExactly(in, wire.data(), wire.size() * sizeof(std::uint64_t)))
        throw std::runtime_error("a list request ended before its indices");
    asked.list.resize(request.count);
    for (std::uint64_t i = 0; i < request.count; ++i) {
        if (wire[i] >= n)
            throw std::runtime_error("point index " + std::to_string(wire[i]) + " is not below " +
                                     std::to_string(n));
        asked.list[i] = static_cast<Index>(wire[i]);
    }
    return asked;
}

/// Points per block of a streamed answer: 16,384 x 3 doubles is 384 KiB, well inside the socket's
/// buffer, and small enough that the last block's copy is a sliver of the answer's time.
constexpr std::size_t kBlockPoints = 16384;

void sendError(int out, std::string error) {
    if (error.size() > kMaxErrorBytes) error.resize(kMaxErrorBytes);
    const Response response{kResponseError, 0, error.size()};
    writeExactly(out, &response, sizeof response);
    writeExactly(out, error.data(), error.size());
}

/// Writes blocks of answers on a thread of its own, so a block's copy into the socket overlaps the
/// calculation of the next one. At most two blocks wait; their buffers are reused.
class BlockWriter {
public:
    explicit BlockWriter(int fd) : fd_(fd), thread_([this] { run(); }) {}
    ~BlockWriter() {
        {
            std::lock_guard lock(mutex_);
            stop_ = true;
        }
        changed_.notify_all();
        thread_.join();
    }
    BlockWriter(const BlockWriter&) = delete;
    BlockWriter& operator=(const BlockWriter&) = delete;

    /// An empty buffer to fill (a used one when there is one).
    std::vector<double> buffer() {
        std::lock_guard lock(mutex_);
        if (spare_.empty()) return {};
        std::vector<double> b = std::move(spare_.back());
        spare_.pop_back();
        return b;
    }
    /// Queues a block. @throws std::runtime_error when a write failed.
    void submit(std::vector<double> block) {
        std::unique_lock lock(mutex_);
        changed_.wait(lock, [&] { return queue_.size() < 2 || !error_.empty(); });
        if (!error_.empty()) throw std::runtime_error(error_);
        queue_.push_back(std::move(block));
        changed_.notify_all();
    }
    /// Waits until every queued block is written. @throws std::runtime_error when a write failed.
    void drain() {
        std::unique_lock lock(mutex_);
        changed_.wait(lock, [&] { return (queue_.empty() && !writing_) || !error_.empty(); });
        if (!error_.empty()) throw std::runtime_error(error_);
    }

private:
    void run() {
        std::unique_lock lock(mutex_);
        for (;;) {
            changed_.wait(lock, [&] { return !queue_.empty() || stop_; });
            if (queue_.empty()) return;
            std::vector<double> block = std::move(queue_.front());
            queue_.pop_front();
            writing_ = true;
            lock.unlock();
            const bool ok = writeFully(fd_, block.data(), block.size() * sizeof(double));
            const int code = errno;
            lock.lock();
            writing_ = false;
            if (!ok && error_.empty()) error_ = std::string("write: ") + std::strerror(code);
            spare_.push_back(std::move(block));
            changed_.notify_all();
        }
    }

    int fd_;
    std::mutex mutex_;
    std::condition_variable changed_;
    std::deque<std::vector<double>> queue_;
    std::vector<std::vector<double>> spare_;
    std::string error_;
    bool writing_ = false, stop_ = false;
    std::thread thread_;  // last: starts after the members it uses
};

/// Answers one request. Decision: the values stream out block by block as they are computed, so
/// pmsc copies block k while block k+1 is computed and the answer costs little more than its
/// calculation; a whole-frame evaluator (its full pose shares work between points) answers in one
/// evaluateAll. An error in the first block is an error response; one after the header has gone
/// cannot be sent, so serve ends (pmsc then reports a short answer with this program's last words).
void answer(const PointEvaluator& evaluator, const Request& request, const Asked& points, int out,
            BlockWriter& writer) {
    const auto channels = static_cast<std::size_t>(evaluator.channelCount());
    const auto frame = static_cast<Index>(request.frame);
    const bool all = points.isRange && points.first == 0 &&
                     points.count == static_cast<std::size_t>(evaluator.pointCount());
    const std::size_t block = all && evaluator.failThroughShape().wholeFrame
                                  ? std::max<std::size_t>(points.count, 1)
                                  : kBlockPoints;
    const Response response{kResponseValues, 0, points.count * channels};
    std::vector<Index> indices;  // a range's block, spelled out
    for (std::size_t at = 0; at < points.count || at == 0; at += block) {
        const std::size_t count = std::min(block, points.count - at);
        std::vector<double> values = writer.buffer();
        values.resize(count * channels);
        try {
            if (count == points.count && all)
                evaluator.evaluateAll(frame, values.data());
            else
                evaluator.evaluate(frame, points.block(at, count, indices), values.data());
        } catch (const std::exception& e) {
            if (at > 0)
                throw std::runtime_error(std::string("frame ") + std::to_string(frame) + ": " + e.what());
            sendError(out, e.what());
            return;
        }
        if (at == 0) writeExactly(out, &response, sizeof response);
        writer.submit(std::move(values));
        if (points.count == 0) break;
    }
    writer.drain();
}

/// Answers a positions request: the evaluator's PointPositionsProvider, or an error response.
void answerPositions(const PointEvaluator& evaluator, const Request& request, int out) {
    if (request.count != static_cast<std::uint64_t>(evaluator.pointCount()) || request.first != 0)
        throw std::runtime_error("a positions request must ask for all " +
                                 std::to_string(evaluator.pointCount()) + " points from 0");
    const auto* placed = dynamic_cast<const PointPositionsProvider*>(&evaluator);
    if (placed == nullptr) {
        sendError(out, "evaluator '" + evaluator.name() + "' has no point positions of its own");
        return;
    }
    FrameSet positions;
    try {
        positions = placed->pointPositions();
    } catch (const std::exception& e) {
        sendError(out, e.what());
        return;
    }
    if (positions.values.size() != static_cast<std::size_t>(evaluator.pointCount()) * 3) {
        sendError(out, "evaluator '" + evaluator.name() + "' gave " +
                           std::to_string(positions.values.size()) + " position values for " +
                           std::to_string(evaluator.pointCount()) + " points");
        return;
    }
    const Response response{kResponseValues, 0, positions.values.size()};
    writeExactly(out, &response, sizeof response);
    writeExactly(out, positions.values.data(), positions.values.size() * sizeof(double));
}

}  // namespace

int serve(const PointEvaluator& evaluator, int in, int out) {
    try {
        Hello hello{};
        std::memcpy(hello.magic, kMagic, sizeof kMagic);
        hello.version = kProtocolVersion;
        hello.channels = static_cast<std::uint32_t>(evaluator.channelCount());
        hello.points = static_cast<std::uint64_t>(evaluator.pointCount());
        hello.frames = static_cast<std::uint64_t>(evaluator.frameCount());
        writeExactly(out, &hello, sizeof hello);

        BlockWriter writer(out);
        for (Request request{}; readExactly(in, &request, sizeof request);) {
            if (request.kind == kRequestPositions)
                answerPositions(evaluator, request, out);
            else
                answer(evaluator, request, requestPoints(in, request, evaluator.pointCount()), out, writer);
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pmsc serve: %s\n", e.what());
        return 1;
    }
}

}  // namespace pmsc::evaluators::exec
