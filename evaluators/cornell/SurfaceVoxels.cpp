#include "evaluators/cornell/SurfaceVoxels.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace pmsc::cornell {

namespace {

// Voxel coordinates packed in 57 bits (19 bits each, offset so negatives sort correctly), leaving
// 5 bits below for the quad index of a (voxel, surface) pair.
constexpr std::int64_t kBias = 1 << 18;
std::uint64_t packKey(std::int64_t i, std::int64_t j, std::int64_t k) {
    return (static_cast<std::uint64_t>(i + kBias) << 38) | (static_cast<std::uint64_t>(j + kBias) << 19) |
           static_cast<std::uint64_t>(k + kBias);
}
std::array<std::int32_t, 3> unpackKey(std::uint64_t key) {
    const std::uint64_t mask = (1u << 19) - 1;
    return {static_cast<std::int32_t>(static_cast<std::int64_t>(key >> 38) - kBias),
            static_cast<std::int32_t>(static_cast<std::int64_t>((key >> 19) & mask) - kBias),
            static_cast<std::int32_t>(static_cast<std::int64_t>(key & mask) - kBias)};
}

bool isFloor(const Quad& q) { return q.normal.y > 0.99 && q.corners[0].y < 1e-9; }

// (key << 5 | quad): every (voxel, surface) pair a sample touched, for quads < 32.
std::vector<std::uint64_t> samplePairs(const CornellScene& scene, double h) {
    std::vector<std::uint64_t> pairs;
    const auto& quads = scene.quads();
    if (quads.size() > 32) throw std::logic_error("SurfaceVoxels: more than 32 quads");
    const double step = h / 3.0;
    for (size_t qi = 0; qi < quads.size(); ++qi) {
        const Quad& q = quads[qi];
        const auto& c = q.corners;
        const double lu = std::max(length(c[1] - c[0]), length(c[2] - c[3]));
        const double lv = std::max(length(c[3] - c[0]), length(c[2] - c[1]));
        const int nu = static_cast<int>(std::ceil(lu / step)) + 1;
        const int nv = static_cast<int>(std::ceil(lv / step)) + 1;
        const bool floor = isFloor(q);
        for (int a = 0; a < nv; ++a) {
            const double v = static_cast<double>(a) / (nv - 1);
            const Vec3 p0 = c[0] + (c[3] - c[0]) * v, p1 = c[1] + (c[2] - c[1]) * v;
            for (int b = 0; b < nu; ++b) {
                const Vec3 p = p0 + (p1 - p0) * (static_cast<double>(b) / (nu - 1));
                if (floor && scene.insideBlock(p)) continue;
                const std::uint64_t key = packKey(static_cast<std::int64_t>(std::floor(p.x / h + 0.5)),
                                                  static_cast<std::int64_t>(std::floor(p.y / h + 0.5)),
                                                  static_cast<std::int64_t>(std::floor(p.z / h + 0.5)));
                pairs.push_back((key << 5) | qi);
            }
        }
    }
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    return pairs;
}

std::size_t countVoxels(const std::vector<std::uint64_t>& pairs) {
    std::size_t n = 0;
    for (size_t i = 0; i < pairs.size(); ++i)
        if (i == 0 || (pairs[i] >> 5) != (pairs[i - 1] >> 5)) ++n;
    return n;
}

void checkVoxelSize(double h) {
    if (!(h > 0.05 && h < 1000))
        throw std::invalid_argument("SurfaceVoxels: voxel size " + std::to_string(h) + " mm out of range");
}

/// The voxels of samplePairs(scene, h).
SurfaceVoxels fromPairs(const CornellScene& scene, double h, const std::vector<std::uint64_t>& pairs) {
    SurfaceVoxels out;
    out.voxelSizeMm = h;
    const auto& quads = scene.quads();
    for (size_t i = 0; i < pairs.size();) {
        const std::uint64_t key = pairs[i] >> 5;
        const auto ijk = unpackKey(key);
        const Vec3 centre{ijk[0] * h, ijk[1] * h, ijk[2] * h};
        // The gather point: the closest point to the voxel centre among the surfaces that
        // pass through the voxel, never on the floor inside a block.
        double best = std::numeric_limits<double>::infinity();
        Vec3 bestP{};
        int bestQ = -1;
        for (; i < pairs.size() && (pairs[i] >> 5) == key; ++i) {
            const int qi = static_cast<int>(pairs[i] & 31);
            const Vec3 p = quads[qi].closestPoint(centre);
            if (isFloor(quads[qi]) && scene.insideBlock(p)) continue;
            const double d = dot(p - centre, p - centre);
            if (d < best) {
                best = d;
                bestP = p;
                bestQ = qi;
            }
        }
        if (bestQ < 0) continue;  // only the floor inside a block reached this voxel
        out.ijk.push_back(ijk);
        out.position.push_back(bestP);
        out.normal.push_back(quads[bestQ].normal);
        out.quad.push_back(bestQ);
    }
    return out;
}

}  // namespace

SurfaceVoxels SurfaceVoxels::voxelize(const CornellScene& scene, double h) {
    checkVoxelSize(h);
    return fromPairs(scene, h, samplePairs(scene, h));
}

SurfaceVoxels SurfaceVoxels::voxelizeToCount(const CornellScene& scene, std::size_t targetCount) {
    if (targetCount < 8)
        throw std::invalid_argument("SurfaceVoxels: need at least 8 points, got " +
                                    std::to_string(targetCount));
    double h = std::sqrt(scene.totalArea() / static_cast<double>(targetCount));
    for (int round = 0; round < 6; ++round) {
        std::vector<std::uint64_t> pairs = samplePairs(scene, h);
        const double ratio = static_cast<double>(countVoxels(pairs)) / static_cast<double>(targetCount);
        if (std::abs(ratio - 1.0) < 0.01) {  // close enough: voxelize the pairs just sampled
            checkVoxelSize(h);
            return fromPairs(scene, h, pairs);
        }
        h *= std::sqrt(ratio);
    }
    return voxelize(scene, h);
}

}  // namespace pmsc::cornell
