// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/cornell/CornellScene.h"
#include "evaluators/cornell/SurfaceVoxels.h"

#include <cstdint>
#include <memory>
#include <span>
#include <string>

namespace pmsc::cornell {

/// What a lighting-cache file records about its frame (stored as grid metadata).
struct CacheMetadata {
    std::int32_t frame = 0;
    Vec3 lightPosition;          ///< millimetres
    std::string state = "miss";  ///< section 5: "hit", "blend", "miss" (or "full" for a reference)
    double weight = 1;           ///< weight of the full result in the values (0 hit .. 1 miss)
    double keyError = 0;         ///< the key points' RMS error of the frame (data units)
};

/// The lighting cache of one frame: an OpenVDB Vec3SGrid named "indirect" whose active voxels
/// are the cache's points (SurfaceVoxels) and whose values are the indirect irradiance (RGB),
/// with a world transform in millimetres (voxel size from SurfaceVoxels). Two companion grids
/// of the same topology, "normal" and "surface_point", record where each voxel's value was
/// gathered, so a renderer can sample the cache at any world position (the paper's "spatial
/// data structure ... to accommodate moving cameras", section 8).
///
/// OpenVDB is included only by LightingCacheGrid.cpp.
/// Thread safety: const methods may run concurrently (each call uses its own accessors).
class LightingCacheGrid {
public:
    /// Builds the grids. @param values voxels.size()*3 doubles, voxel order.
    /// @throws std::invalid_argument on a size mismatch.
    LightingCacheGrid(const SurfaceVoxels& voxels, std::span<const double> values, const CacheMetadata& meta);
    ~LightingCacheGrid();
    LightingCacheGrid(LightingCacheGrid&&) noexcept;
    LightingCacheGrid& operator=(LightingCacheGrid&&) noexcept;

    /// Writes the three grids to a .vdb file readable by `vdb_print` (blosc/zip compressed),
    /// atomically (pmsc::AtomicFile). @throws pmsc::IoError naming the path.
    void write(const std::string& path) const;
    /// The same, straight to `path` with no temporary file: for callers that make the file
    /// appear atomically themselves (pmsc::FrameWriter). @throws pmsc::IoError.
    void writeTo(const std::string& path) const;
    /// Reads a file written by write(). @throws pmsc::InputError for a missing, unreadable
    /// or foreign file (no "indirect" Vec3SGrid, companion grids missing or mismatched).
    static LightingCacheGrid read(const std::string& path);

    CacheMetadata metadata() const;
    double voxelSizeMm() const;
    std::int64_t activeVoxelCount() const;
    /// The stored value at voxel ijk (zero if inactive).
    Rgb valueAt(const std::array<std::int32_t, 3>& ijk) const;

    /// World-space lookup for rendering: trilinear interpolation over the 8 voxels around p,
    /// keeping only active voxels whose surface normal agrees with n (dot > 0.5), weights
    /// renormalized. Why not openvdb::tools::BoxSampler: the cache is a one-voxel shell, so
    /// half of any trilinear stencil is empty background and would darken every lookup, and
    /// at corners the stencil reaches the other wall (red bleeding onto the floor). Falls back
    /// to the nearest matching voxel within 2 voxels, then to zero.
    /// @param[out] out 3 doubles per point.
    void sample(std::span<const Vec3> p, std::span<const Vec3> n, double* out) const;

private:
    LightingCacheGrid();
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace pmsc::cornell
