#include "pmsc/SpatialGrid.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>

namespace pmsc {

std::vector<Index> sparseGridPoints(const Eigen::Ref<const Eigen::MatrixXd>& positions, Index cellsPerAxis) {
    if (cellsPerAxis < 1) {
        throw std::invalid_argument("spatial grid: cells per axis must be >= 1, got " +
                                    std::to_string(cellsPerAxis));
    }
    if (positions.cols() != 3) {
        throw std::invalid_argument("spatial grid: positions need 3 columns, got " +
                                    std::to_string(positions.cols()));
    }
    const Index n = positions.rows();
    if (n == 0) return {};
    for (Index i = 0; i < n; ++i) {
        if (!positions.row(i).allFinite()) {
            throw std::invalid_argument("spatial grid: position of point " + std::to_string(i) +
                                        " is not finite");
        }
    }
    const Eigen::RowVector3d lo = positions.colwise().minCoeff();
    const Eigen::RowVector3d hi = positions.colwise().maxCoeff();
    const double side = (hi - lo).maxCoeff();
    // All points at one place: a single cell holds them all.
    const double cell = side > 0 ? side / static_cast<double>(cellsPerAxis) : 1.0;
    struct Best {
        Index point;
        double distance2;
    };
    std::map<Index, Best> cells;  // ordered by cell id: the deterministic output order
    for (Index i = 0; i < n; ++i) {
        Index id = 0;
        Index stride = 1;
        Eigen::Vector3d centre;
        for (int a = 0; a < 3; ++a) {
            Index k = static_cast<Index>(std::floor((positions(i, a) - lo[a]) / cell));
            k = std::clamp<Index>(k, 0, cellsPerAxis - 1);  // the max face belongs to the last cell
            centre[a] = lo[a] + (static_cast<double>(k) + 0.5) * cell;
            id += k * stride;
            stride *= cellsPerAxis;
        }
        const double d2 = (positions.row(i).transpose() - centre).squaredNorm();
        auto [it, inserted] = cells.try_emplace(id, Best{i, d2});
        if (!inserted && d2 < it->second.distance2) it->second = Best{i, d2};
    }
    std::vector<Index> out;
    out.reserve(cells.size());
    for (const auto& [id, best] : cells) out.push_back(best.point);
    return out;
}

std::vector<Index> sparseGridPointsByCount(const Eigen::Ref<const Eigen::MatrixXd>& positions, Index count) {
    if (count < 1)
        throw std::invalid_argument("spatial grid: point count must be >= 1, got " + std::to_string(count));
    // cellsPerAxis = 1 gives one point; the occupied count is at most min(N, cells^3).
    std::vector<Index> best = sparseGridPoints(positions, 1);
    Index lo = 1;
    Index hi = 2;
    // Grow until the grid has too many points (or cannot grow further: every point its own cell).
    while (true) {
        std::vector<Index> g = sparseGridPoints(positions, hi);
        if (static_cast<Index>(g.size()) > count) break;
        best = std::move(g);
        lo = hi;
        if (static_cast<Index>(best.size()) >= std::min<Index>(count, positions.rows()) ||
            hi > (Index{1} << 20))
            return best;
        hi *= 2;
    }
    while (hi - lo > 1) {
        const Index mid = (lo + hi) / 2;
        std::vector<Index> g = sparseGridPoints(positions, mid);
        if (static_cast<Index>(g.size()) <= count) {
            if (g.size() > best.size()) best = std::move(g);
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return best;
}

}  // namespace pmsc
