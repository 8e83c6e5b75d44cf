// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/cornell/CornellScene.h"

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace pmsc::volume {

using scene::Rgb;
using scene::Vec3;

/// How the demo turns a mesh into smoke (DensityVolume::fromMesh).
struct FogOptions {
    std::size_t targetVoxels = 260000;  ///< active voxels wanted (met within about 3%)
    double sizeMetres = 4.0;            ///< the mesh is scaled so its longest side is this long
    double noiseFrequency = 1.2;        ///< features per metre of the noise's first octave
    std::uint32_t noiseSeed = 11;
    /// density = scale x fog x (floor + (1 - floor) n^exponent), n in [0, 1] the fractal noise.
    /// The demo's smoke: 1, 0.15, 2 (lumpy, never empty inside). floor 1: uniform density (the
    /// noise plays no part); floor 0 and a high exponent: sparse wisps where the noise peaks.
    double densityScale = 1.0;
    double noiseFloor = 0.15;
    double noiseExponent = 2.0;
};

/// The medium: a heterogeneous density FloatGrid (OpenVDB) and the ordered list of its active
/// voxels, which are the points of the volumetric lighting cache (point i is the i-th active
/// voxel in leaf order, then voxel order within the leaf: deterministic for a given tree).
///
/// Active tiles are voxelized on load, so every active value is a voxel. World units are the
/// grid's own (metres for the demo's grid); density is dimensionless, the evaluator scales it
/// to an extinction coefficient.
///
/// OpenVDB is included only by DensityVolume.cpp (with ScatterCache) and DensityFromMesh.cpp.
/// Thread safety: const methods may run concurrently; a Tracer belongs to one thread.
class DensityVolume {
public:
    /// Reads a FloatGrid from a .vdb. gridName empty: the float grid named "density" if there is
    /// one, else the file's only float grid, whatever its name (vdb_tool's fog volumes are named
    /// after the mesh and the operations).
    /// @throws pmsc::InputError (one line, naming the file) for a missing or unreadable file, a
    ///         file without a float grid, several float grids none named "density" (listing
    ///         them), a grid name that is not in the file or not a float grid, a grid without
    ///         active voxels, or non-uniform voxels.
    static DensityVolume read(const std::string& path, const std::string& gridName = "");

    /// Builds smoke from a mesh (any format Assimp reads): OpenVDB's meshToLevelSet, then
    /// sdfToFogVolume (0 outside, ramping to 1 inside over the narrow band), then multiplied by
    /// fractal value noise so the density varies like a cloud; voxel size chosen for
    /// options.targetVoxels. @throws pmsc::InputError for a mesh that cannot be read or is empty.
    static DensityVolume fromMesh(const std::string& meshPath, const FogOptions& options);

    /// Writes the grid (named "density", class fog volume) atomically. @throws pmsc::IoError.
    void write(const std::string& path) const;

    std::size_t voxelCount() const;
    const std::vector<Vec3>& voxelPositions() const;  ///< world space, point order
    double voxelSize() const;                         ///< world units
    std::string gridName() const;
    std::pair<Vec3, Vec3> worldBounds() const;  ///< of the active voxels' centres
    double maxDensity() const;
    double densityAt(std::size_t point) const;  ///< the stored value of active voxel `point`
    /// Bytes of the density tree (OpenVDB's memUsage).
    std::uint64_t memoryBytes() const;

    /// Per-thread ray queries against the density: OpenVDB's VolumeRayIntersector (hierarchical
    /// DDA over the leaf nodes) finds the spans of the ray that pass through active leaves, and a
    /// midpoint-rule march with trilinear interpolation (tools::BoxSampler) integrates inside
    /// them, so empty space costs nothing.
    class Tracer {
    public:
        explicit Tracer(const DensityVolume& volume);
        ~Tracer();
        Tracer(const Tracer&) = delete;
        Tracer& operator=(const Tracer&) = delete;

        /// Integral of the density along the segment from `from` to `to` (world units x density).
        /// stepVoxels: march step in voxels (the spans are split into equal steps of at most that length).
        double densityIntegral(Vec3 from, Vec3 to, double stepVoxels);
        /// Trilinearly interpolated density at a world position.
        double density(Vec3 p);
        /// World-distance spans [t0, t1] of the ray origin + t dir (dir unit), t in [0, tMax],
        /// that cross active leaf nodes (dilated by one voxel for the interpolation stencil).
        void spans(Vec3 origin, Vec3 dir, double tMax, std::vector<std::pair<double, double>>& out);

    private:
        struct Impl;
        std::unique_ptr<Impl> impl_;
    };

    struct Impl;
    const Impl& impl() const { return *impl_; }

private:
    friend DensityVolume makeDensityVolume(std::shared_ptr<Impl> impl);
    explicit DensityVolume(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}
    std::shared_ptr<const Impl> impl_;
};

DensityVolume makeDensityVolume(std::shared_ptr<DensityVolume::Impl> impl);

/// What a cache file records about its frame (grid metadata of "inscatter").
struct ScatterCacheInfo {
    std::int32_t frame = 0;
    Vec3 lightPosition;
    double lightKelvin = 0;
    std::string state = "full";  ///< "hit", "blend", "miss", "full" or "soft-cached"
    double sigmaT = 0;           ///< extinction per unit density per world unit
    Rgb albedo{0, 0, 0};
};

/// One frame of the volumetric lighting cache: a Vec3SGrid named "inscatter" with exactly the
/// density grid's topology (a TopologyCopy of its tree), values the in-scattered radiance RGB
/// (isotropic phase, view-independent). In a DCC tool: emission = density x sigma_s x inscatter,
/// sigma_s = sigma_t x albedo (both stored as metadata). Memory grows with the active voxels, not
/// the bounding box: the leaves hold dense 8^3 buffers of Vec3s (12 bytes), so a cache costs 12
/// bytes / (leaf fill ratio) per active voxel plus small internal nodes; measured for the demo's
/// 253,972 voxels (58% leaf fill): 9.6 MB in memory (38 bytes per voxel, 85% of a dense box of
/// the same extent because the smoke fills its box), 2.4 MB on disk (blosc).
class ScatterCache {
public:
    /// @param values density.voxelCount() * 3 doubles, point order.
    /// @throws std::invalid_argument on a size mismatch.
    ScatterCache(const DensityVolume& density, std::span<const double> values, const ScatterCacheInfo& info);
    ~ScatterCache();
    ScatterCache(ScatterCache&&) noexcept;
    ScatterCache& operator=(ScatterCache&&) noexcept;

    /// Atomic write (pmsc::AtomicFile). @throws pmsc::IoError naming the path.
    void write(const std::string& path) const;
    /// Straight to `path` (for FrameWriter, whose caller renames). @throws pmsc::IoError.
    void writeTo(const std::string& path) const;
    /// @throws pmsc::InputError for a file without an "inscatter" Vec3SGrid.
    static ScatterCache read(const std::string& path);

    std::int64_t activeVoxelCount() const;
    std::uint64_t memoryBytes() const;
    ScatterCacheInfo info() const;

    /// Per-thread world-space lookups: trilinear over the 8 voxels around p, inactive voxels left
    /// out and the weights renormalized (at the medium's edge half of a stencil is outside, and
    /// counting those as black would darken the rim that the density still shows).
    class Sampler {
    public:
        explicit Sampler(const ScatterCache& cache);
        ~Sampler();
        Rgb at(Vec3 p);

    private:
        struct Impl;
        std::unique_ptr<Impl> impl_;
    };

private:
    ScatterCache();
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace pmsc::volume
