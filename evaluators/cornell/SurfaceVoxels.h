// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/cornell/CornellScene.h"

#include <array>
#include <cstdint>
#include <vector>

namespace pmsc::cornell {

/// The points of the lighting cache: the box's surfaces voxelized into a sparse grid, one
/// point per active voxel (section 8's 160,000 illumination points, here in world space so the
/// cache serves moving cameras).
///
/// Index space follows OpenVDB's cell-centred convention: voxel (i,j,k) has its centre at
/// world (i,j,k) * voxelSizeMm and covers +-voxelSizeMm/2 around it.
///
/// Point p of the evaluator is voxel p of this list (sorted by (i,j,k), so the order, and with
/// it every point id, is the same on every run and machine).
struct SurfaceVoxels {
    double voxelSizeMm = 0;
    std::vector<std::array<std::int32_t, 3>> ijk;  ///< active voxel coordinates
    std::vector<Vec3> position;      ///< nearest surface point to the voxel centre (the gather point)
    std::vector<Vec3> normal;        ///< unit normal of that surface (its lit side)
    std::vector<std::int32_t> quad;  ///< index of that surface in CornellScene::quads()

    std::size_t size() const { return ijk.size(); }

    /// Voxelizes the scene at a given voxel size: a voxel is active when a surface sample lands
    /// in it (samples every voxelSize/3 along each quad, so a plane yields a one-voxel shell).
    /// The floor inside the blocks' footprints is skipped (never seen, never lit).
    static SurfaceVoxels voxelize(const CornellScene& scene, double voxelSizeMm);

    /// Voxelizes with the voxel size that gives about `targetCount` active voxels: starts
    /// from sqrt(area / count) and corrects by sqrt(count ratio) until within 1% (at most
    /// 6 rounds). @throws std::invalid_argument for targetCount < 8.
    static SurfaceVoxels voxelizeToCount(const CornellScene& scene, std::size_t targetCount);
};

}  // namespace pmsc::cornell
