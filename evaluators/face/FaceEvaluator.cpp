#include "evaluators/face/FaceEvaluator.h"

#include "evaluators/face/ObjWriter.h"

#include <stdexcept>
#include <string>

namespace pmsc::face {

FaceEvaluator::FaceEvaluator(std::shared_ptr<const FaceRig> rig,
                             std::shared_ptr<const FaceAnimation> animation,
                             std::shared_ptr<const ObjMesh> mesh)
    : rig_(std::move(rig)), animation_(std::move(animation)), mesh_(std::move(mesh)) {
    if (!rig_ || !animation_ || !mesh_)
        throw std::invalid_argument("FaceEvaluator: needs a rig, an animation and a mesh");
}

const ControlVector& FaceEvaluator::controls(Index frame) const {
    if (frame < 0 || frame >= frameCount()) {
        throw std::out_of_range("face: frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(frameCount()) + ")");
    }
    return animation_->frame(frame);
}

void FaceEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    rig_->evaluate(controls(frame), points, out);
}

void FaceEvaluator::evaluateAll(Index frame, double* out) const { rig_->evaluateAll(controls(frame), out); }

std::vector<std::shared_ptr<const FrameWriter>> FaceEvaluator::frameWriters() const {
    return {std::make_shared<ObjFrameWriter>(mesh_->vertexCount(), mesh_)};
}

std::unique_ptr<FaceEvaluator> makeFaceEvaluator(const std::string& folder,
                                                 const FaceAnimationOptions& options) {
    const IctFace face = loadIctFace(folder);
    auto rig = std::make_shared<const FaceRig>(face);
    auto animation = std::make_shared<const FaceAnimation>(FaceAnimation::generate(options));
    auto mesh = std::make_shared<const ObjMesh>(face.neutral);
    return std::make_unique<FaceEvaluator>(std::move(rig), std::move(animation), std::move(mesh));
}

}  // namespace pmsc::face
