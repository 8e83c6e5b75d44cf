// One of the two translation units of examples/volume that include OpenVDB (the other builds the
// demo's density from a mesh): the density grid, its ray queries, and the cache grids.
#include "evaluators/volume/DensityVolumeImpl.h"

#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include <openvdb/tools/Interpolation.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <mutex>
#include <stdexcept>

namespace pmsc::volume {

void initOpenVdb() {
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

DensityVolume makeDensityVolume(std::shared_ptr<DensityVolume::Impl> impl) {
    return DensityVolume(std::shared_ptr<const DensityVolume::Impl>(std::move(impl)));
}

void DensityVolume::Impl::index(const std::string& where) {
    if (!grid->hasUniformVoxels())
        throw InputError(where + ": the grid's voxels are not cubes (non-uniform scale)");
    grid->tree().voxelizeActiveTiles();
    if (grid->tree().activeVoxelCount() == 0) throw InputError(where + ": the grid has no active voxels");
    positions.clear();
    values.clear();
    positions.reserve(grid->tree().activeVoxelCount());
    values.reserve(grid->tree().activeVoxelCount());
    const auto& xf = grid->transform();
    maxDensity = 0;
    const double inf = std::numeric_limits<double>::infinity();
    lo = {inf, inf, inf};
    hi = {-inf, -inf, -inf};
    for (auto leaf = grid->tree().cbeginLeaf(); leaf; ++leaf) {
        for (auto v = leaf->cbeginValueOn(); v; ++v) {
            const openvdb::Vec3d w = xf.indexToWorld(v.getCoord());
            const Vec3 p{w.x(), w.y(), w.z()};
            positions.push_back(p);
            values.push_back(*v);
            maxDensity = std::max(maxDensity, static_cast<double>(*v));
            lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
            hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
        }
    }
    // One dilation: the trilinear stencil reaches one voxel beyond the active ones.
    master = std::make_unique<Intersector>(*grid, /*dilationCount=*/1);
}

namespace {

/// No grid named: the float grid named "density" if there is one, else the file's only float grid
/// (mesh-to-volume tools name it after the mesh and the operations, e.g. vdb_tool's
/// "ls2fog_mesh2ls_NAME"). Several float grids and none named "density": one error listing them,
/// since picking the first would light whichever grid the writer happened to store first.
openvdb::GridBase::Ptr readTheDensityGrid(openvdb::io::File& file, const std::string& where) {
    std::vector<std::string> floats;
    const openvdb::GridPtrVecPtr grids = file.readAllGridMetadata();  // held: the loop reads it
    for (const auto& g : *grids)
        if (g->isType<openvdb::FloatGrid>()) floats.push_back(g->getName());
    if (floats.empty()) throw InputError(where + ": has no float grid (a density FloatGrid is needed)");
    if (std::find(floats.begin(), floats.end(), "density") != floats.end()) return file.readGrid("density");
    if (floats.size() > 1) {
        std::string names;
        for (const auto& n : floats) names += (names.empty() ? "'" : ", '") + n + "'";
        throw InputError(
            where + ": " + std::to_string(floats.size()) + " float grids (" + names +
            ") and none named 'density': name one (--grid NAME, or grid=NAME in a volume: spec)");
    }
    return file.readGrid(floats.front());
}

}  // namespace

DensityVolume DensityVolume::read(const std::string& path, const std::string& gridName) {
    initOpenVdb();
    const std::string where = "volume: " + path;
    if (!std::filesystem::is_regular_file(path)) throw InputError(where + ": no such file");
    auto impl = std::make_shared<Impl>();
    try {
        openvdb::io::File file(path);
        file.open();
        openvdb::GridBase::Ptr base;
        if (!gridName.empty()) {
            if (!file.hasGrid(gridName)) {
                std::string names;
                for (auto it = file.beginName(); it != file.endName(); ++it)
                    names += (names.empty() ? "" : ", ") + *it;
                throw InputError(where + ": no grid named '" + gridName + "' (grids: " + names + ")");
            }
            base = file.readGrid(gridName);
            if (!openvdb::gridPtrCast<openvdb::FloatGrid>(base))
                throw InputError(where + ": grid '" + gridName + "' is a " + base->valueType() +
                                 " grid, not a float grid");
        } else {
            base = readTheDensityGrid(file, where);
        }
        file.close();
        impl->grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    } catch (const InputError&) {
        throw;
    } catch (const std::exception& e) {
        throw InputError(where + ": not a readable OpenVDB file: " + e.what());
    }
    impl->index(where);
    return DensityVolume(std::move(impl));
}

void DensityVolume::write(const std::string& path) const {
    AtomicFile out(path);
    try {
        openvdb::FloatGrid::Ptr g = impl_->grid->deepCopy();
        g->setName("density");
        g->setGridClass(openvdb::GRID_FOG_VOLUME);
        openvdb::io::File file(out.temporaryPath());
        file.setCompression(openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK);
        openvdb::MetaMap meta;
        meta.insertMeta("creator", openvdb::StringMetadata("pmsc demo volume"));
        file.write({g}, meta);
        file.close();
    } catch (const std::exception& e) {
        throw IoError("cannot write " + path + ": " + e.what());
    }
    out.commit();
}

std::size_t DensityVolume::voxelCount() const { return impl_->positions.size(); }
const std::vector<Vec3>& DensityVolume::voxelPositions() const { return impl_->positions; }
double DensityVolume::voxelSize() const { return impl_->grid->voxelSize()[0]; }
std::string DensityVolume::gridName() const { return impl_->grid->getName(); }
std::pair<Vec3, Vec3> DensityVolume::worldBounds() const { return {impl_->lo, impl_->hi}; }
double DensityVolume::maxDensity() const { return impl_->maxDensity; }
double DensityVolume::densityAt(std::size_t point) const { return impl_->values.at(point); }
std::uint64_t DensityVolume::memoryBytes() const { return impl_->grid->memUsage(); }

// --- Tracer ---------------------------------------------------------------------------------------

struct DensityVolume::Tracer::Impl {
    explicit Impl(const DensityVolume::Impl& v)
        : grid(*v.grid), acc(v.grid->tree()), inter(*v.master), voxel(v.grid->voxelSize()[0]) {}
    const openvdb::FloatGrid& grid;
    openvdb::tree::ValueAccessor<const openvdb::FloatTree, false> acc;  // unregistered: no mutex
    Intersector inter;  // shallow copy: shares the master's topology, own accessor
    double voxel;

    /// Trilinear density at an index-space position: the value of openvdb::tools::BoxSampler's
    /// sample() to the bit (its floor, its trilinearInterpolation on the same eight values), read
    /// from one leaf's buffer when the 2 x 2 x 2 stencil lies inside a leaf (343 of its 512 voxels)
    /// instead of eight accessor lookups. Why: the eight lookups were about a third of the
    /// evaluator's time (`perf` of pmsc_volume_bench).
    float sample(const openvdb::Vec3d& x) {
        using openvdb::tools::BoxSampler;
        using Leaf = openvdb::FloatTree::LeafNodeType;
        const openvdb::Vec3i floor = openvdb::tools::local_util::floorVec3(x);
        const openvdb::Vec3d uvw = x - floor;
        const openvdb::Coord ijk(floor);
        float data[2][2][2];
        constexpr int kLast = static_cast<int>(Leaf::DIM) - 1;
        if ((ijk.x() & kLast) != kLast && (ijk.y() & kLast) != kLast && (ijk.z() & kLast) != kLast) {
            if (const Leaf* leaf = acc.probeConstLeaf(ijk)) {
                // LeafNode::getValue(offset): the buffer read that also answers 0 for a leaf whose
                // buffer was never allocated, as the accessor does.
                constexpr openvdb::Index kX = 1u << (2 * Leaf::LOG2DIM), kY = 1u << Leaf::LOG2DIM;
                const openvdb::Index o = Leaf::coordToOffset(ijk);
                data[0][0][0] = leaf->getValue(o);
                data[0][0][1] = leaf->getValue(o + 1);
                data[0][1][0] = leaf->getValue(o + kY);
                data[0][1][1] = leaf->getValue(o + kY + 1);
                data[1][0][0] = leaf->getValue(o + kX);
                data[1][0][1] = leaf->getValue(o + kX + 1);
                data[1][1][0] = leaf->getValue(o + kX + kY);
                data[1][1][1] = leaf->getValue(o + kX + kY + 1);
                return BoxSampler::trilinearInterpolation(data, uvw);
            }
        }
        // The stencil straddles leaves: its corners lie in 2, 4 or 8 of them, one probe each (eight
        // lookups through the one-leaf accessor cache would alternate between them), and a corner
        // without a leaf reads its tile or the background through the accessor.
        const int sx = (ijk.x() & kLast) == kLast, sy = (ijk.y() & kLast) == kLast,
                  sz = (ijk.z() & kLast) == kLast;
        const Leaf* leaves[2][2][2] = {};
        for (int a = 0; a <= sx; ++a)
            for (int b = 0; b <= sy; ++b)
                for (int c = 0; c <= sz; ++c) leaves[a][b][c] = acc.probeConstLeaf(ijk.offsetBy(a, b, c));
        for (int a = 0; a < 2; ++a)
            for (int b = 0; b < 2; ++b)
                for (int c = 0; c < 2; ++c) {
                    const openvdb::Coord q = ijk.offsetBy(a, b, c);
                    const Leaf* leaf = leaves[a & sx][b & sy][c & sz];
                    data[a][b][c] = leaf ? leaf->getValue(q) : acc.getValue(q);
                }
        return BoxSampler::trilinearInterpolation(data, uvw);
    }
};

DensityVolume::Tracer::Tracer(const DensityVolume& volume) : impl_(std::make_unique<Impl>(*volume.impl_)) {}
DensityVolume::Tracer::~Tracer() = default;

double DensityVolume::Tracer::densityIntegral(Vec3 from, Vec3 to, double stepVoxels) {
    auto& m = *impl_;
    const openvdb::Vec3d a = m.grid.worldToIndex(openvdb::Vec3d(from.x, from.y, from.z));
    const openvdb::Vec3d b = m.grid.worldToIndex(openvdb::Vec3d(to.x, to.y, to.z));
    openvdb::Vec3d dir = b - a;
    const double len = dir.length();  // in voxels
    if (!(len > 0)) return 0;
    dir /= len;
    const openvdb::math::Ray<double> ray(a, dir, 0.0, len);
    if (!m.inter.setIndexRay(ray)) return 0;
    double t0 = 0, t1 = 0, sum = 0;
    while (m.inter.march(t0, t1)) {
        t0 = std::max(t0, 0.0);
        t1 = std::min(t1, len);
        if (t1 <= t0) continue;
        const int n = std::max(1, static_cast<int>(std::ceil((t1 - t0) / stepVoxels)));
        const double dt = (t1 - t0) / n;
        double s = 0;
        for (int i = 0; i < n; ++i) s += m.sample(a + dir * (t0 + (i + 0.5) * dt));
        sum += s * dt;
    }
    return sum * m.voxel;
}

double DensityVolume::Tracer::density(Vec3 p) {
    auto& m = *impl_;
    return m.sample(m.grid.worldToIndex(openvdb::Vec3d(p.x, p.y, p.z)));
}

void DensityVolume::Tracer::spans(Vec3 origin, Vec3 dir, double tMax,
                                  std::vector<std::pair<double, double>>& out) {
    auto& m = *impl_;
    out.clear();
    const openvdb::Vec3d a = m.grid.worldToIndex(openvdb::Vec3d(origin.x, origin.y, origin.z));
    const openvdb::Vec3d d = openvdb::Vec3d(dir.x, dir.y, dir.z);  // unit in world = 1/voxel in index
    const openvdb::math::Ray<double> ray(a, d, 0.0, tMax / m.voxel);
    if (!m.inter.setIndexRay(ray)) return;
    double t0 = 0, t1 = 0;
    while (m.inter.march(t0, t1)) {
        t0 = std::max(t0, 0.0);
        if (t1 > t0) out.emplace_back(t0 * m.voxel, t1 * m.voxel);
    }
}

// --- ScatterCache ---------------------------------------------------------------------------------

namespace {
constexpr const char* kInscatter = "inscatter";
}

struct ScatterCache::Impl {
    openvdb::Vec3SGrid::Ptr grid;
};

ScatterCache::ScatterCache() : impl_(std::make_unique<Impl>()) { initOpenVdb(); }
ScatterCache::~ScatterCache() = default;
ScatterCache::ScatterCache(ScatterCache&&) noexcept = default;
ScatterCache& ScatterCache::operator=(ScatterCache&&) noexcept = default;

ScatterCache::ScatterCache(const DensityVolume& density, std::span<const double> values,
                           const ScatterCacheInfo& info)
    : ScatterCache() {
    const auto& d = density.impl();
    if (values.size() != 3 * d.positions.size())
        throw std::invalid_argument("ScatterCache: " + std::to_string(values.size()) + " values for " +
                                    std::to_string(d.positions.size()) + " voxels x 3 channels");
    // Same topology as the density (active voxels are the cache's points), values in point order:
    // the leaves of a topology copy are visited in the same order as the density's.
    auto tree =
        std::make_shared<openvdb::Vec3STree>(d.grid->tree(), openvdb::Vec3s(0.0f), openvdb::TopologyCopy());
    std::size_t i = 0;
    for (auto leaf = tree->beginLeaf(); leaf; ++leaf)
        for (auto v = leaf->beginValueOn(); v; ++v, ++i)
            v.setValue(openvdb::Vec3s(static_cast<float>(values[3 * i]),
                                      static_cast<float>(values[3 * i + 1]),
                                      static_cast<float>(values[3 * i + 2])));
    auto g = openvdb::Vec3SGrid::create(tree);
    g->setTransform(d.grid->transform().copy());
    g->setName(kInscatter);
    g->setGridClass(openvdb::GRID_UNKNOWN);
    g->setVectorType(openvdb::VEC_INVARIANT);
    g->insertMeta("frame", openvdb::Int32Metadata(info.frame));
    g->insertMeta("light_position", openvdb::Vec3DMetadata(openvdb::Vec3d(
                                        info.lightPosition.x, info.lightPosition.y, info.lightPosition.z)));
    g->insertMeta("light_kelvin", openvdb::DoubleMetadata(info.lightKelvin));
    g->insertMeta("cache_state", openvdb::StringMetadata(info.state));
    g->insertMeta("sigma_t_per_density", openvdb::DoubleMetadata(info.sigmaT));
    g->insertMeta("albedo",
                  openvdb::Vec3DMetadata(openvdb::Vec3d(info.albedo[0], info.albedo[1], info.albedo[2])));
    g->insertMeta("density_grid", openvdb::StringMetadata(d.grid->getName()));
    g->insertMeta(
        "quantity",
        openvdb::StringMetadata(
            "in-scattered radiance RGB, isotropic phase; emission = density * sigma_t * albedo * inscatter"));
    impl_->grid = g;
}

void ScatterCache::writeTo(const std::string& path) const {
    try {
        openvdb::io::File file(path);
        file.setCompression(openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK);
        openvdb::MetaMap meta;
        meta.insertMeta("creator", openvdb::StringMetadata("pmsc volume lighting cache"));
        file.write({impl_->grid}, meta);
        file.close();
    } catch (const std::exception& e) {
        throw IoError("cannot write " + path + ": " + e.what());
    }
}

void ScatterCache::write(const std::string& path) const {
    AtomicFile file(path);
    writeTo(file.temporaryPath());
    file.commit();
}

ScatterCache ScatterCache::read(const std::string& path) {
    ScatterCache out;
    try {
        openvdb::io::File file(path);
        file.open();
        if (!file.hasGrid(kInscatter)) throw InputError(path + ": no grid named 'inscatter'");
        out.impl_->grid = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid(kInscatter));
        file.close();
        if (!out.impl_->grid) throw InputError(path + ": grid 'inscatter' is not a Vec3SGrid");
    } catch (const InputError&) {
        throw;
    } catch (const std::exception& e) {
        throw InputError(path + ": not a readable volume lighting cache: " + e.what());
    }
    return out;
}

std::int64_t ScatterCache::activeVoxelCount() const {
    return static_cast<std::int64_t>(impl_->grid->activeVoxelCount());
}
std::uint64_t ScatterCache::memoryBytes() const { return impl_->grid->memUsage(); }

ScatterCacheInfo ScatterCache::info() const {
    const auto& g = *impl_->grid;
    ScatterCacheInfo i;
    try {
        i.frame = g.metaValue<openvdb::Int32>("frame");
        const auto lp = g.metaValue<openvdb::Vec3d>("light_position");
        i.lightPosition = {lp.x(), lp.y(), lp.z()};
        i.lightKelvin = g.metaValue<double>("light_kelvin");
        i.state = g.metaValue<std::string>("cache_state");
        i.sigmaT = g.metaValue<double>("sigma_t_per_density");
        const auto a = g.metaValue<openvdb::Vec3d>("albedo");
        i.albedo = {a.x(), a.y(), a.z()};
    } catch (const std::exception& e) {
        throw InputError(std::string("volume lighting cache: metadata missing or of the wrong type: ") +
                         e.what());
    }
    return i;
}

struct ScatterCache::Sampler::Impl {
    explicit Impl(const openvdb::Vec3SGrid& g) : grid(g), acc(g.tree()) {}
    const openvdb::Vec3SGrid& grid;
    openvdb::tree::ValueAccessor<const openvdb::Vec3STree, false> acc;
};

ScatterCache::Sampler::Sampler(const ScatterCache& cache)
    : impl_(std::make_unique<Impl>(*cache.impl_->grid)) {}
ScatterCache::Sampler::~Sampler() = default;

Rgb ScatterCache::Sampler::at(Vec3 p) {
    auto& m = *impl_;
    const openvdb::Vec3d x = m.grid.worldToIndex(openvdb::Vec3d(p.x, p.y, p.z));
    const openvdb::Coord base(static_cast<int>(std::floor(x.x())), static_cast<int>(std::floor(x.y())),
                              static_cast<int>(std::floor(x.z())));
    const double fx = x.x() - base.x(), fy = x.y() - base.y(), fz = x.z() - base.z();
    double sum[3] = {0, 0, 0}, wsum = 0;
    for (int c = 0; c < 8; ++c) {
        openvdb::Vec3s v;
        if (!m.acc.probeValue(base.offsetBy(c & 1, (c >> 1) & 1, (c >> 2) & 1), v)) continue;
        const double w =
            ((c & 1) ? fx : 1 - fx) * (((c >> 1) & 1) ? fy : 1 - fy) * (((c >> 2) & 1) ? fz : 1 - fz);
        sum[0] += w * v.x();
        sum[1] += w * v.y();
        sum[2] += w * v.z();
        wsum += w;
    }
    if (wsum <= 1e-9) return {0, 0, 0};
    return {sum[0] / wsum, sum[1] / wsum, sum[2] / wsum};
}

}  // namespace pmsc::volume
