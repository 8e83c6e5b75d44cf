// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/FaceAnimation.h"
#include "evaluators/face/FaceRig.h"
#include "pmsc/FrameWriter.h"
#include "pmsc/PointEvaluator.h"

#include <memory>

namespace pmsc::face {

/// The face rig as the engine's point evaluator (section 7): frame f -> the animation's controls
/// at f -> the rig posing the requested points. Implements "face:DIR" on the command line.
///
/// Thread safety and determinism are the rig's (FaceRig): any subset, any thread, same bits.
/// Also offers a per-frame .obj writer (FrameWriterProvider) so `pmsc run` can write posed meshes.
class FaceEvaluator : public PointEvaluator, public FrameWriterProvider {
public:
    /// Shares the rig (it takes ~1 s to build) and the animation.
    FaceEvaluator(std::shared_ptr<const FaceRig> rig, std::shared_ptr<const FaceAnimation> animation,
                  std::shared_ptr<const ObjMesh> mesh);

    std::string name() const override { return "face"; }
    Index pointCount() const override { return rig_->pointCount(); }
    Index channelCount() const override { return 3; }
    Index frameCount() const override { return animation_->frameCount(); }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override;
    void evaluateAll(Index frame, double* out) const override;
    /// A whole-frame fail-through is one full pose (the rig shares relax rings and contact inputs
    /// between points; 64 chunks through a 32-plan cache cost more than a pose), and a subset
    /// poses only its dependency closure, so local fail-through pays off.
    FailThroughShape failThroughShape() const override { return {true, 0, true}; }

    std::vector<std::shared_ptr<const FrameWriter>> frameWriters() const override;

    const FaceRig& rig() const { return *rig_; }
    const FaceAnimation& animation() const { return *animation_; }
    const ObjMesh& mesh() const { return *mesh_; }

private:
    const ControlVector& controls(Index frame) const;

    std::shared_ptr<const FaceRig> rig_;
    std::shared_ptr<const FaceAnimation> animation_;
    std::shared_ptr<const ObjMesh> mesh_;
};

/// Loads the ICT face from `folder`, builds the rig and the default animation
/// (FaceAnimationOptions{}): what "face:DIR" means on the command line.
/// @throws InputError naming the file for a missing or bad ICT folder.
std::unique_ptr<FaceEvaluator> makeFaceEvaluator(const std::string& folder,
                                                 const FaceAnimationOptions& options = {});

}  // namespace pmsc::face
