// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

// Wavefront .obj: the one reader and the one writer of the project. The face rig reads
// the ICT meshes with it, the synthetic ICT frames read their blendshapes with it, and every
// evaluator that poses a mesh (face, skin) writes `pmsc run --format obj` frames with it, so an
// .obj output has the same format, and holds the same values, whichever evaluator made it.

#include "pmsc/FrameSet.h"  // Index
#include "pmsc/FrameWriter.h"

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace pmsc {

/// The parts of a Wavefront OBJ file pmsc needs: vertex positions and polygons.
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

/// A mesh of triangles (3 point indices each, 0-based) and no positions: the topology a
/// triangle-soup evaluator (skin) hands to ObjFrameWriter.
/// @throws std::invalid_argument for a count that is not a multiple of 3 or an index outside int32.
ObjMesh triangleMesh(std::span<const std::int64_t> triangles);

/// OBJ text of a posed mesh: an optional "# comment" line, a "v x y z" line per vertex of
/// `positions` (3 per vertex, the mesh's vertex order) and the mesh's polygons as 1-based "f"
/// lines. Decision: every coordinate is the shortest decimal that reads back to the same double
/// (std::to_chars), so a file holds the evaluator's values exactly and readObj() returns them bit
/// for bit; the face demo's former "%.6g" lost everything below a micro-unit and made
/// `--format obj` lossy for one evaluator and exact for the other. Identical values give
/// identical bytes, which lets a farm compare the outputs of two runs.
std::string formatObj(const ObjMesh& topology, std::span<const double> positions,
                      const std::string& comment = "");

/// Writes formatObj() to `path` atomically (temporary file + fsync + rename).
/// @throws IoError naming the path.
void writeObj(const std::string& path, const ObjMesh& topology, std::span<const double> positions,
              const std::string& comment = "");

/// `pmsc run --format obj`: one posed frame per file, "# pmsc frame F: N points, P polygons"
/// then formatObj()'s lines. Thread safety: const; the topology is shared and immutable.
class ObjFrameWriter final : public FrameWriter {
public:
    /// @param points   N, vertices per frame (values carry 3 channels each).
    /// @param topology the polygons (its positions, if any, are not used).
    ObjFrameWriter(Index points, std::shared_ptr<const ObjMesh> topology);

    std::string extension() const override { return ".obj"; }
    /// `values`: 3 per vertex of the topology. @throws IoError naming the path.
    void write(const std::string& path, Index frame, const double* values) const override;
    /// readObj() parses the whole file (finite coordinates, face indices in range), it has N
    /// vertices and exactly the topology's polygons.
    bool isValid(const std::string& path) const override;

private:
    Index points_;
    std::shared_ptr<const ObjMesh> topology_;
};

}  // namespace pmsc
