// Small but complete models for the model-file tests, and a model with sentinels for the engine's.
#pragma once

#include "pmsc/Model.h"
#include "pmsc/Sentinels.h"

#include <Eigen/QR>

#include <algorithm>
#include <cmath>

namespace pmsc::test {

/// A small but complete model: N=7 points, C=3, M=3, K=3 keys, made the way
/// training makes one (orthonormal basis, projector = pinv of the key rows).
inline pmsc::Model smallModel() {
    pmsc::Model m;
    m.points = 7;
    m.channels = 3;
    m.trainFrames = 11;
    Eigen::MatrixXd random(21, 3);
    for (Eigen::Index i = 0; i < random.size(); ++i) random.data()[i] = std::sin(0.7 * i + 0.3);
    m.basis = Eigen::HouseholderQR<Eigen::MatrixXd>(random).householderQ() * Eigen::MatrixXd::Identity(21, 3);
    m.mean = Eigen::VectorXd::LinSpaced(21, -1.0, 2.5);
    m.singularValues = Eigen::Vector3d(9.5, 3.25, 0.125);
    m.totalEnergy = m.singularValues.squaredNorm() + 0.5;
    m.keyPoints = {4, 0, 6};
    m.projector = pmsc::makeProjector(m.basis, m.channels, m.keyPoints);
    m.selector = pmsc::Selector::QDeim;
    m.epsMin = 0.01;
    m.epsMax = 0.015;
    m.tolerance = 0.05;
    m.trainMaxPointResidual = 0.002;
    return m;
}

/// smallModel()'s sizes with the channels sharing the basis: basis 7 x 3, projector 3 x 3.
inline pmsc::Model smallSharedChannelModel() {
    pmsc::Model m = smallModel();
    Eigen::MatrixXd random(7, 3);
    for (Eigen::Index i = 0; i < random.size(); ++i) random.data()[i] = std::sin(1.1 * i + 0.4);
    m.basis = Eigen::HouseholderQR<Eigen::MatrixXd>(random).householderQ() * Eigen::MatrixXd::Identity(7, 3);
    m.sharedChannels = true;
    m.projector = pmsc::makeProjector(m.basis, 1, m.keyPoints);
    return m;
}

/// smallModel() with two regions: points {0,1,2,3} and {4,5,6}, keys {4,0} and {4,6}
/// (key numbers {0,1} and {0,2}), local bases of 1 and 2 vectors, feather entries on 3 and 4.
inline pmsc::Model smallModelWithRegions() {
    pmsc::Model m = smallModel();
    pmsc::LocalRegions regions;
    regions.featherWidth = 0.25;
    regions.maxLocalFraction = 0.5;
    const auto region = [&](std::vector<pmsc::Index> points, std::vector<pmsc::Index> keys,
                            pmsc::Index basisSize) {
        pmsc::Region g;
        g.points = std::move(points);
        g.keys = std::move(keys);
        const auto rows = static_cast<Eigen::Index>(g.points.size()) * 3;
        Eigen::MatrixXd random(rows, basisSize);
        for (Eigen::Index i = 0; i < random.size(); ++i)
            random.data()[i] = std::cos(1.3 * i + 0.2 * basisSize);
        g.basis = Eigen::HouseholderQR<Eigen::MatrixXd>(random).householderQ() *
                  Eigen::MatrixXd::Identity(rows, basisSize);
        g.keyBasis = Eigen::MatrixXd(static_cast<Eigen::Index>(g.keys.size()) * 3, basisSize);
        for (Eigen::Index i = 0; i < g.keyBasis.size(); ++i) g.keyBasis.data()[i] = std::sin(0.9 * i + 0.1);
        Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(g.keyBasis);
        g.projector = cod.pseudoInverse();
        g.epsMin = 0.02 * basisSize;
        g.epsMax = 0.04 * basisSize;
        g.ratio = 1.5;
        return g;
    };
    regions.regions.push_back(region({0, 1, 2, 3}, {0, 1}, 1));
    regions.regions.push_back(region({4, 5, 6}, {0, 2}, 2));
    regions.featherStart = {0, 0, 0, 0, 1, 2, 2, 2};
    regions.featherRegion = {1, 0};
    regions.featherFactor = {0.5, 0.25};
    m.regions = std::move(regions);
    return m;
}

/// `m` with sentinels every 10th point (no key among them), its hits checked at `tolerance`:
/// 1e300 lets every check pass, 1e-12 refuses every hit PM does not reproduce to the last bits.
inline pmsc::Model withSentinels(pmsc::Model m, double tolerance) {
    m.tolerance = tolerance;
    pmsc::Sentinels s;
    s.source = pmsc::SentinelSource::PointOrder;
    for (pmsc::Index p = 5; p < m.points; p += 10)
        if (std::find(m.keyPoints.begin(), m.keyPoints.end(), p) == m.keyPoints.end()) s.points.push_back(p);
    s.coveringRadius = 10;
    m.sentinels = s;
    m.validate();
    return m;
}

}  // namespace pmsc::test
