// The volume scene of the viewer: any .vdb density, lit by the rig's spherical light moved by
// azimuth, elevation and colour temperature.
#include "evaluators/volume/VolumeEvaluator.h"
#include "pmsc/Errors.h"
#include "viewer/RelightScene.h"
#include "viewer/SceneBytes.h"

namespace pmsc::viewer {

namespace {

using volume::VolumeEvaluator;
using volume::VolumeLight;
using volume::VolumeRig;
using volume::VolumeWorld;

class VolumeScene : public RelightScene {
public:
    VolumeScene(std::shared_ptr<const VolumeWorld> world, std::string source)
        : world_(std::move(world)), source_(std::move(source)) {
        // Elevation reaches below the training band (6 to 76 degrees) and kelvin past its
        // 4000-6500 K, so a lighter can leave what the model was trained on and watch the
        // cache fail through to the full calculation.
        controls_ = {{"azimuth", "Light azimuth", "deg", 0, 360, 0.5, 30},
                     {"elevation", "Light elevation", "deg", -60, 89, 0.5, 40},
                     {"kelvin", "Colour temperature", "K", 2500, 10000, 50, 5000}};
        std::vector<std::array<double, 3>> p;
        p.reserve(world_->density.voxelCount());
        for (const auto& v : world_->density.voxelPositions()) p.push_back({v.x, v.y, v.z});
        layout_ = DenseLayout::of(p, world_->density.voxelSize());
    }

    std::string kind() const override { return "volume"; }
    Index pointCount() const override { return Index(world_->density.voxelCount()); }
    const std::vector<Control>& controls() const override { return controls_; }

    nlohmann::json describe() const override {
        const auto& m = world_->medium;
        const auto c = world_->centre;
        return {
            {"kind", "volume"},
            {"source", source_},
            {"points", pointCount()},
            {"channels", 3},
            {"grid", layout_.toJson()},
            {"camera", {{"target", {c.x, c.y, c.z}}, {"distance", 3.2 * world_->radius}, {"up", {0, 1, 0}}}},
            {"volume", {{"sigma_t", m.sigmaT}, {"albedo", {m.albedo[0], m.albedo[1], m.albedo[2]}}}}};
    }

    std::string geometry() const override {
        std::string out;
        const std::size_t n = world_->density.voxelCount();
        out.reserve(n * 8);
        for (std::uint32_t i : layout_.index) appendBytes(out, i);
        for (std::size_t i = 0; i < n; ++i) appendBytes(out, float(world_->density.densityAt(i)));
        return out;
    }

    nlohmann::json light(const Controls& controls) const override {
        const VolumeLight l = lightOf(resolve(controls));
        return {{"position", {l.position.x, l.position.y, l.position.z}}, {"radius", l.radius}};
    }

    std::shared_ptr<const PointEvaluator> evaluator(const Controls& controls) const override {
        return std::make_shared<VolumeEvaluator>(world_, std::vector<VolumeLight>{lightOf(resolve(controls))},
                                                 "volume");
    }

private:
    /// The training rig's light (distance and radius from the medium's size, intensity so an
    /// unshadowed voxel at the centre receives a luminance of 1), as the model was trained with.
    VolumeLight lightOf(const Controls& c) const {
        return VolumeRig{}.light(*world_, c.at("azimuth"), c.at("elevation"), c.at("kelvin"));
    }

    std::shared_ptr<const VolumeWorld> world_;
    std::string source_;
    std::vector<Control> controls_;
    DenseLayout layout_;
};

}  // namespace

std::unique_ptr<RelightScene> makeVolumeScene(const std::string& args) {
    const volume::VolumeSpec spec = volume::parseVolumeSpec(args);
    if (args.find(":lights=") != std::string::npos)
        throw InputError(
            "scene 'volume': lights= is not an option of the viewer (its controls move the light)");
    auto world =
        VolumeWorld::create(volume::DensityVolume::read(spec.path, spec.grid), spec.medium, spec.path);
    return std::make_unique<VolumeScene>(std::move(world), spec.path);
}

}  // namespace pmsc::viewer
