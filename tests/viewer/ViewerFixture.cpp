#include "tests/viewer/ViewerFixture.h"

#include "evaluators/volume/DensityVolume.h"
#include "pmsc/FrameSet.h"
#include "pmsc/Training.h"

#include <gtest/gtest.h>

#include <unistd.h>
#include <cstdlib>
#include <filesystem>

namespace pmsc::viewer::test {

namespace {

void build(SmallVolume& v) {
    const std::string mesh = std::string(PMSC_ASSIMP_MODELS_DIR) + "/OBJ/WusonOBJ.obj";
    if (!std::filesystem::exists(mesh)) return;
    v.dir = (std::filesystem::temp_directory_path() / ("pmsc_viewer_" + std::to_string(::getpid()))).string();
    std::filesystem::create_directories(v.dir);
    volume::FogOptions fog;
    fog.targetVoxels = 5000;
    volume::DensityVolume::fromMesh(mesh, fog).write(v.dir + "/density.vdb");
    v.scene = makeRelightScene("volume:" + v.dir + "/density.vdb:samples=2");
    const Index n = v.scene->pointCount();
    std::vector<Controls> lights;
    for (int e : {10, 40, 70}) {
        for (int a = 0; a < 8; ++a) {
            lights.push_back(
                {{"azimuth", 45.0 * a}, {"elevation", double(e)}, {"kelvin", a % 2 ? 4000.0 : 6500.0}});
        }
    }
    FrameSet q(Index(lights.size()), n, 3);
    for (size_t f = 0; f < lights.size(); ++f)
        v.scene->evaluator(lights[f])->evaluateAll(0, q.frame(Index(f)));
    TrainingOptions o;
    o.maxBasis = 12;
    o.maxKeys = 48;
    v.model = train(q, o);
}

}  // namespace

SmallVolume::~SmallVolume() {
    std::error_code ec;
    if (!dir.empty()) std::filesystem::remove_all(dir, ec);
}

const SmallVolume& smallVolume() {
    static SmallVolume v;
    static const bool built = (build(v), true);
    (void)built;
    return v;
}

std::vector<double> fullValues(const RelightScene& scene, const Controls& controls) {
    std::vector<double> out(size_t(scene.pointCount() * 3));
    scene.evaluator(scene.resolve(controls))->evaluateAll(0, out.data());
    return out;
}

}  // namespace pmsc::viewer::test
