// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/FaceAnimation.h"
#include "evaluators/face/FaceRig.h"
#include "pmsc/PointEvaluator.h"

#include <memory>
#include <string>

namespace pmsc::face {

/// The control face as a point evaluator ("face-control:DIR" on the command line): frame f ->
/// the default animation's controls at f (the same frames as "face:DIR") -> FaceRig::evaluateControl
/// (blendshapes, jaw, eyelids, eyes; no relax, flesh or contact). It is what a cross model
/// (section 7, "Cross Point Multiplication") evaluates at its control keys:
/// `pmsc run --model CROSS.pmsc --evaluator face-control:DIR`.
///
/// Thread safety and determinism are the rig's (FaceRig): any subset, any thread, same bits.
class FaceControlEvaluator : public PointEvaluator {
public:
    FaceControlEvaluator(std::shared_ptr<const FaceRig> rig, std::shared_ptr<const FaceAnimation> animation)
        : rig_(std::move(rig)), animation_(std::move(animation)) {}
    std::string name() const override { return "face-control"; }
    Index pointCount() const override { return rig_->pointCount(); }
    Index channelCount() const override { return 3; }
    Index frameCount() const override { return animation_->frameCount(); }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override;

private:
    std::shared_ptr<const FaceRig> rig_;
    std::shared_ptr<const FaceAnimation> animation_;
};

/// Loads the ICT face from `folder` and builds the control evaluator over the default animation.
/// @throws InputError naming the file for a missing or bad ICT folder.
std::unique_ptr<FaceControlEvaluator> makeFaceControlEvaluator(const std::string& folder);

}  // namespace pmsc::face
