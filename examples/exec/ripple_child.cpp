// A complete exec-protocol child in C++ that needs nothing of pmsc: a rippling sheet of G x G
// points (x, y, z), standing for a calculation built with another compiler or C++ ABI.
//
//   pmsc run --model M.pmsc --evaluator 'exec:pmsc_exec_ripple --grid 64' --frames 0-99 --out OUT
//
//   pmsc_exec_ripple [--grid G] [--frames F] [--work-us U]
//     --work-us U  also spins U microseconds per request, like a calculation with a fixed cost
//
// The protocol (docs/exec-protocol.md), all little-endian: a 32-byte hello; per request a 32-byte
// header (kind 1 = a list of u64 point indices follows, kind 2 = the range first..first+count-1),
// answered by a 16-byte header (status 0, count * C) and the float64 values, point-major.
#include <unistd.h>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

#pragma pack(push, 1)
struct Hello {
    char magic[8];
    std::uint32_t version, channels;
    std::uint64_t points, frames;
};
struct Request {
    std::uint32_t kind, reserved;
    std::int64_t frame;
    std::uint64_t count, first;
};
struct Response {
    std::uint32_t status, reserved;
    std::uint64_t length;
};
#pragma pack(pop)

bool readExactly(void* bytes, std::size_t size) {
    auto* p = static_cast<char*>(bytes);
    while (size > 0) {
        const ssize_t n = ::read(0, p, size);
        if (n <= 0) return false;  // end of input: pmsc is done
        p += n;
        size -= static_cast<std::size_t>(n);
    }
    return true;
}

void writeExactly(const void* bytes, std::size_t size) {
    const auto* p = static_cast<const char*>(bytes);
    while (size > 0) {
        const ssize_t n = ::write(1, p, size);
        if (n <= 0) std::exit(1);  // pmsc went away
        p += n;
        size -= static_cast<std::size_t>(n);
    }
}

/// The calculation: point p of frame f on a sheet rippling out from its centre.
void ripple(std::uint64_t grid, std::int64_t frame, std::uint64_t p, double* xyz) {
    const double u = static_cast<double>(p % grid) / static_cast<double>(grid - 1) - 0.5;
    const double v = static_cast<double>(p / grid) / static_cast<double>(grid - 1) - 0.5;
    const double t = static_cast<double>(frame) / 24.0;
    const double r = std::sqrt(u * u + v * v);
    xyz[0] = u;
    xyz[1] = v;
    xyz[2] = 0.05 * std::sin(20.0 * r - 4.0 * t) * std::exp(-2.0 * r) + 0.02 * std::sin(3.0 * u + t);
}

}  // namespace

int main(int argc, char** argv) {
    std::uint64_t grid = 64, frames = 240;
    long workMicroseconds = 0;
    for (int i = 1; i + 1 < argc; i += 2) {
        const std::string option = argv[i];
        const long value = std::strtol(argv[i + 1], nullptr, 10);
        if (option == "--grid" && value >= 2)
            grid = static_cast<std::uint64_t>(value);
        else if (option == "--frames" && value >= 1)
            frames = static_cast<std::uint64_t>(value);
        else if (option == "--work-us" && value >= 0)
            workMicroseconds = value;
        else {
            std::fprintf(stderr, "pmsc_exec_ripple: bad option %s %s\n", argv[i], argv[i + 1]);
            return 2;
        }
    }
    Hello hello{{'P', 'M', 'S', 'C', 'E', 'X', 'E', 'C'}, 1, 3, grid * grid, frames};
    writeExactly(&hello, sizeof hello);

    std::vector<std::uint64_t> points;
    std::vector<double> values;
    for (Request request{}; readExactly(&request, sizeof request);) {
        points.resize(request.count);
        if (request.kind == 1) {
            if (!readExactly(points.data(), points.size() * sizeof(std::uint64_t))) return 0;
        } else {
            for (std::uint64_t i = 0; i < request.count; ++i) points[i] = request.first + i;
        }
        const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(workMicroseconds);
        while (std::chrono::steady_clock::now() < until) {
        }
        bool inside = true;
        for (const std::uint64_t p : points) inside = inside && p < grid * grid;
        if (!inside || request.frame < 0 || static_cast<std::uint64_t>(request.frame) >= frames) {
            const std::string text = "pmsc_exec_ripple: a point or frame out of range";
            const Response error{1, 0, text.size()};
            writeExactly(&error, sizeof error);
            writeExactly(text.data(), text.size());
            continue;
        }
        values.resize(points.size() * 3);
        for (std::size_t i = 0; i < points.size(); ++i)
            ripple(grid, request.frame, points[i], &values[i * 3]);
        const Response response{0, 0, values.size()};
        writeExactly(&response, sizeof response);
        writeExactly(values.data(), values.size() * sizeof(double));
    }
    return 0;
}
