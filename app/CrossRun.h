// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/Run.h"

namespace pmsc::app {

/// `pmsc run` with a cross model: `control` is an evaluator of the control (N = the
/// model's control points), evaluated at the key points only; the target frames are written one
/// .npy per frame (targetPoints x C), resumable as runFrames(). The stats file has each frame's key
/// RMS and bound and says fail-through is impossible. Checks before any work: the evaluator's N and
/// C, --keep-misses / --whole-frame-fail-through / a format other than npy (refused), the frames,
/// the output folder.
RunReport runCrossFrames(const Model& model, const PointEvaluator& control, const RunOptions& options);

}  // namespace pmsc::app
