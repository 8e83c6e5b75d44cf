// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/ObjReader.h"
#include "pmsc/FrameSet.h"

#include <array>
#include <string>
#include <string_view>
#include <vector>

namespace pmsc::face {

/// A named range of vertices of the ICT face, [first, last] inclusive as in the upstream table.
struct VertexRegion {
    std::string_view name;
    Index first;
    Index last;
    bool contains(Index v) const { return v >= first && v <= last; }
    Index size() const { return last - first + 1; }
};

/// The ICT-FaceKit face model (FaceXModel folder): the neutral mesh, its 57 expression shapes as
/// deltas (expression - neutral, same vertex order), the polygons, and the facts of the upstream
/// README a rig and a key-point selector use (vertex regions, Multi-PIE 68 landmarks).
struct IctFace {
    /// Names of the 57 expression OBJ files (without ".obj"), in the order of `deltas`.
    static const std::vector<std::string>& expressionNames();
    /// Upstream README vertex regions (face, head and neck, mouth socket, eye sockets, gums and
    /// tongue, teeth, eyeballs, ...), for the 26,719-vertex topology.
    static const std::vector<VertexRegion>& regions();
    /// One region by name ("face", "eyeball_left", "teeth_lower", ...). @throws std::out_of_range.
    static const VertexRegion& region(std::string_view name);
    /// Multi-PIE 68 point landmark vertex indices (upstream README, 0-based): the designer's
    /// fiducial key points (paper section 4).
    static const std::array<Index, 68>& multiPie68();
    /// Vertex count of the ICT topology.
    static constexpr Index kVertexCount = 26719;

    std::string folder;
    ObjMesh neutral;                 ///< positions and polygons of generic_neutral_mesh.obj
    std::vector<std::string> names;  ///< == expressionNames()
    /// deltas[s][3*v + c]: channel c of vertex v of expression s minus the neutral.
    std::vector<std::vector<double>> deltas;

    Index vertexCount() const { return neutral.vertexCount(); }
    /// Index of an expression by name. @throws std::out_of_range naming it.
    Index expression(std::string_view name) const;
    /// Diagonal of the neutral mesh's axis-aligned bounding box (the paper's error unit, section 7).
    double boundingBoxDiagonal() const;
};

/// Loads the ICT face from a folder holding generic_neutral_mesh.obj and the 57 expression OBJs.
/// Files are parsed in parallel (oneTBB).
/// @throws InputError naming the file: a missing or unreadable file, a malformed line, a vertex
///         or polygon count that differs from the neutral mesh's, or a neutral mesh that is not
///         the 26,719-vertex ICT topology.
IctFace loadIctFace(const std::string& folder);

}  // namespace pmsc::face
