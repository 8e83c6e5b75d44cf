#include "pmsc/KeyNeighbours.h"

#include "pmsc/ByteIO.h"
#include "pmsc/Model.h"
#include "pmsc/ModelSections.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

namespace pmsc {

void KeyNeighbours::validate(const Model& model) const {
    if (perKey < 1 || perKey > model.points - model.keyCount())
        throw std::invalid_argument("key neighbours: " + std::to_string(perKey) +
                                    " per key is outside [1, N - K]");
    if (static_cast<Index>(points.size()) != model.keyCount() * perKey)
        throw std::invalid_argument("key neighbours: " + std::to_string(points.size()) +
                                    " points, expected K * " + std::to_string(perKey));
    for (const Index p : points) {
        if (p < 0 || p >= model.points)
            throw std::invalid_argument("key neighbours: point " + std::to_string(p) + " is outside [0, N)");
    }
}

KeyNeighbours nearestToKeys(const Eigen::Ref<const Eigen::MatrixXd>& positions, std::span<const Index> keys,
                            Index perKey, bool fromMean) {
    const Index n = positions.rows();
    if (positions.cols() != 3) throw std::invalid_argument("nearestToKeys: positions must be N x 3");
    if (perKey < 1 || perKey > n - static_cast<Index>(keys.size()))
        throw std::invalid_argument("nearestToKeys: " + std::to_string(perKey) +
                                    " per key is outside [1, N - K]");
    std::vector<char> isKey(static_cast<size_t>(n), 0);
    for (const Index k : keys) {
        if (k < 0 || k >= n)
            throw std::invalid_argument("nearestToKeys: key point " + std::to_string(k) + " out of range");
        isKey[size_t(k)] = 1;
    }
    KeyNeighbours out;
    out.perKey = perKey;
    out.fromMean = fromMean;
    out.points.reserve(keys.size() * size_t(perKey));
    std::vector<std::pair<double, Index>> distance;
    distance.reserve(static_cast<size_t>(n));
    for (const Index k : keys) {
        distance.clear();
        for (Index p = 0; p < n; ++p) {
            if (!isKey[size_t(p)])
                distance.emplace_back((positions.row(p) - positions.row(k)).squaredNorm(), p);
        }
        // Pairs compare by distance, then index: the same neighbours on every machine.
        std::partial_sort(distance.begin(), distance.begin() + perKey, distance.end());
        for (Index i = 0; i < perKey; ++i) out.points.push_back(distance[size_t(i)].second);
    }
    return out;
}

// --- the "KEYNEAR" section --------------------------------------------------------------------
//
//   u32 from mean (0 or 1), u64 per key P, u64[K*P] points (key-major, nearest first)

ModelSectionCodec keyNeighboursSectionCodec() {
    return {{'K', 'E', 'Y', 'N', 'E', 'A', 'R', '\0'},
            [](const Model& m) { return m.keyNeighbours.has_value(); },
            [](const Model& m, ByteWriter& out) {
                out.u32(m.keyNeighbours->fromMean ? 1 : 0);
                out.index(m.keyNeighbours->perKey);
                out.indices(m.keyNeighbours->points);
            },
            [](ByteReader& in, Model& m) {
                KeyNeighbours near;
                const std::uint32_t fromMean = in.u32("key neighbours' source");
                if (fromMean > 1)
                    in.fail("key neighbours' source " + std::to_string(fromMean) + " is not 0 or 1");
                near.fromMean = fromMean == 1;
                const auto n = static_cast<std::uint64_t>(m.points);
                const auto k = static_cast<std::uint64_t>(m.keyCount());
                const std::uint64_t perKey = in.u64("key neighbours per key");
                if (perKey == 0 || perKey + k > n)
                    in.fail("key neighbours per key " + std::to_string(perKey) + " outside [1, N - K]");
                near.perKey = static_cast<Index>(perKey);
                std::uint64_t count = 0;
                if (__builtin_mul_overflow(k, perKey, &count)) in.fail("key neighbours: too many points");
                in.require(count, 8, "key neighbour points");
                near.points = in.indices(count, n, "key neighbour point");
                m.keyNeighbours = std::move(near);
            }};
}

}  // namespace pmsc
