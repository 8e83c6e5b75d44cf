#include "evaluators/face/FaceControlEvaluator.h"

#include "evaluators/face/IctFace.h"

#include <stdexcept>
#include <string>

namespace pmsc::face {

void FaceControlEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    if (frame < 0 || frame >= frameCount())
        throw std::out_of_range("face-control: frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(frameCount()) + ")");
    rig_->evaluateControl(animation_->frame(frame), points, out);
}

std::unique_ptr<FaceControlEvaluator> makeFaceControlEvaluator(const std::string& folder) {
    const IctFace face = loadIctFace(folder);
    return std::make_unique<FaceControlEvaluator>(
        std::make_shared<const FaceRig>(face),
        std::make_shared<const FaceAnimation>(FaceAnimation::generate({})));
}

}  // namespace pmsc::face
