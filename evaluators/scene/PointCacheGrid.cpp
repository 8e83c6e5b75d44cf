// The scene library's one translation unit that includes OpenVDB (its headers are heavy; STYLE.md).
#include "evaluators/scene/PointCacheGrid.h"

#include "pmsc/Errors.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <type_traits>
#include <unordered_map>
#include <vector>

namespace pmsc::scene {

namespace {

constexpr const char* kLight = "light";
constexpr const char* kPosition = "position";

struct CellHash {
    std::size_t operator()(const openvdb::Coord& c) const {
        return static_cast<std::size_t>(c.x()) * 73856093u ^ static_cast<std::size_t>(c.y()) * 19349663u ^
               static_cast<std::size_t>(c.z()) * 83492791u;
    }
};

openvdb::Coord cellOf(const double* p, double size) {
    return {static_cast<openvdb::Int32>(std::floor(p[0] / size)),
            static_cast<openvdb::Int32>(std::floor(p[1] / size)),
            static_cast<openvdb::Int32>(std::floor(p[2] / size))};
}

/// Each point's distance to its nearest other point within the 27 cells of side `size` around it
/// (infinity when there is none that near).
std::vector<double> nearestDistances(std::span<const double> positions, double size) {
    const std::size_t n = positions.size() / 3;
    std::unordered_map<openvdb::Coord, std::vector<std::size_t>, CellHash> cells;
    for (std::size_t i = 0; i < n; ++i) cells[cellOf(&positions[3 * i], size)].push_back(i);
    std::vector<double> out(n, std::numeric_limits<double>::infinity());
    for (std::size_t i = 0; i < n; ++i) {
        const double* p = &positions[3 * i];
        const openvdb::Coord c = cellOf(p, size);
        for (int dx = -1; dx <= 1; ++dx)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dz = -1; dz <= 1; ++dz) {
                    const auto found = cells.find(c.offsetBy(dx, dy, dz));
                    if (found == cells.end()) continue;
                    for (const std::size_t j : found->second) {
                        if (j == i) continue;
                        const double* q = &positions[3 * j];
                        const double d = std::hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]);
                        if (d > 0) out[i] = std::min(out[i], d);
                    }
                }
    }
    return out;
}

/// The points of one voxel: sums of their values and positions, and how many.
struct VoxelSum {
    double value[3] = {0, 0, 0}, position[3] = {0, 0, 0};
    int count = 0;
};
using VoxelSums = std::unordered_map<openvdb::Coord, VoxelSum, CellHash>;

/// A grid named `name` with voxel size `cellSize` whose voxels hold valueOf(their sum).
template <typename GridT, typename ValueOf>
typename GridT::Ptr gridOf(const VoxelSums& voxels, const char* name, double cellSize, ValueOf valueOf) {
    auto g = GridT::create(typename GridT::ValueType(0));
    g->setName(name);
    g->setTransform(openvdb::math::Transform::createLinearTransform(cellSize));
    g->setGridClass(openvdb::GRID_UNKNOWN);
    auto a = g->getAccessor();
    for (const auto& [ijk, s] : voxels) a.setValue(ijk, valueOf(s));
    return g;
}

openvdb::Vec3s meanOf(const double (&sum)[3], int count) {
    return {float(sum[0] / count), float(sum[1] / count), float(sum[2] / count)};
}

}  // namespace

double PointCacheGrid::cellSizeFor(std::span<const double> positions) {
    const std::size_t n = positions.size() / 3;
    double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
    for (std::size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) {
            const double v = positions[3 * i + size_t(a)];
            if (!std::isfinite(v))
                throw InputError("point " + std::to_string(i) + " has a non-finite position");
            lo[a] = i == 0 ? v : std::min(lo[a], v);
            hi[a] = i == 0 ? v : std::max(hi[a], v);
        }
    const double diagonal = std::hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
    if (n < 2 || diagonal == 0) return 1;
    // Cells of the size a point cloud filling the box would have: a surface's points are denser
    // in them, a few per occupied cell; a cell with no other point near widens the search.
    double cell = diagonal / std::cbrt(static_cast<double>(n));
    std::vector<double> d = nearestDistances(positions, cell);
    // Sparser than that (most points with no other in reach): cells twice as large, until most do.
    auto found = [&] { return std::count_if(d.begin(), d.end(), [](double v) { return std::isfinite(v); }); };
    while (static_cast<std::size_t>(found()) < n / 2 && cell < diagonal)
        d = nearestDistances(positions, cell *= 2);
    std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(n / 2), d.end());
    const double median = d[n / 2];
    return std::isfinite(median) && median > 0 ? median / 2 : 1;
}

void PointCacheGrid::write(const std::string& path, std::span<const double> positions,
                           std::span<const double> values, Index channels, double cellSize, Index frame) {
    const std::size_t n = positions.size() / 3;
    if (positions.size() != 3 * n || (channels != 1 && channels != 3) ||
        values.size() != n * static_cast<std::size_t>(channels) || !(cellSize > 0))
        throw std::invalid_argument("PointCacheGrid: " + std::to_string(values.size()) + " values of " +
                                    std::to_string(channels) + " channels at " + std::to_string(n) +
                                    " points (1 or 3 channels a point, a positive voxel size)");
    openvdb::initialize();  // idempotent and thread-safe (OpenVDB's own lock)
    // Sums and counts per voxel, then the means.
    VoxelSums voxels;
    const auto transform = openvdb::math::Transform::createLinearTransform(cellSize);
    for (std::size_t i = 0; i < n; ++i) {
        const double* p = &positions[3 * i];
        VoxelSum& s = voxels[transform->worldToIndexCellCentered(openvdb::Vec3d(p[0], p[1], p[2]))];
        for (int c = 0; c < channels; ++c) s.value[c] += values[i * size_t(channels) + size_t(c)];
        for (int a = 0; a < 3; ++a) s.position[a] += p[a];
        ++s.count;
    }
    std::int64_t shared = 0;
    for (const auto& entry : voxels)
        if (entry.second.count > 1) shared += entry.second.count;
    auto position = gridOf<openvdb::Vec3SGrid>(voxels, kPosition, cellSize,
                                               [](const VoxelSum& s) { return meanOf(s.position, s.count); });
    position->setVectorType(openvdb::VEC_CONTRAVARIANT_ABSOLUTE);
    openvdb::GridBase::Ptr light;
    if (channels == 3)
        light = gridOf<openvdb::Vec3SGrid>(voxels, kLight, cellSize,
                                           [](const VoxelSum& s) { return meanOf(s.value, s.count); });
    else
        light = gridOf<openvdb::FloatGrid>(voxels, kLight, cellSize,
                                           [](const VoxelSum& s) { return float(s.value[0] / s.count); });
    light->insertMeta("frame", openvdb::Int64Metadata(frame));
    light->insertMeta("points", openvdb::Int64Metadata(static_cast<std::int64_t>(n)));
    light->insertMeta("voxel_size", openvdb::DoubleMetadata(cellSize));
    light->insertMeta("points_in_shared_voxels", openvdb::Int64Metadata(shared));
    try {
        openvdb::io::File file(path);
        file.setCompression(openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK);
        openvdb::MetaMap fileMeta;
        fileMeta.insertMeta("creator", openvdb::StringMetadata("pmsc run"));
        file.write(openvdb::GridPtrVec{light, position}, fileMeta);
        file.close();
    } catch (const std::exception& e) {
        throw IoError("cannot write " + path + ": " + e.what());
    }
}

namespace {

/// The values of `grid` at the voxels of `positions`, `channels` each. @throws InputError naming
/// the first position in no active voxel.
template <typename GridT>
std::vector<double> voxelValues(const GridT& grid, std::span<const double> positions, int channels,
                                const std::string& path) {
    std::vector<double> out;
    out.reserve(positions.size() / 3 * size_t(channels));
    auto a = grid.getConstAccessor();
    for (std::size_t i = 0; i < positions.size() / 3; ++i) {
        const double* p = &positions[3 * i];
        const openvdb::Coord ijk =
            grid.transform().worldToIndexCellCentered(openvdb::Vec3d(p[0], p[1], p[2]));
        typename GridT::ValueType v;
        if (!a.probeValue(ijk, v))
            throw InputError(path + ": point " + std::to_string(i) + " is in no voxel of the cache");
        if constexpr (std::is_same_v<typename GridT::ValueType, float>) {
            out.push_back(v);
        } else {
            for (int c = 0; c < 3; ++c) out.push_back(v[c]);
        }
    }
    return out;
}

}  // namespace

std::vector<double> PointCacheGrid::sample(const std::string& path, std::span<const double> positions,
                                           Index& channels) {
    openvdb::initialize();  // idempotent and thread-safe (OpenVDB's own lock)
    openvdb::GridBase::Ptr light;
    try {
        openvdb::io::File file(path);
        file.open();
        if (!file.hasGrid(kLight)) throw InputError(path + ": not a point light cache (no grid 'light')");
        light = file.readGrid(kLight);
        file.close();
    } catch (const InputError&) {
        throw;
    } catch (const std::exception& e) {
        throw InputError(path + ": not a readable point light cache: " + e.what());
    }
    if (auto rgb = openvdb::gridPtrCast<openvdb::Vec3SGrid>(light)) {
        channels = 3;
        return voxelValues(*rgb, positions, 3, path);
    }
    if (auto scalar = openvdb::gridPtrCast<openvdb::FloatGrid>(light)) {
        channels = 1;
        return voxelValues(*scalar, positions, 1, path);
    }
    throw InputError(path + ": grid 'light' is neither a Vec3SGrid nor a FloatGrid");
}

std::int64_t PointCacheGrid::pointCount(const std::string& path) {
    openvdb::initialize();  // idempotent and thread-safe (OpenVDB's own lock)
    try {
        openvdb::io::File file(path);
        file.open();
        if (!file.hasGrid(kLight) || !file.hasGrid(kPosition))
            throw InputError(path + ": not a point light cache (no grids 'light' and 'position')");
        const std::int64_t points = file.readGridMetadata(kLight)->metaValue<openvdb::Int64>("points");
        file.close();
        return points;
    } catch (const InputError&) {
        throw;
    } catch (const std::exception& e) {
        throw InputError(path + ": not a readable point light cache: " + e.what());
    }
}

}  // namespace pmsc::scene
