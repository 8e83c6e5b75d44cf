// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
// Private to examples/volume: the OpenVDB side of DensityVolume, shared by the two translation
// units that include OpenVDB (DensityVolume.cpp and DensityFromMesh.cpp). Not installed.
#pragma once

#include "evaluators/volume/DensityVolume.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/RayIntersector.h>

namespace pmsc::volume {

/// Ray queries march leaf-node spans (NodeLevel 0 of the hierarchical DDA).
using Intersector = openvdb::tools::VolumeRayIntersector<openvdb::FloatGrid, 0>;

struct DensityVolume::Impl {
    openvdb::FloatGrid::Ptr grid;
    std::vector<Vec3> positions;          // world centres of the active voxels, point order
    std::vector<float> values;            // their densities
    std::unique_ptr<Intersector> master;  // owns the dilated topology; Tracers copy it shallowly
    double maxDensity = 0;
    Vec3 lo, hi;

    /// Voxelizes active tiles, lists the active voxels and builds the intersector.
    /// @throws pmsc::InputError (prefixed by `where`) for an empty grid or non-uniform voxels.
    void index(const std::string& where);
};

/// OpenVDB's one-time registration of grid types (thread-safe, idempotent).
void initOpenVdb();

/// Makes a DensityVolume from a finished Impl (for DensityFromMesh.cpp).
DensityVolume makeDensityVolume(std::shared_ptr<DensityVolume::Impl> impl);

}  // namespace pmsc::volume
