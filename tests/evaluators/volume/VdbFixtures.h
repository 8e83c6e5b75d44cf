// pmsc — test inputs for the volume tests, written with OpenVDB (VdbFixtures.cpp only).
#pragma once

#include <string>
#include <vector>

namespace pmsc::volume::test {

/// A box of constant density `density` spanning [-half, half]^3 (world units), voxel `voxel`,
/// as a FloatGrid named `name` in a new file at `path`.
void writeDensityBox(const std::string& path, const std::string& name, double half, double voxel,
                     float density);
/// Several float grids, each a box of constant density 1 spanning [-half, half]^3, named `names`.
void writeFloatGrids(const std::string& path, const std::vector<std::string>& names, double half,
                     double voxel);
/// A float grid `name` without active voxels.
void writeEmptyFloatGrid(const std::string& path, const std::string& name);
/// A file with only a Vec3SGrid "velocity" (no float grid).
void writeVectorOnly(const std::string& path);
/// A FloatGrid "density" (voxel `voxel`) of pseudo-random values from `seed` over index
/// [-12, 12)^3 (parts of 4 x 4 x 4 leaves around the origin; active and inactive voxels alike),
/// with an active leaf-sized tile (which DensityVolume::read voxelizes) and an inactive one of
/// other values beside them.
void writeNoiseDensity(const std::string& path, double voxel, unsigned seed);
/// openvdb::tools::BoxSampler's trilinear value of the grid "density" in `path` at each world
/// point (x, y, z in turn), read the way OpenVDB's own samplers read it.
std::vector<double> boxSamplerDensities(const std::string& path, const std::vector<double>& xyz);
/// The demo's mesh (assimp-testmodels' WusonOBJ.obj) or "" when the folder is missing.
std::string testMesh();
/// A fresh temporary folder for one test.
std::string tempDir(const std::string& tag);

}  // namespace pmsc::volume::test
