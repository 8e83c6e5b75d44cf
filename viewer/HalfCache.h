// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/PointEvaluator.h"  // Index

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace pmsc::viewer {

/// IEEE 754 half float of v (round to nearest even), clamped to +-65504 so a page never sees an
/// infinity; NaN stays NaN.
std::uint16_t toHalf(double v);
/// The value of a half float.
float fromHalf(std::uint16_t h);
/// toHalf of every value into out (values.size() halves), vectorized where the CPU has F16C.
void toHalves(std::span<const double> values, std::uint16_t* out);
/// The checksum the server and the page compare: FNV-1a 64 (offset 0xcbf29ce484222325, prime
/// 0x100000001b3) stepped once per 32-bit little-endian word of the halves, the last word
/// zero-padded when the count is odd.
std::uint64_t wordChecksum(std::span<const std::uint16_t> halfs);

/// What a viewer holds of a cache: N x C half floats, the form the page uploads. Updated range by
/// range as the server sends them, so the server and the page hold the same bytes and can compare
/// checksums.
class HalfCache {
public:
    HalfCache(Index points, Index channels) : channels_(channels), values_(size_t(points * channels), 0) {}

    /// Stores `values` (count x C doubles) at points [first, first + count); returns their halfs.
    std::span<const std::uint16_t> write(Index first, std::span<const double> values);
    /// wordChecksum of the whole array, as 16 lowercase hex digits.
    std::string checksum() const;
    std::span<const std::uint16_t> values() const { return values_; }
    Index points() const { return Index(values_.size()) / channels_; }

private:
    Index channels_;
    std::vector<std::uint16_t> values_;
};

}  // namespace pmsc::viewer
