// pmsc_scaleout_compare A.pmsc B.pmsc: prints how two models of the same training set compare
// (M, keys, largest principal angle between the bases, training residuals) and exits 0 when they
// agree (same M and keys, basis angle < 1e-9, residuals within 1e-9 relative),
// 1 otherwise. Used by the Slurm + MPI test and by hand.
#include "pmsc/ModelIO.h"

#include <Eigen/SVD>

#include <cmath>
#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: %s A.pmsc B.pmsc\n", argv[0]);
        return 2;
    }
    try {
        const pmsc::Model a = pmsc::readModel(argv[1]);
        const pmsc::Model b = pmsc::readModel(argv[2]);
        double angle = 1;
        if (a.basisSize() == b.basisSize() && a.basis.rows() == b.basis.rows()) {
            const Eigen::MatrixXd r = b.basis - a.basis * (a.basis.transpose() * b.basis);
            angle = Eigen::JacobiSVD<Eigen::MatrixXd>(r).singularValues()(0);
        }
        const bool sameKeys = a.keyPoints == b.keyPoints;
        const double residualDiff = std::abs(a.trainMaxPointResidual - b.trainMaxPointResidual);
        std::printf(
            "M %lld vs %lld, K %lld vs %lld, keys %s, basis angle (sin) %.3g, residual %.9g vs %.9g\n",
            static_cast<long long>(a.basisSize()), static_cast<long long>(b.basisSize()),
            static_cast<long long>(a.keyCount()), static_cast<long long>(b.keyCount()),
            sameKeys ? "identical" : "DIFFER", angle, a.trainMaxPointResidual, b.trainMaxPointResidual);
        const bool same = a.basisSize() == b.basisSize() && sameKeys && angle < 1e-9 &&
                          residualDiff <= 1e-9 * a.trainMaxPointResidual;
        return same ? 0 : 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pmsc_scaleout_compare: %s\n", e.what());
        return 2;
    }
}
