// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "examples/face/ObjReader.h"
#include "pmsc/FrameWriter.h"

#include <memory>
#include <span>
#include <string>

namespace pmsc::face {

/// Writes a posed mesh as Wavefront OBJ text: "v" lines from `positions` (3 per vertex, the
/// mesh's vertex order) and the mesh's polygons. %.6g keeps a micro-unit at head scale.
std::string formatObj(const ObjMesh& topology, std::span<const double> positions,
                      const std::string& comment = "");

/// Writes an OBJ file atomically (temporary file + rename). @throws IoError naming the path.
void writeObj(const std::string& path, const ObjMesh& topology, std::span<const double> positions,
              const std::string& comment = "");

/// FrameWriter for posed face meshes (".obj"), for `pmsc run --format obj`.
class ObjFrameWriter : public FrameWriter {
public:
    explicit ObjFrameWriter(std::shared_ptr<const ObjMesh> topology) : topology_(std::move(topology)) {}
    std::string extension() const override { return ".obj"; }
    void write(const std::string& path, Index frame, const double* values) const override;
    bool isValid(const std::string& path) const override;

private:
    std::shared_ptr<const ObjMesh> topology_;
};

}  // namespace pmsc::face
