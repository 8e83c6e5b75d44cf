#include "pmsc/MeanShape.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace pmsc {

double rmsMotion(const Model& model) {
    const double cells = static_cast<double>(std::max<Index>(1, model.points * model.trainFrames));
    return std::sqrt(model.totalEnergy / cells);
}

double motionShare(const Model& model, double rmsMotion) {
    const Eigen::Map<const Eigen::MatrixXd> mean(model.mean.data(), 3, model.points);
    const double diagonal = (mean.rowwise().maxCoeff() - mean.rowwise().minCoeff()).norm();
    if (diagonal > 0) return rmsMotion / diagonal;
    return rmsMotion > 0 ? std::numeric_limits<double>::infinity() : 0.0;
}

Eigen::MatrixXd meanShape(const Model& model, double rmsMotion) {
    if (model.channels != 3 || model.sharedChannels) return {};
    if (!(motionShare(model, rmsMotion) <= kMostMotion)) return {};
    return Eigen::Map<const Eigen::MatrixXd>(model.mean.data(), 3, model.points).transpose();
}

}  // namespace pmsc
