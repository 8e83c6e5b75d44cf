// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace pmsc::scene {

/// One frame of values at points that have places (an exec child's, a renderer's probes) as a
/// sparse .vdb light cache, for `pmsc run --format vdb` and for any reader of OpenVDB (Blender's
/// Python with pyopenvdb, Houdini, `vdb_print`):
///
/// - grid "light": the values, a Vec3SGrid for 3 channels (RGB) or a FloatGrid for 1, one active
///   voxel per occupied cell, holding the mean of the points in it;
/// - grid "position": a Vec3SGrid of the same topology, the mean position of those points, so a
///   reader knows where each value was computed;
/// - metadata on "light": "frame", "points" (N), "voxel_size", "points_in_shared_voxels".
///
/// The voxel size (cellSizeFor): half the median distance from a point to its nearest other point,
/// with the transform's cell centres on the lattice (a point p is in voxel round(p / h)). Why half
/// the median: a voxel then holds about one point, so reading the light back at a point's own
/// position gives its value (points closer than that share their mean, as in any light cache),
/// while a surface's cache stays a sheet of voxels a few per leaf node rather than one isolated
/// point per 8^3 leaf (which would cost 6 KB a point). OpenVDB is included only by the .cpp.
class PointCacheGrid {
public:
    /// The voxel size for `positions` (N x 3, point-major): half the median nearest-neighbour
    /// distance; for one point, or points all at one place, 1. @throws InputError for a
    /// non-finite position.
    static double cellSizeFor(std::span<const double> positions);

    /// Writes `values` (N x channels, channels 1 or 3) at `positions` (N x 3) with voxel size
    /// `cellSize` straight to `path` (the caller makes the file appear atomically).
    /// @throws std::invalid_argument for sizes that disagree or other channel counts;
    ///         pmsc::IoError naming `path` when it cannot be written.
    static void write(const std::string& path, std::span<const double> positions,
                      std::span<const double> values, Index channels, double cellSize, Index frame);

    /// The values of a file written by write() read back at `positions` (M x 3): the value of the
    /// voxel each falls in (a point's own, or the mean of the points that share its voxel), M x
    /// channels (1 or 3, as written). What a renderer does with the cache, and the tests' check.
    /// @throws pmsc::InputError for a missing, unreadable or foreign file, or a position in no
    ///         active voxel (naming its index).
    static std::vector<double> sample(const std::string& path, std::span<const double> positions,
                                      Index& channels);

    /// The "points" metadata of a file written by write(). @throws pmsc::InputError for a
    /// missing, unreadable or foreign file.
    static std::int64_t pointCount(const std::string& path);
};

}  // namespace pmsc::scene
