// The demo's medium: a mesh (Assimp) turned into smoke with OpenVDB's own tools. The second and
// last translation unit of examples/volume that includes OpenVDB (MeshToVolume is the heaviest).
#include "evaluators/scene/Sampling.h"
#include "evaluators/volume/DensityVolumeImpl.h"
#include "pmsc/Errors.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <openvdb/tools/LevelSetUtil.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/Prune.h>
#include <assimp/Importer.hpp>

#include <cmath>
#include <filesystem>

namespace pmsc::volume {

namespace {

/// Lattice value in [-1, 1] (integer hash of the cell and the seed).
double lattice(std::int64_t x, std::int64_t y, std::int64_t z, std::uint32_t seed) {
    using scene::hash32;
    const std::uint32_t h =
        hash32(static_cast<std::uint32_t>(x) ^
               hash32(static_cast<std::uint32_t>(y) ^ hash32(static_cast<std::uint32_t>(z) ^ seed)));
    return h * (2.0 / 4294967296.0) - 1.0;
}

/// Value noise: the lattice values interpolated with a quintic fade, in [-1, 1].
double valueNoise(double x, double y, double z, std::uint32_t seed) {
    const double fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
    const auto ix = static_cast<std::int64_t>(fx), iy = static_cast<std::int64_t>(fy),
               iz = static_cast<std::int64_t>(fz);
    auto fade = [](double t) { return t * t * t * (t * (t * 6 - 15) + 10); };
    const double u = fade(x - fx), v = fade(y - fy), w = fade(z - fz);
    double r = 0;
    for (int c = 0; c < 8; ++c) {
        const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
        r +=
            (dx ? u : 1 - u) * (dy ? v : 1 - v) * (dz ? w : 1 - w) * lattice(ix + dx, iy + dy, iz + dz, seed);
    }
    return r;
}

/// Three octaves of value noise (lacunarity 2, gain 0.5), normalized to about [-1, 1].
double fractalNoise(double x, double y, double z, std::uint32_t seed) {
    double sum = 0, amp = 1, norm = 0;
    for (int o = 0; o < 3; ++o) {
        sum += amp * valueNoise(x, y, z, seed + 977u * static_cast<std::uint32_t>(o));
        norm += amp;
        amp *= 0.5;
        x *= 2.03;
        y *= 2.03;
        z *= 2.03;
    }
    return sum / norm * 1.6;  // the sum of octaves rarely reaches its bound; stretch to use the range
}

struct Mesh {
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> triangles;
};

Mesh readMesh(const std::string& path, double sizeMetres) {
    const std::string where = "volume: " + path;
    if (!std::filesystem::is_regular_file(path)) throw InputError(where + ": no such file");
    Assimp::Importer importer;
    const aiScene* scene = importer.ReadFile(
        path, aiProcess_Triangulate | aiProcess_PreTransformVertices | aiProcess_JoinIdenticalVertices);
    if (!scene || !scene->mRootNode)
        throw InputError(where + ": Assimp cannot read it: " + importer.GetErrorString());
    Mesh m;
    for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
        const aiMesh* mesh = scene->mMeshes[i];
        const auto base = static_cast<unsigned>(m.points.size());
        for (unsigned v = 0; v < mesh->mNumVertices; ++v)
            m.points.emplace_back(mesh->mVertices[v].x, mesh->mVertices[v].y, mesh->mVertices[v].z);
        for (unsigned f = 0; f < mesh->mNumFaces; ++f)
            if (mesh->mFaces[f].mNumIndices == 3)
                m.triangles.emplace_back(base + mesh->mFaces[f].mIndices[0],
                                         base + mesh->mFaces[f].mIndices[1],
                                         base + mesh->mFaces[f].mIndices[2]);
    }
    if (m.triangles.empty()) throw InputError(where + ": has no triangles");
    // Centre on the origin, longest side sizeMetres.
    openvdb::Vec3s lo(1e30f), hi(-1e30f);
    for (const auto& p : m.points) {
        lo = openvdb::math::minComponent(lo, p);
        hi = openvdb::math::maxComponent(hi, p);
    }
    const openvdb::Vec3s centre = 0.5f * (lo + hi);
    const float longest = std::max({hi.x() - lo.x(), hi.y() - lo.y(), hi.z() - lo.z()});
    if (!(longest > 0)) throw InputError(where + ": the mesh has no extent");
    const float s = static_cast<float>(sizeMetres) / longest;
    for (auto& p : m.points) p = (p - centre) * s;
    return m;
}

/// Fog volume (before noise) at a voxel size; its active voxel count.
openvdb::FloatGrid::Ptr fog(const Mesh& mesh, double voxelSize) {
    const auto xf = openvdb::math::Transform::createLinearTransform(voxelSize);
    // A half width of 4 voxels: the fog's ramp from the surface inwards is 4 voxels wide, a soft edge.
    auto grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xf, mesh.points, mesh.triangles, 4.0f);
    openvdb::tools::sdfToFogVolume(*grid);
    grid->tree().voxelizeActiveTiles();
    return grid;
}

}  // namespace

DensityVolume DensityVolume::fromMesh(const std::string& meshPath, const FogOptions& o) {
    initOpenVdb();
    if (o.targetVoxels < 1000) throw InputError("volume: at least 1000 voxels are needed");
    if (!(o.densityScale > 0) || !(o.noiseFloor >= 0 && o.noiseFloor <= 1) || !(o.noiseExponent > 0))
        throw InputError(
            "volume: the fog's density scale must be > 0, its noise floor in [0, 1] and its "
            "exponent > 0");
    const Mesh mesh = readMesh(meshPath, o.sizeMetres);
    // The voxel size for the target count: active voxels scale as voxelSize^-3; two corrections
    // from a coarse first guess land within a few percent.
    double voxel = o.sizeMetres / 48.0;
    openvdb::FloatGrid::Ptr grid;
    for (int it = 0; it < 3; ++it) {
        grid = fog(mesh, voxel);
        const double count = static_cast<double>(grid->activeVoxelCount());
        if (count <= 0) throw InputError("volume: " + meshPath + ": the mesh encloses no volume");
        const double ratio = count / static_cast<double>(o.targetVoxels);
        if (std::abs(ratio - 1) < 0.03) break;
        if (it < 2) voxel *= std::cbrt(ratio);
    }
    // Noise: density = scale x fog x (floor + (1 - floor) n^exponent), n in [0, 1] from fractal
    // noise in world space, so the inside is lumpy like smoke; voxels whose density is zero (the
    // fog's surface value, or the noise's troughs with floor 0) go inactive.
    const double f = o.noiseFrequency;
    for (auto leaf = grid->tree().beginLeaf(); leaf; ++leaf) {
        for (auto v = leaf->beginValueOn(); v; ++v) {
            const openvdb::Vec3d w = grid->indexToWorld(v.getCoord());
            const double n =
                std::clamp(0.5 + 0.5 * fractalNoise(w.x() * f, w.y() * f, w.z() * f, o.noiseSeed), 0.0, 1.0);
            const float d = static_cast<float>(
                o.densityScale * *v * (o.noiseFloor + (1 - o.noiseFloor) * std::pow(n, o.noiseExponent)));
            if (d <= 1e-4f) {
                v.setValue(0.0f);
                v.setValueOff();
            } else {
                v.setValue(d);
            }
        }
    }
    openvdb::tools::pruneInactive(grid->tree());
    grid->setName("density");
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    auto impl = std::make_shared<DensityVolume::Impl>();
    impl->grid = grid;
    impl->index("volume: " + meshPath);
    return makeDensityVolume(std::move(impl));
}

}  // namespace pmsc::volume
