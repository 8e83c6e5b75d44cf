// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/ObjReader.h"

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace pmsc::face {

/// Connectivity of a polygon mesh: each vertex's neighbours along polygon edges (sorted, so a
/// sum over neighbours always runs in the same order: the rig's results must not depend on which
/// points are evaluated) and the polygons split into triangles (for contact and rendering).
class MeshTopology {
public:
    explicit MeshTopology(const ObjMesh& mesh);

    Index vertexCount() const { return static_cast<Index>(neighbourStart_.size()) - 1; }
    /// Neighbours of v, ascending.
    std::span<const std::int32_t> neighbours(Index v) const {
        return {neighbours_.data() + neighbourStart_[v],
                static_cast<size_t>(neighbourStart_[v + 1] - neighbourStart_[v])};
    }
    /// Polygons fanned into triangles, corners in the polygon's winding order.
    const std::vector<std::array<std::int32_t, 3>>& triangles() const { return triangles_; }
    /// Polygon each triangle came from.
    const std::vector<std::int32_t>& triangleToPolygon() const { return triangleToPolygon_; }

    /// Area-weighted vertex normals of `positions` (3 per vertex), unit length (zero for a vertex
    /// on no triangle).
    std::vector<double> vertexNormals(std::span<const double> positions) const;

    /// Vertices within `rings` edges of `seeds` (seeds included), ascending.
    std::vector<Index> ringClosure(std::span<const Index> seeds, int rings) const;

private:
    std::vector<std::int32_t> neighbourStart_;
    std::vector<std::int32_t> neighbours_;
    std::vector<std::array<std::int32_t, 3>> triangles_;
    std::vector<std::int32_t> triangleToPolygon_;
};

}  // namespace pmsc::face
