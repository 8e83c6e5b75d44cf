// The one translation unit that includes OpenVDB (its headers are heavy; see STYLE.md).
#include "evaluators/cornell/LightingCacheGrid.h"

#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include <openvdb/openvdb.h>

#include <cmath>
#include <mutex>
#include <stdexcept>

namespace pmsc::cornell {

namespace {

void initOpenVdb() {
    static std::once_flag once;
    std::call_once(once, [] { openvdb::initialize(); });
}

constexpr const char* kIndirect = "indirect";
constexpr const char* kNormal = "normal";
constexpr const char* kSurfacePoint = "surface_point";

}  // namespace

struct LightingCacheGrid::Impl {
    openvdb::Vec3SGrid::Ptr indirect, normal, surfacePoint;
};

LightingCacheGrid::LightingCacheGrid() : impl_(std::make_unique<Impl>()) { initOpenVdb(); }
LightingCacheGrid::~LightingCacheGrid() = default;
LightingCacheGrid::LightingCacheGrid(LightingCacheGrid&&) noexcept = default;
LightingCacheGrid& LightingCacheGrid::operator=(LightingCacheGrid&&) noexcept = default;

LightingCacheGrid::LightingCacheGrid(const SurfaceVoxels& voxels, std::span<const double> values,
                                     const CacheMetadata& meta)
    : LightingCacheGrid() {
    if (values.size() != 3 * voxels.size())
        throw std::invalid_argument("LightingCacheGrid: " + std::to_string(values.size()) + " values for " +
                                    std::to_string(voxels.size()) + " voxels x 3 channels");
    const auto transform = openvdb::math::Transform::createLinearTransform(voxels.voxelSizeMm);
    auto make = [&](const char* name, openvdb::VecType type) {
        auto g = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
        g->setName(name);
        g->setTransform(transform->copy());
        g->setGridClass(openvdb::GRID_UNKNOWN);
        g->setVectorType(type);
        return g;
    };
    impl_->indirect = make(kIndirect, openvdb::VEC_INVARIANT);
    impl_->normal = make(kNormal, openvdb::VEC_COVARIANT_NORMALIZE);
    impl_->surfacePoint = make(kSurfacePoint, openvdb::VEC_CONTRAVARIANT_ABSOLUTE);
    auto a = impl_->indirect->getAccessor();
    auto an = impl_->normal->getAccessor();
    auto ap = impl_->surfacePoint->getAccessor();
    for (size_t v = 0; v < voxels.size(); ++v) {
        const openvdb::Coord c(voxels.ijk[v][0], voxels.ijk[v][1], voxels.ijk[v][2]);
        a.setValue(c, openvdb::Vec3s(static_cast<float>(values[3 * v]), static_cast<float>(values[3 * v + 1]),
                                     static_cast<float>(values[3 * v + 2])));
        const Vec3 n = voxels.normal[v], p = voxels.position[v];
        an.setValue(
            c, openvdb::Vec3s(static_cast<float>(n.x), static_cast<float>(n.y), static_cast<float>(n.z)));
        ap.setValue(
            c, openvdb::Vec3s(static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(p.z)));
    }
    auto& g = *impl_->indirect;
    g.insertMeta("frame", openvdb::Int32Metadata(meta.frame));
    g.insertMeta("light_position_mm", openvdb::Vec3DMetadata(openvdb::Vec3d(
                                          meta.lightPosition.x, meta.lightPosition.y, meta.lightPosition.z)));
    g.insertMeta("cache_state", openvdb::StringMetadata(meta.state));
    g.insertMeta("full_weight", openvdb::DoubleMetadata(meta.weight));
    g.insertMeta("key_rms_error", openvdb::DoubleMetadata(meta.keyError));
    g.insertMeta("quantity", openvdb::StringMetadata("one-bounce indirect irradiance, RGB"));
    g.insertMeta("units", openvdb::StringMetadata("world: mm"));
}

void LightingCacheGrid::writeTo(const std::string& path) const {
    try {
        openvdb::GridPtrVec grids{impl_->indirect, impl_->normal, impl_->surfacePoint};
        openvdb::io::File file(path);
        file.setCompression(openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK);
        openvdb::MetaMap fileMeta;
        fileMeta.insertMeta("creator", openvdb::StringMetadata("pmsc demo cornell"));
        file.write(grids, fileMeta);
        file.close();
    } catch (const std::exception& e) {
        throw IoError("cannot write " + path + ": " + e.what());
    }
}

void LightingCacheGrid::write(const std::string& path) const {
    AtomicFile file(path);  // OpenVDB writes the temporary file by name; commit() syncs and renames it
    writeTo(file.temporaryPath());
    file.commit();
}

LightingCacheGrid LightingCacheGrid::read(const std::string& path) {
    LightingCacheGrid out;
    try {
        openvdb::io::File file(path);
        file.open();
        auto get = [&](const char* name) {
            if (!file.hasGrid(name)) throw InputError(path + ": no grid named '" + name + "'");
            auto g = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid(name));
            if (!g) throw InputError(path + ": grid '" + std::string(name) + "' is not a Vec3SGrid");
            return g;
        };
        out.impl_->indirect = get(kIndirect);
        out.impl_->normal = get(kNormal);
        out.impl_->surfacePoint = get(kSurfacePoint);
        file.close();
    } catch (const InputError&) {
        throw;
    } catch (const std::exception& e) {
        throw InputError(path + ": not a readable lighting cache: " + e.what());
    }
    if (out.impl_->normal->activeVoxelCount() != out.impl_->indirect->activeVoxelCount() ||
        out.impl_->surfacePoint->activeVoxelCount() != out.impl_->indirect->activeVoxelCount())
        throw InputError(path + ": companion grids do not match 'indirect'");
    return out;
}

CacheMetadata LightingCacheGrid::metadata() const {
    CacheMetadata m;
    const auto& g = *impl_->indirect;
    try {
        m.frame = g.metaValue<openvdb::Int32>("frame");
        const openvdb::Vec3d lp = g.metaValue<openvdb::Vec3d>("light_position_mm");
        m.lightPosition = {lp.x(), lp.y(), lp.z()};
        m.state = g.metaValue<std::string>("cache_state");
        m.weight = g.metaValue<double>("full_weight");
        m.keyError = g.metaValue<double>("key_rms_error");
    } catch (const std::exception& e) {
        throw InputError(std::string("lighting cache: metadata missing or of the wrong type: ") + e.what());
    }
    return m;
}

double LightingCacheGrid::voxelSizeMm() const { return impl_->indirect->voxelSize()[0]; }

std::int64_t LightingCacheGrid::activeVoxelCount() const {
    return static_cast<std::int64_t>(impl_->indirect->activeVoxelCount());
}

Rgb LightingCacheGrid::valueAt(const std::array<std::int32_t, 3>& ijk) const {
    const openvdb::Vec3s v = impl_->indirect->tree().getValue(openvdb::Coord(ijk[0], ijk[1], ijk[2]));
    return {v.x(), v.y(), v.z()};
}

void LightingCacheGrid::sample(std::span<const Vec3> p, std::span<const Vec3> n, double* out) const {
    auto a = impl_->indirect->getConstAccessor();
    auto an = impl_->normal->getConstAccessor();
    const auto& xf = impl_->indirect->transform();
    for (size_t i = 0; i < p.size(); ++i) {
        const openvdb::Vec3d x = xf.worldToIndex(openvdb::Vec3d(p[i].x, p[i].y, p[i].z));
        const openvdb::Coord base(static_cast<int>(std::floor(x.x())), static_cast<int>(std::floor(x.y())),
                                  static_cast<int>(std::floor(x.z())));
        const double fx = x.x() - base.x(), fy = x.y() - base.y(), fz = x.z() - base.z();
        const openvdb::Vec3s nn(static_cast<float>(n[i].x), static_cast<float>(n[i].y),
                                static_cast<float>(n[i].z));
        double sum[3] = {0, 0, 0}, wsum = 0;
        for (int c = 0; c < 8; ++c) {
            const openvdb::Coord q = base.offsetBy(c & 1, (c >> 1) & 1, (c >> 2) & 1);
            openvdb::Vec3s nv, v;
            if (!an.probeValue(q, nv) || nv.dot(nn) < 0.5f) continue;
            a.probeValue(q, v);
            const double w =
                ((c & 1) ? fx : 1 - fx) * (((c >> 1) & 1) ? fy : 1 - fy) * (((c >> 2) & 1) ? fz : 1 - fz);
            sum[0] += w * v.x();
            sum[1] += w * v.y();
            sum[2] += w * v.z();
            wsum += w;
        }
        if (wsum <= 1e-12) {
            // Nearest matching voxel within 2 voxels (thin features, stencils that only
            // touched the other side of a corner).
            const openvdb::Coord near(static_cast<int>(std::lround(x.x())),
                                      static_cast<int>(std::lround(x.y())),
                                      static_cast<int>(std::lround(x.z())));
            double best = 1e30;
            for (int dz = -2; dz <= 2; ++dz)
                for (int dy = -2; dy <= 2; ++dy)
                    for (int dx = -2; dx <= 2; ++dx) {
                        const openvdb::Coord q = near.offsetBy(dx, dy, dz);
                        openvdb::Vec3s nv, v;
                        if (!an.probeValue(q, nv) || nv.dot(nn) < 0.5f) continue;
                        const double d2 = (q.x() - x.x()) * (q.x() - x.x()) +
                                          (q.y() - x.y()) * (q.y() - x.y()) +
                                          (q.z() - x.z()) * (q.z() - x.z());
                        if (d2 < best) {
                            best = d2;
                            a.probeValue(q, v);
                            sum[0] = v.x();
                            sum[1] = v.y();
                            sum[2] = v.z();
                            wsum = 1;
                        }
                    }
        }
        for (int c = 0; c < 3; ++c) out[3 * i + c] = wsum > 0 ? sum[c] / wsum : 0.0;
    }
}

}  // namespace pmsc::cornell
