#include "evaluators/face/MeshTopology.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace pmsc::face {

MeshTopology::MeshTopology(const ObjMesh& mesh) {
    const Index n = mesh.vertexCount();
    std::vector<std::pair<std::int32_t, std::int32_t>> edges;
    edges.reserve(mesh.polygonVertices.size() * 2);
    for (Index f = 0; f < mesh.polygonCount(); ++f) {
        const std::int32_t begin = mesh.polygonStart[f];
        const std::int32_t end = mesh.polygonStart[f + 1];
        for (std::int32_t i = begin; i < end; ++i) {
            const std::int32_t a = mesh.polygonVertices[i];
            const std::int32_t b = mesh.polygonVertices[i + 1 < end ? i + 1 : begin];
            if (a == b) continue;
            edges.emplace_back(a, b);
            edges.emplace_back(b, a);
        }
        for (std::int32_t i = begin + 1; i + 1 < end; ++i) {
            triangles_.push_back(
                {mesh.polygonVertices[begin], mesh.polygonVertices[i], mesh.polygonVertices[i + 1]});
            triangleToPolygon_.push_back(static_cast<std::int32_t>(f));
        }
    }
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    neighbourStart_.assign(static_cast<size_t>(n) + 1, 0);
    for (const auto& e : edges) ++neighbourStart_[e.first + 1];
    for (Index v = 0; v < n; ++v) neighbourStart_[v + 1] += neighbourStart_[v];
    neighbours_.resize(edges.size());
    for (size_t i = 0; i < edges.size(); ++i) neighbours_[i] = edges[i].second;  // sorted by (a, b)
}

std::vector<double> MeshTopology::vertexNormals(std::span<const double> positions) const {
    std::vector<double> normals(positions.size(), 0.0);
    for (const auto& t : triangles_) {
        const double* a = &positions[3 * static_cast<std::size_t>(t[0])];
        const double* b = &positions[3 * static_cast<std::size_t>(t[1])];
        const double* c = &positions[3 * static_cast<std::size_t>(t[2])];
        const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const double cross[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                                 u[0] * w[1] - u[1] * w[0]};
        for (int k = 0; k < 3; ++k) {
            for (int c2 = 0; c2 < 3; ++c2) normals[3 * t[k] + c2] += cross[c2];
        }
    }
    for (size_t v = 0; v < normals.size(); v += 3) {
        const double len = std::sqrt(normals[v] * normals[v] + normals[v + 1] * normals[v + 1] +
                                     normals[v + 2] * normals[v + 2]);
        if (len > 0) {
            for (int c = 0; c < 3; ++c) normals[v + c] /= len;
        }
    }
    return normals;
}

std::vector<Index> MeshTopology::ringClosure(std::span<const Index> seeds, int rings) const {
    std::vector<char> in(static_cast<size_t>(vertexCount()), 0);
    std::vector<Index> frontier;
    for (Index s : seeds) {
        if (!in[s]) {
            in[s] = 1;
            frontier.push_back(s);
        }
    }
    for (int r = 0; r < rings; ++r) {
        std::vector<Index> next;
        for (Index v : frontier) {
            for (std::int32_t u : neighbours(v)) {
                if (!in[u]) {
                    in[u] = 1;
                    next.push_back(u);
                }
            }
        }
        frontier = std::move(next);
    }
    std::vector<Index> out;
    for (Index v = 0; v < vertexCount(); ++v) {
        if (in[v]) out.push_back(v);
    }
    return out;
}

}  // namespace pmsc::face
