#include "pmsc/QDeim.h"

#include "pmsc/KeyPointSelector.h"

#include <Eigen/QR>

#include <stdexcept>
#include <string>

namespace pmsc {

QDeimSelection selectKeysQDeim(const Eigen::MatrixXd& basis, Index channels, Index maxKeys,
                               const std::vector<Index>& seeds, Index candidates) {
    const Index rows = basis.rows();
    const Index n = rows / channels;
    const Index m = basis.cols();
    if (maxKeys < 1 || maxKeys > n) {
        throw std::invalid_argument("key budget " + std::to_string(maxKeys) + " must be in [1, " +
                                    std::to_string(n) + "]");
    }
    KeySet keys(n, candidates);
    seedKeys(keys, seeds, {});
    if (keys.size() > maxKeys) {
        throw std::invalid_argument(std::to_string(keys.size()) + " seed points exceed the key budget " +
                                    std::to_string(maxKeys));
    }
    QDeimSelection result;
    bool firstPass = true;
    while (keys.size() < maxKeys) {
        // Candidate rows: all channels of the points not yet chosen.
        std::vector<Index> candidates;
        candidates.reserve(static_cast<size_t>(rows));
        for (Index p = 0; p < n; ++p)
            if (!keys.contains(p))
                for (Index c = 0; c < channels; ++c) candidates.push_back(p * channels + c);
        if (candidates.empty()) break;

        const auto cn = static_cast<Index>(candidates.size());
        Eigen::MatrixXd bt(m, cn);
        for (Index j = 0; j < cn; ++j) bt.col(j) = basis.row(candidates[static_cast<size_t>(j)]).transpose();

        Index freeRank = m;
        if (firstPass && !seeds.empty()) {
            // Forced pivots: deflate the seeds' span out of the candidates' columns.
            Eigen::MatrixXd seeded(m, static_cast<Index>(seeds.size()) * channels);
            for (size_t i = 0; i < seeds.size(); ++i)
                for (Index c = 0; c < channels; ++c)
                    seeded.col(static_cast<Index>(i) * channels + c) =
                        basis.row(seeds[i] * channels + c).transpose();
            Eigen::ColPivHouseholderQR<Eigen::MatrixXd> sqr(seeded);
            const Index r = sqr.rank();
            if (r > 0) {
                Eigen::MatrixXd span = Eigen::MatrixXd::Identity(m, r);
                span.applyOnTheLeft(sqr.householderQ());
                bt -= span * (span.transpose() * bt);
            }
            freeRank = m - r;
        }
        firstPass = false;
        if (freeRank <= 0) {
            // The seeds already determine every coordinate: later passes go on with plain Q-DEIM
            // on the remaining rows to fill the budget.
            continue;
        }

        Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(bt);
        const Index pivots = std::min(qr.rank(), freeRank);
        ++result.passes;
        const Index before = keys.size();
        for (Index i = 0; i < pivots && keys.size() < maxKeys; ++i) {
            const Index row = candidates[static_cast<size_t>(qr.colsPermutation().indices()[i])];
            keys.add(row / channels);
        }
        // A pass that adds nothing (remaining rows all numerically zero in the basis) would loop
        // forever; stop, the caller reports the shortfall.
        if (keys.size() == before) break;
    }
    result.keys = keys.keys();
    return result;
}

}  // namespace pmsc
