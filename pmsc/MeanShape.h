// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"

namespace pmsc {

/// The training mean is a shape when the frames' RMS motion about it is at most this share of its
/// bounding-box diagonal. Decision, from measurements: the ICT face moves by 0.5%, a synthetic
/// deforming surface by 2.3%, the Cornell box's RGB irradiance by 20% (light, not points moving).
inline constexpr double kMostMotion = 0.1;

/// RMS over points and frames of a point's motion about the training mean, from the model's total
/// energy (the mean-removed matrix's energy per point and frame).
double rmsMotion(const Model& model);

/// The frames' RMS motion `rmsMotion` as a share of the training mean's bounding-box diagonal (3
/// channels: the mean read as N points); 0 when neither moves, infinity when only the mean is a
/// point. The mean is a shape when this is at most kMostMotion.
double motionShare(const Model& model, double rmsMotion);

/// The training mean as N x 3 positions (one row per point) when it is a shape: 3 channels, and
/// motionShare at most kMostMotion. Empty otherwise.
Eigen::MatrixXd meanShape(const Model& model, double rmsMotion);

}  // namespace pmsc
