// The Cornell box of the viewer: the measured box, one bounce of indirect light from a point
// light moved over the plane of the training lights.
#include "evaluators/cornell/CornellEvaluator.h"
#include "pmsc/Errors.h"
#include "viewer/RelightScene.h"
#include "viewer/SceneBytes.h"

namespace pmsc::viewer {

namespace {

using cornell::CornellEvaluator;
using cornell::CornellWorld;
using cornell::LightRig;
using cornell::PointLight;

class CornellRelightScene : public RelightScene {
public:
    CornellRelightScene(std::shared_ptr<const CornellWorld> world, int samples, std::string source)
        : world_(std::move(world)), samples_(samples), source_(std::move(source)) {
        // The training lights cover x 80-476 mm and z 81.6-477.6 mm (12 x 12, 36 mm apart); the
        // controls reach the walls, where the model has seen nothing.
        controls_ = {{"x", "Light x", "mm", 20, 536, 1, 278}, {"z", "Light z", "mm", 20, 539, 1, 279.6}};
        std::vector<std::array<double, 3>> p;
        const double h = world_->voxels.voxelSizeMm;
        for (const auto& ijk : world_->voxels.ijk) p.push_back({ijk[0] * h, ijk[1] * h, ijk[2] * h});
        layout_ = DenseLayout::of(p, h);
    }

    std::string kind() const override { return "cornell"; }
    Index pointCount() const override { return Index(world_->voxels.size()); }
    const std::vector<Control>& controls() const override { return controls_; }

    nlohmann::json describe() const override {
        nlohmann::json quads = nlohmann::json::array();
        for (const auto& q : world_->scene.quads()) {
            nlohmann::json corners = nlohmann::json::array();
            for (const auto& c : q.corners) corners.push_back({c.x, c.y, c.z});
            quads.push_back({{"name", q.name},
                             {"corners", corners},
                             {"albedo", {q.albedo[0], q.albedo[1], q.albedo[2]}},
                             {"normal", {q.normal.x, q.normal.y, q.normal.z}}});
        }
        return {{"kind", "cornell"},
                {"source", source_},
                {"points", pointCount()},
                {"channels", 3},
                {"grid", layout_.toJson()},
                {"camera", {{"target", {278.0, 274.4, 279.6}}, {"distance", 1340.0}, {"up", {0, 1, 0}}}},
                {"quads", quads}};
    }

    std::string geometry() const override {
        std::string out;
        for (std::uint32_t i : layout_.index) appendBytes(out, i);
        for (const auto& n : world_->voxels.normal) {
            appendBytes(out, float(n.x));
            appendBytes(out, float(n.y));
            appendBytes(out, float(n.z));
        }
        return out;
    }

    nlohmann::json light(const Controls& controls) const override {
        const PointLight l = lightOf(resolve(controls));
        return {{"position", {l.position.x, l.position.y, l.position.z}}, {"radius", 0.0}};
    }

    std::shared_ptr<const PointEvaluator> evaluator(const Controls& controls) const override {
        return std::make_shared<CornellEvaluator>(world_, std::vector<PointLight>{lightOf(resolve(controls))},
                                                  samples_, "cornell");
    }

private:
    /// The training rig's light at (x, z), on its plane below the ceiling, with its intensity.
    static PointLight lightOf(const Controls& c) {
        const LightRig rig;
        PointLight l = rig.trainingLights().front();
        l.position.x = c.at("x");
        l.position.z = c.at("z");
        return l;
    }

    std::shared_ptr<const CornellWorld> world_;
    int samples_;
    std::string source_;
    std::vector<Control> controls_;
    DenseLayout layout_;
};

}  // namespace

std::unique_ptr<RelightScene> makeCornellScene(const std::string& args) {
    const cornell::CornellSpec spec = cornell::parseCornellSpec(args);
    if (args.find("lights=") != std::string::npos)
        throw InputError(
            "scene 'cornell': lights= is not an option of the viewer (its controls move the light)");
    return std::make_unique<CornellRelightScene>(CornellWorld::create(spec.points), spec.samples,
                                                 "cornell:" + args);
}

}  // namespace pmsc::viewer
