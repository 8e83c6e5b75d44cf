#include "viewer/HalfCache.h"

#include "pmsc/ModelIO.h"  // fnv1a64

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace pmsc::viewer {

std::uint16_t toHalf(double v) {
    const float f = std::isnan(v) ? float(v) : float(std::clamp(v, -65504.0, 65504.0));
    return Eigen::half_impl::raw_half_as_uint16(Eigen::half(f));
}

float fromHalf(std::uint16_t h) { return float(Eigen::half(Eigen::half_impl::raw_uint16_to_half(h))); }

std::span<const std::uint16_t> HalfCache::write(Index first, std::span<const double> values) {
    const size_t begin = size_t(first * channels_);
    if (begin + values.size() > values_.size())
        throw std::out_of_range("HalfCache::write: range past the end");
    std::transform(values.begin(), values.end(), values_.begin() + std::ptrdiff_t(begin), toHalf);
    return std::span<const std::uint16_t>(values_).subspan(begin, values.size());
}

std::string HalfCache::checksum() const {
    // The bytes of a uint16 array are its little-endian form on the machines pmsc builds for.
    const std::uint64_t h = fnv1a64(values_.data(), values_.size() * sizeof(std::uint16_t));
    char text[17];
    std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(h));
    return text;
}

}  // namespace pmsc::viewer
