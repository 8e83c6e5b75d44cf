#include "examples/face/ObjWriter.h"

#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

namespace pmsc::face {

std::string formatObj(const ObjMesh& topology, std::span<const double> positions,
                      const std::string& comment) {
    std::string text;
    text.reserve(static_cast<size_t>(topology.vertexCount()) * 40 + topology.polygonVertices.size() * 8);
    if (!comment.empty()) text += "# " + comment + "\n";
    char line[128];
    for (size_t i = 0; i + 2 < positions.size(); i += 3) {
        const int len = std::snprintf(line, sizeof line, "v %.6g %.6g %.6g\n", positions[i], positions[i + 1],
                                      positions[i + 2]);
        text.append(line, static_cast<size_t>(len));
    }
    for (Index f = 0; f < topology.polygonCount(); ++f) {
        text += 'f';
        for (std::int32_t i = topology.polygonStart[f]; i < topology.polygonStart[f + 1]; ++i) {
            const int len = std::snprintf(line, sizeof line, " %d", topology.polygonVertices[i] + 1);
            text.append(line, static_cast<size_t>(len));
        }
        text += '\n';
    }
    return text;
}

void writeObj(const std::string& path, const ObjMesh& topology, std::span<const double> positions,
              const std::string& comment) {
    writeFileAtomically(path, formatObj(topology, positions, comment));
}

void ObjFrameWriter::write(const std::string& path, Index frame, const double* values) const {
    const std::string text =
        formatObj(*topology_, {values, static_cast<size_t>(3 * topology_->vertexCount())},
                  "pmsc face frame " + std::to_string(frame));
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path.c_str(), "wb"), &std::fclose);
    if (!file) throw IoError(path + ": cannot create: " + std::strerror(errno));
    if (std::fwrite(text.data(), 1, text.size(), file.get()) != text.size() || std::fflush(file.get()) != 0) {
        throw IoError(path + ": write failed: " + std::strerror(errno));
    }
}

bool ObjFrameWriter::isValid(const std::string& path) const {
    try {
        Index faces = 0;
        const ObjMesh mesh = readObj(path, ObjContent::Positions, &faces);
        return mesh.vertexCount() == topology_->vertexCount() && faces == topology_->polygonCount();
    } catch (...) {
        return false;
    }
}

}  // namespace pmsc::face
