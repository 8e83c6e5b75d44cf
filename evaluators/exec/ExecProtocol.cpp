// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "evaluators/exec/ExecProtocol.h"

#include "evaluators/exec/ChildProcess.h"

#include <unistd.h>
#include <cerrno>
#include <cstdio>
#include <exception>
#include <limits>
#include <string>
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

/// The points a request names, checked against N (an unknown kind or a bad index is malformed:
/// the stream cannot be trusted past it).
std::vector<Index> requestPoints(int in, const Request& request, Index pointCount) {
    const auto n = static_cast<std::uint64_t>(pointCount);
    if (request.count > n)
        throw std::runtime_error("a request asks for " + std::to_string(request.count) + " points of " +
                                 std::to_string(n));
    std::vector<Index> points(request.count);
    if (request.kind == kRequestRange) {
        if (request.first > n - request.count)
            throw std::runtime_error("a range request goes past the last point");
        for (std::uint64_t i = 0; i < request.count; ++i) points[i] = static_cast<Index>(request.first + i);
        return points;
    }
    if (request.kind != kRequestList)
        throw std::runtime_error("unknown request kind " + std::to_string(request.kind));
    std::vector<std::uint64_t> wire(request.count);
    if (request.count > 0 && !readExactly(in, wire.data(), wire.size() * sizeof(std::uint64_t)))
        throw std::runtime_error("a list request ended before its indices");
    for (std::uint64_t i = 0; i < request.count; ++i) {
        if (wire[i] >= n)
            throw std::runtime_error("point index " + std::to_string(wire[i]) + " is not below " +
                                     std::to_string(n));
        points[i] = static_cast<Index>(wire[i]);
    }
    return points;
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

        const Index channels = evaluator.channelCount();
        std::vector<double> values;
        for (Request request{}; readExactly(in, &request, sizeof request);) {
            const std::vector<Index> points = requestPoints(in, request, evaluator.pointCount());
            Response response{};
            std::string error;
            try {
                values.resize(points.size() * static_cast<std::size_t>(channels));
                if (request.kind == kRequestRange && request.first == 0 &&
                    points.size() == static_cast<std::size_t>(evaluator.pointCount()))
                    evaluator.evaluateAll(static_cast<Index>(request.frame), values.data());
                else
                    evaluator.evaluate(static_cast<Index>(request.frame), points, values.data());
            } catch (const std::exception& e) {
                error = e.what();
            }
            if (error.empty()) {
                response.status = kResponseValues;
                response.length = values.size();
                writeExactly(out, &response, sizeof response);
                writeExactly(out, values.data(), values.size() * sizeof(double));
            } else {
                if (error.size() > kMaxErrorBytes) error.resize(kMaxErrorBytes);
                response.status = kResponseError;
                response.length = error.size();
                writeExactly(out, &response, sizeof response);
                writeExactly(out, error.data(), error.size());
            }
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pmsc serve: %s\n", e.what());
        return 1;
    }
}

}  // namespace pmsc::evaluators::exec
