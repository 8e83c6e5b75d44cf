// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <cstdint>

namespace pmsc::testing {

// Deterministic synthetic values the engine's tests and benchmarks (bench/EngineBenchSupport.h)
// build their models and frames from: the same value for the same (stream, index) on any thread,
// chunking or machine.

/// splitmix64: a well-mixed 64-bit hash.
inline std::uint64_t mix(std::uint64_t x) {
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

/// Uniform in [-1, 1), value `b` of stream `a`.
inline double unit(std::uint64_t a, std::uint64_t b) {
    return double(mix(a * 0x100000001b3ull ^ mix(b)) >> 11) * (2.0 / 9007199254740992.0) - 1.0;
}

}  // namespace pmsc::testing
