#include "pmsc/MeanShape.h"

#include <algorithm>
#include <cmath>

namespace pmsc {

double rmsMotion(const Model& model) {
    const double cells = static_cast<double>(std::max<Index>(1, model.points * model.trainFrames));
    return std::sqrt(model.totalEnergy / cells);
}

Eigen::MatrixXd meanShape(const Model& model, double rmsMotion) {
    if (model.channels != 3 || model.sharedChannels) return {};
    const Eigen::MatrixXd mean = Eigen::Map<const Eigen::MatrixXd>(model.mean.data(), 3, model.points);
    const double diagonal = (mean.rowwise().maxCoeff() - mean.rowwise().minCoeff()).norm();
    if (!(rmsMotion <= kMostMotion * diagonal)) return {};
    return mean.transpose();
}

}  // namespace pmsc
