#include "pmsc/Sentinels.h"

#include "pmsc/ByteIO.h"
#include "pmsc/MeanShape.h"
#include "pmsc/Model.h"
#include "pmsc/ModelSections.h"
#include "pmsc/RowBlocks.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>

namespace pmsc {

void Sentinels::validate(const Model& model) const {
    if (!std::isfinite(coveringRadius) || coveringRadius < 0)
        throw std::invalid_argument("sentinels: covering radius " + std::to_string(coveringRadius) +
                                    " is not finite and >= 0");
    if (static_cast<Index>(points.size()) > model.points)
        throw std::invalid_argument("sentinels: " + std::to_string(points.size()) + " points, more than N");
    for (const Index p : points) {
        if (p < 0 || p >= model.points)
            throw std::invalid_argument("sentinels: point " + std::to_string(p) + " is outside [0, N)");
    }
    const auto count = static_cast<Index>(points.size());
    if (perSentinel < 0 || perSentinel >= std::max<Index>(count, 1) ||
        neighbours.size() != size_t(count * perSentinel) || neighbourDistances.size() != neighbours.size())
        throw std::invalid_argument("sentinels: " + std::to_string(neighbours.size()) + " neighbours and " +
                                    std::to_string(neighbourDistances.size()) + " distances for " +
                                    std::to_string(count) + " sentinels of " + std::to_string(perSentinel) +
                                    " each");
    for (size_t i = 0; i < neighbours.size(); ++i) {
        const Index self = static_cast<Index>(i) / std::max<Index>(perSentinel, 1);
        if (neighbours[i] < 0 || neighbours[i] >= count || neighbours[i] == self)
            throw std::invalid_argument("sentinels: sentinel " + std::to_string(self) + "'s neighbour " +
                                        std::to_string(neighbours[i]) + " is not another sentinel");
        if (!(neighbourDistances[i] > 0) || !std::isfinite(neighbourDistances[i]))
            throw std::invalid_argument("sentinels: sentinel " + std::to_string(self) +
                                        "'s neighbour distance is not finite and > 0");
    }
}

Index sentinelCount(Index requested, Index points) {
    return std::max<Index>(0, std::min(requested, points / kSentinelSpacing));
}

Eigen::VectorXd basisMotion(const Model& model) {
    const Index n = model.points, rowsPerPoint = model.basisChannels();
    Eigen::VectorXd motion = Eigen::VectorXd::Zero(n);
    if (model.basisSize() == 0) return motion;
    // In slabs of points: the scaled basis of every point at once would be as large as the basis.
    Eigen::MatrixXd scaled;
    for (Index first = 0; first < n; first += kSlabPoints) {
        const Index count = std::min(kSlabPoints, n - first);
        scaled = model.basis.middleRows(first * rowsPerPoint, count * rowsPerPoint) *
                 model.singularValues.asDiagonal();
        for (Index p = 0; p < count; ++p)
            motion[first + p] = std::sqrt(scaled.middleRows(p * rowsPerPoint, rowsPerPoint).squaredNorm());
    }
    return motion;
}

namespace {

/// The points that are not keys and move at least kMovingShare of the most (ascending).
std::vector<Index> movingPool(const Eigen::Ref<const Eigen::VectorXd>& motion, std::span<const Index> keys,
                              const char* caller) {
    const Index n = motion.size();
    std::vector<char> excluded(static_cast<size_t>(n), 0);
    for (const Index k : keys) {
        if (k < 0 || k >= n)
            throw std::invalid_argument(std::string(caller) + ": key point " + std::to_string(k) +
                                        " out of range");
        excluded[size_t(k)] = 1;
    }
    const double most = n > 0 ? motion.maxCoeff() : 0.0;
    std::vector<Index> pool;
    for (Index p = 0; p < n; ++p) {
        if (!excluded[size_t(p)] && motion[p] > 0 && motion[p] >= kMovingShare * most) pool.push_back(p);
    }
    return pool;
}

/// Fills s.neighbours and s.neighbourDistances: each sentinel's kSentinelNeighbours nearest others
/// (ties by position in s.points). Every pair once: S^2 / 2 distances, a few milliseconds at 1024.
void nearestSentinels(const Eigen::Ref<const Eigen::MatrixXd>& positions, Sentinels& s) {
    const auto count = static_cast<Index>(s.points.size());
    s.perSentinel = std::min<Index>(kSentinelNeighbours, count - 1);
    s.neighbours.clear();
    s.neighbourDistances.clear();
    if (s.perSentinel <= 0) {
        s.perSentinel = 0;
        return;
    }
    std::vector<std::pair<double, Index>> others(static_cast<size_t>(count - 1));
    for (Index i = 0; i < count; ++i) {
        const Eigen::RowVector3d at = positions.row(s.points[size_t(i)]);
        size_t o = 0;
        for (Index j = 0; j < count; ++j)
            if (j != i) others[o++] = {(positions.row(s.points[size_t(j)]) - at).norm(), j};
        std::partial_sort(others.begin(), others.begin() + s.perSentinel, others.end());
        for (Index k = 0; k < s.perSentinel; ++k) {
            s.neighbours.push_back(others[size_t(k)].second);
            s.neighbourDistances.push_back(others[size_t(k)].first);
        }
    }
}

/// The same for sentinels drawn in point order (ascending, one in each run): each one's
/// kSentinelNeighbours nearest runs, at the distance between the runs, |i - j| times the covering
/// radius (a run's length). Why the runs' distance and not the drawn points': the draw inside a run
/// guards against a periodic point order, it says nothing of where the points are; two sentinels
/// drawn a point apart at the border of their runs would make the slope check extrapolate their
/// difference over a whole run (15 times it, on a body of skinned tubes), where the runs, like
/// farthest-point samples, are a covering radius apart. On the motion-capture takes
/// (bench/mocap_suite.py) the distance in points refused a third of 01_01's hits, every one under T.
void nearestInPointOrder(Sentinels& s) {
    const auto count = static_cast<Index>(s.points.size());
    s.perSentinel = std::max<Index>(0, std::min<Index>(kSentinelNeighbours, count - 1));
    s.neighbours.clear();
    s.neighbourDistances.clear();
    if (s.perSentinel == 0) return;
    std::vector<std::pair<Index, Index>> near;  // (runs apart, run)
    for (Index i = 0; i < count; ++i) {
        near.clear();
        for (Index j = std::max<Index>(0, i - s.perSentinel); j <= std::min(count - 1, i + s.perSentinel);
             ++j)
            if (j != i) near.emplace_back(std::abs(j - i), j);
        std::partial_sort(near.begin(), near.begin() + s.perSentinel, near.end());
        for (Index k = 0; k < s.perSentinel; ++k) {
            s.neighbours.push_back(near[size_t(k)].second);
            s.neighbourDistances.push_back(static_cast<double>(near[size_t(k)].first) * s.coveringRadius);
        }
    }
}

}  // namespace

Sentinels farthestPointSentinels(const Eigen::Ref<const Eigen::MatrixXd>& positions,
                                 const Eigen::Ref<const Eigen::VectorXd>& motion, std::span<const Index> keys,
                                 Index count, SentinelSource source) {
    const Index n = positions.rows();
    if (positions.cols() != 3) throw std::invalid_argument("farthestPointSentinels: positions must be N x 3");
    if (motion.size() != n)
        throw std::invalid_argument("farthestPointSentinels: " + std::to_string(motion.size()) +
                                    " motions for " + std::to_string(n) + " points");
    const std::vector<Index> pool = movingPool(motion, keys, "farthestPointSentinels");
    Sentinels out;
    out.source = source;
    if (pool.empty() || count <= 0) return out;
    // Start from the pool's point that moves most (lowest index on ties): where error is likeliest.
    Index first = pool.front();
    for (const Index p : pool) {
        if (motion[p] > motion[first]) first = p;
    }
    std::vector<double> nearest(pool.size(), std::numeric_limits<double>::infinity());
    Index next = first;
    const Index want = std::min<Index>(count, static_cast<Index>(pool.size()));
    out.points.reserve(static_cast<size_t>(want));
    double farthest = 0;
    for (Index s = 0; s < want; ++s) {
        out.points.push_back(next);
        const Eigen::RowVector3d at = positions.row(next);
        farthest = -1;
        Index argFarthest = next;
        for (size_t i = 0; i < pool.size(); ++i) {
            const double d = (positions.row(pool[i]) - at).squaredNorm();
            if (d < nearest[i]) nearest[i] = d;
            if (nearest[i] > farthest) {  // strict: the lowest index wins a tie
                farthest = nearest[i];
                argFarthest = pool[i];
            }
        }
        next = argFarthest;
    }
    out.coveringRadius = std::sqrt(std::max(0.0, farthest));
    nearestSentinels(positions, out);
    return out;
}

Sentinels pointOrderSentinels(const Eigen::Ref<const Eigen::VectorXd>& motion, std::span<const Index> keys,
                              Index count, std::uint64_t seed) {
    const std::vector<Index> pool = movingPool(motion, keys, "pointOrderSentinels");
    Sentinels out;
    out.source = SentinelSource::PointOrder;
    const auto moving = static_cast<Index>(pool.size());
    const Index want = std::min(count, moving);
    if (want <= 0) return out;
    std::mt19937_64 rng(seed);
    out.points.reserve(static_cast<size_t>(want));
    for (Index s = 0; s < want; ++s) {
        const Index begin = s * moving / want, end = (s + 1) * moving / want;  // end > begin: want <= moving
        // rng() % length: the engine's output is fixed by the standard, the distributions' are not.
        const auto length = static_cast<std::uint64_t>(end - begin);
        out.points.push_back(pool[size_t(begin + static_cast<Index>(rng() % length))]);
    }
    const Index longestRun = (moving + want - 1) / want;  // ceiling: the runs' lengths differ by one at most
    out.coveringRadius = static_cast<double>(longestRun);
    nearestInPointOrder(out);
    return out;
}

namespace {

/// For each sentinel of `s` that `gone` marks, the distance to the nearest kept one along the
/// neighbour lists (Bellman-Ford on the removed ones: there are few); infinity where none is
/// reached.
std::vector<double> distanceToKept(const Sentinels& s, const std::vector<char>& gone) {
    const size_t count = s.points.size(), k = size_t(s.perSentinel);
    std::vector<double> reach(count, std::numeric_limits<double>::infinity());
    for (size_t i = 0; i < count; ++i)
        if (!gone[i]) reach[i] = 0;
    for (bool changed = true; changed;) {
        changed = false;
        for (size_t i = 0; i < count; ++i) {
            if (!gone[i]) continue;
            for (size_t n = i * k; n < (i + 1) * k; ++n) {
                const double via = s.neighbourDistances[n] + reach[size_t(s.neighbours[n])];
                if (via < reach[i]) {
                    reach[i] = via;
                    changed = true;
                }
            }
        }
    }
    return reach;
}

}  // namespace

Sentinels withoutPoints(const Sentinels& s, std::span<const Index> removed) {
    const size_t count = s.points.size(), k = size_t(s.perSentinel);
    std::vector<char> gone(count, 0);
    for (size_t i = 0; i < count; ++i)
        gone[i] = std::find(removed.begin(), removed.end(), s.points[i]) != removed.end();
    if (std::find(gone.begin(), gone.end(), 1) == gone.end()) return s;
    std::vector<Index> renumbered(count, -1);
    Sentinels out;
    out.source = s.source;
    for (size_t i = 0; i < count; ++i) {
        if (gone[i]) continue;
        renumbered[i] = static_cast<Index>(out.points.size());
        out.points.push_back(s.points[i]);
    }
    const std::vector<double> reach = distanceToKept(s, gone);
    double grown = 0;
    for (size_t i = 0; i < count; ++i)
        if (gone[i]) grown = std::max(grown, reach[i]);
    // The shortest kept list: every list cut to it keeps the fixed count the model stores.
    Index shortest = s.perSentinel;
    for (size_t i = 0; i < count; ++i) {
        if (gone[i]) continue;
        Index kept = 0;
        for (size_t n = i * k; n < (i + 1) * k; ++n) kept += gone[size_t(s.neighbours[n])] ? 0 : 1;
        shortest = std::min(shortest, kept);
    }
    out.coveringRadius = s.coveringRadius + (std::isfinite(grown) ? grown : 0.0);
    if (!std::isfinite(grown) || out.points.size() < 2) return out;  // no slope check: perSentinel 0
    out.perSentinel = shortest;
    for (size_t i = 0; i < count; ++i) {
        if (gone[i]) continue;
        Index taken = 0;
        for (size_t n = i * k; n < (i + 1) * k && taken < shortest; ++n) {
            if (gone[size_t(s.neighbours[n])]) continue;
            out.neighbours.push_back(renumbered[size_t(s.neighbours[n])]);
            out.neighbourDistances.push_back(s.neighbourDistances[n]);
            ++taken;
        }
    }
    return out;
}

namespace {

/// Each of up to kShapeSamples points' (evenly spaced in point order) nearest other point in
/// `shape` (N x 3) at a distance > 0; points with none are left out.
std::vector<std::pair<Index, Index>> nearestPairs(const Eigen::MatrixXd& shape) {
    const Index n = shape.rows();
    const Index samples = std::min(n, kShapeSamples);
    std::vector<std::pair<Index, Index>> pairs;
    for (Index k = 0; k < samples; ++k) {
        const Index i = k * n / samples;
        const Eigen::RowVector3d at = shape.row(i);
        double best = std::numeric_limits<double>::infinity();
        Index nearest = -1;
        for (Index j = 0; j < n; ++j) {
            const double d = (shape.row(j) - at).squaredNorm();
            if (d > 0 && d < best) {
                best = d;
                nearest = j;
            }
        }
        if (nearest >= 0) pairs.emplace_back(i, nearest);
    }
    return pairs;
}

}  // namespace

Eigen::MatrixXd frameShape(const Eigen::Ref<const Eigen::VectorXd>& mean,
                           const Eigen::Ref<const Eigen::MatrixXd>& basis,
                           const Eigen::Ref<const Eigen::MatrixXd>& coefficients) {
    const Index n = mean.size() / 3, frames = coefficients.cols();
    if (mean.size() != 3 * n || basis.rows() != mean.size() || coefficients.rows() != basis.cols())
        throw std::invalid_argument("frameShape: " + std::to_string(mean.size()) +
                                    " mean values, a basis of " + std::to_string(basis.rows()) + " x " +
                                    std::to_string(basis.cols()) + ", " +
                                    std::to_string(coefficients.rows()) + " coefficients a frame");
    if (n < 2 || frames == 0) return {};
    Index nearestToMean = 0;  // the frame nearest the mean (Eigen takes the lowest index on ties)
    coefficients.colwise().squaredNorm().minCoeff(&nearestToMean);
    const Eigen::VectorXd frame = mean + basis * coefficients.col(nearestToMean);
    Eigen::MatrixXd shape = Eigen::Map<const Eigen::MatrixXd>(frame.data(), 3, n).transpose();
    const std::vector<std::pair<Index, Index>> pairs = nearestPairs(shape);
    if (pairs.empty()) return {};
    const Index used = std::min(frames, kShapeFrames);
    Eigen::MatrixXd c(coefficients.rows(), used);
    for (Index k = 0; k < used; ++k) c.col(k) = coefficients.col(k * frames / used);
    std::vector<double> spreads;
    for (const auto& [i, j] : pairs) {
        const Eigen::Matrix3Xd apart =
            ((basis.middleRows(3 * i, 3) - basis.middleRows(3 * j, 3)) * c).colwise() +
            (mean.segment<3>(3 * i) - mean.segment<3>(3 * j));
        const Eigen::ArrayXd d = apart.colwise().norm().transpose().array();
        const double average = d.mean();
        const double spread = std::sqrt((d - average).square().mean());
        spreads.push_back(average > 0 ? spread / average : std::numeric_limits<double>::infinity());
    }
    const auto middle = spreads.begin() + static_cast<std::ptrdiff_t>(spreads.size() / 2);
    std::nth_element(spreads.begin(), middle, spreads.end());
    return *middle <= kMostStretch ? shape : Eigen::MatrixXd();
}

Eigen::MatrixXd sentinelShape(const Model& model, SentinelSource& source,
                              const std::function<Eigen::MatrixXd()>& coefficients) {
    if (model.channels != 3 || model.sharedChannels) return {};
    source = SentinelSource::Mean;
    Eigen::MatrixXd shape = meanShape(model, rmsMotion(model));
    if (shape.size() > 0) return shape;
    // A shape whose mean is not one (limbs swept far): a frame, if the data deform as a surface does.
    source = SentinelSource::Frame;
    return frameShape(model.mean, model.basis, coefficients());
}

const char* toString(SentinelSource source) {
    switch (source) {
        case SentinelSource::Given:
            return "given";
        case SentinelSource::Mean:
            return "mean";
        case SentinelSource::PointOrder:
            return "point order";
        case SentinelSource::Frame:
            return "frame";
    }
    return "?";
}

const char* describe(SentinelSource source) {
    switch (source) {
        case SentinelSource::Given:
            return "positions given to train";
        case SentinelSource::Mean:
            return "training mean";
        case SentinelSource::PointOrder:
            return "point order: no positions";
        case SentinelSource::Frame:
            return "training frame nearest the mean";
    }
    return "?";
}

// --- the "SENTINEL" section --------------------------------------------------------------------
//
//   u32 source (SentinelSource: 0 given, 1 mean, 2 point order, 3 a training frame), f64 covering radius, u64
//   count S, u64[S] points

// --- the "SENTNBRS" section (after "SENTINEL") ---------------------------------------------------
//
//   u64 per sentinel k, then for each of the S sentinels k u64 neighbours (positions in the
//   sentinel list) and k f64 distances. Absent: no slope check (a model file written without
//   it).

ModelSectionCodec sentinelNeighboursSectionCodec() {
    return {{'S', 'E', 'N', 'T', 'N', 'B', 'R', 'S'},
            [](const Model& m) { return m.sentinels.has_value() && m.sentinels->perSentinel > 0; },
            [](const Model& m, ByteWriter& out) {
                const Sentinels& s = *m.sentinels;
                out.index(s.perSentinel);
                for (size_t i = 0; i < s.points.size(); ++i) {
                    const size_t at = i * size_t(s.perSentinel);
                    out.indices(std::span<const Index>(s.neighbours).subspan(at, size_t(s.perSentinel)));
                    for (Index k = 0; k < s.perSentinel; ++k) out.f64(s.neighbourDistances[at + size_t(k)]);
                }
            },
            [](ByteReader& in, Model& m) {
                if (!m.sentinels) in.fail("sentinel neighbours without sentinels");
                Sentinels& s = *m.sentinels;
                const auto count = static_cast<std::uint64_t>(s.points.size());
                const std::uint64_t k = in.u64("neighbours per sentinel");
                if (k == 0 || k >= std::max<std::uint64_t>(count, 1))
                    in.fail("neighbours per sentinel " + std::to_string(k) + " is not in [1, S)");
                in.require(count * k, 16, "sentinel neighbours");
                s.perSentinel = static_cast<Index>(k);
                for (std::uint64_t i = 0; i < count; ++i) {
                    const std::vector<Index> near = in.indices(k, count, "sentinel neighbour");
                    for (const Index j : near)
                        if (j == static_cast<Index>(i)) in.fail("a sentinel is its own neighbour");
                    s.neighbours.insert(s.neighbours.end(), near.begin(), near.end());
                    for (std::uint64_t j = 0; j < k; ++j) {
                        const double d = in.finite("sentinel neighbour distance");
                        if (!(d > 0)) in.fail("a sentinel neighbour distance is not > 0");
                        s.neighbourDistances.push_back(d);
                    }
                }
            }};
}

ModelSectionCodec sentinelsSectionCodec() {
    return {{'S', 'E', 'N', 'T', 'I', 'N', 'E', 'L'},
            [](const Model& m) { return m.sentinels.has_value(); },
            [](const Model& m, ByteWriter& out) {
                out.u32(static_cast<std::uint32_t>(m.sentinels->source));
                out.f64(m.sentinels->coveringRadius);
                out.index(static_cast<Index>(m.sentinels->points.size()));
                out.indices(m.sentinels->points);
            },
            [](ByteReader& in, Model& m) {
                Sentinels s;
                const std::uint32_t source = in.u32("sentinels' source");
                if (source > 3)
                    in.fail("sentinels' source " + std::to_string(source) + " is not 0, 1, 2 or 3");
                s.source = static_cast<SentinelSource>(source);
                s.coveringRadius = in.finite("sentinels' covering radius");
                if (s.coveringRadius < 0) in.fail("sentinels' covering radius is negative");
                const auto n = static_cast<std::uint64_t>(m.points);
                const std::uint64_t count = in.u64("sentinel count");
                if (count > n) in.fail("sentinel count " + std::to_string(count) + " is more than N");
                in.require(count, 8, "sentinel points");
                s.points = in.indices(count, n, "sentinel point");
                m.sentinels = std::move(s);
            }};
}

}  // namespace pmsc
