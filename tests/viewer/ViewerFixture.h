// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"
#include "viewer/RelightScene.h"

#include <memory>
#include <string>

namespace pmsc::viewer::test {

/// A small smoke (about 5,000 voxels of the demo's mesh) written as a .vdb, its scene through
/// makeRelightScene, and a model trained on 24 of the scene's own lights. Built once per test
/// program; empty scene when the mesh is missing (assimp-testmodels).
struct SmallVolume {
    std::string dir;
    std::unique_ptr<RelightScene> scene;
    Model model;
    ~SmallVolume();
};
const SmallVolume& smallVolume();

/// The full calculation of every point of `scene` for `controls`.
std::vector<double> fullValues(const RelightScene& scene, const Controls& controls);

}  // namespace pmsc::viewer::test
