// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <cstdint>
#include <string>
#include <vector>

namespace pmsc::face {

/// The parts of a Wavefront OBJ file a face rig needs: vertex positions and polygons.
///
/// Polygons are kept as written (the ICT face is mostly quads), in a compressed layout:
/// polygon f has the vertex indices polygonVertices[polygonStart[f] .. polygonStart[f+1]),
/// 0-based. Texture and normal indices are skipped.
struct ObjMesh {
    std::vector<double> positions;  ///< 3 per vertex, x y z
    std::vector<std::int32_t> polygonStart{0};
    std::vector<std::int32_t> polygonVertices;

    Index vertexCount() const { return static_cast<Index>(positions.size() / 3); }
    Index polygonCount() const { return static_cast<Index>(polygonStart.size()) - 1; }
};

/// What to read from a file.
enum class ObjContent : int {
    Positions = 0,             ///< "v" lines only; polygon lines are counted, not parsed
    PositionsAndPolygons = 1,  ///< "v" and "f" lines
};

/// Reads an OBJ file. Fast path for large meshes: the file is read in one go and parsed with
/// std::from_chars (about 100 MB/s per core), because a face rig loads 58 files of 26,719
/// vertices at start-up.
/// @param[out] polygonLines number of "f" lines seen (also with ObjContent::Positions), so a
///             caller can check that two files share a topology without parsing the faces.
/// @throws InputError naming `path` and the line for a missing/unreadable file, a malformed
///         "v" or "f" line, a non-finite coordinate, or a face index outside the vertices.
ObjMesh readObj(const std::string& path, ObjContent content, Index* polygonLines = nullptr);

}  // namespace pmsc::face
