// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "pmsc/ObjIO.h"

#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace pmsc {
namespace {

std::string readWholeFile(const std::string& path) {
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path.c_str(), "rb"), &std::fclose);
    if (!file) throw InputError(path + ": cannot open: " + std::strerror(errno));
    std::string bytes;
    char buffer[1 << 16];
    for (;;) {
        const size_t n = std::fread(buffer, 1, sizeof buffer, file.get());
        bytes.append(buffer, n);
        if (n < sizeof buffer) break;
    }
    if (std::ferror(file.get())) throw InputError(path + ": read error");
    return bytes;
}

[[noreturn]] void malformed(const std::string& path, Index line, const char* what) {
    throw InputError(path + ":" + std::to_string(line) + ": " + what);
}

const char* skipBlanks(const char* p, const char* end) {
    while (p < end && (*p == ' ' || *p == '\t')) ++p;
    return p;
}

void appendNumber(std::string& text, double value) {
    char buf[32];
    const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, value);
    text.append(buf, end);
}

}  // namespace

ObjMesh readObj(const std::string& path, ObjContent content, Index* polygonLines) {
    const std::string bytes = readWholeFile(path);
    ObjMesh mesh;
    mesh.positions.reserve(bytes.size() / 24);
    Index faces = 0;
    Index lineNumber = 0;
    const char* p = bytes.data();
    const char* const end = p + bytes.size();
    while (p < end) {
        ++lineNumber;
        const char* eol = static_cast<const char*>(std::memchr(p, '\n', static_cast<size_t>(end - p)));
        if (!eol) eol = end;
        const char* lineEnd = (eol > p && eol[-1] == '\r') ? eol - 1 : eol;
        if (lineEnd - p >= 2 && p[0] == 'v' && (p[1] == ' ' || p[1] == '\t')) {
            const char* q = p + 2;
            for (int c = 0; c < 3; ++c) {
                q = skipBlanks(q, lineEnd);
                double value = 0;
                const auto [next, ec] = std::from_chars(q, lineEnd, value);
                if (ec != std::errc{})
                    malformed(path, lineNumber, "malformed vertex line (expected 'v x y z')");
                if (!std::isfinite(value)) malformed(path, lineNumber, "non-finite vertex coordinate");
                mesh.positions.push_back(value);
                q = next;
            }
        } else if (lineEnd - p >= 2 && p[0] == 'f' && (p[1] == ' ' || p[1] == '\t')) {
            ++faces;
            if (content == ObjContent::PositionsAndPolygons) {
                const char* q = p + 2;
                int corners = 0;
                for (;;) {
                    q = skipBlanks(q, lineEnd);
                    if (q >= lineEnd) break;
                    long index = 0;
                    const auto [next, ec] = std::from_chars(q, lineEnd, index);
                    if (ec != std::errc{}) malformed(path, lineNumber, "malformed face line");
                    // OBJ indices are 1-based; negative ones count back from the last vertex read.
                    const long vertex = index > 0 ? index - 1 : static_cast<long>(mesh.vertexCount()) + index;
                    if (vertex < 0 || vertex >= static_cast<long>(mesh.vertexCount()) || index == 0)
                        malformed(path, lineNumber, "face refers to a vertex that does not exist");
                    mesh.polygonVertices.push_back(static_cast<std::int32_t>(vertex));
                    ++corners;
                    q = next;
                    while (q < lineEnd && *q != ' ' && *q != '\t') ++q;  // skip "/vt/vn"
                }
                if (corners < 3) malformed(path, lineNumber, "face with fewer than 3 corners");
                mesh.polygonStart.push_back(static_cast<std::int32_t>(mesh.polygonVertices.size()));
            }
        }
        p = eol + 1;
    }
    if (polygonLines) *polygonLines = faces;
    return mesh;
}

ObjMesh triangleMesh(std::span<const std::int64_t> triangles) {
    if (triangles.size() % 3 != 0)
        throw std::invalid_argument("triangleMesh: " + std::to_string(triangles.size()) +
                                    " indices, not a multiple of 3");
    ObjMesh mesh;
    mesh.polygonVertices.reserve(triangles.size());
    mesh.polygonStart.reserve(triangles.size() / 3 + 1);
    for (std::size_t i = 0; i < triangles.size(); ++i) {
        if (triangles[i] < 0 || triangles[i] > std::numeric_limits<std::int32_t>::max())
            throw std::invalid_argument("triangleMesh: index " + std::to_string(triangles[i]) +
                                        " outside int32");
        mesh.polygonVertices.push_back(static_cast<std::int32_t>(triangles[i]));
        if (i % 3 == 2) mesh.polygonStart.push_back(static_cast<std::int32_t>(i + 1));
    }
    return mesh;
}

std::string formatObj(const ObjMesh& topology, std::span<const double> positions,
                      const std::string& comment) {
    std::string text;
    text.reserve(positions.size() * 20 + topology.polygonVertices.size() * 8 + comment.size() + 4);
    if (!comment.empty()) text += "# " + comment + "\n";
    for (size_t i = 0; i + 2 < positions.size(); i += 3) {
        text += 'v';
        for (int c = 0; c < 3; ++c) {
            text += ' ';
            appendNumber(text, positions[i + static_cast<size_t>(c)]);
        }
        text += '\n';
    }
    for (Index f = 0; f < topology.polygonCount(); ++f) {
        text += 'f';
        for (std::int32_t i = topology.polygonStart[static_cast<size_t>(f)];
             i < topology.polygonStart[static_cast<size_t>(f) + 1]; ++i) {
            text += ' ';
            text += std::to_string(topology.polygonVertices[static_cast<size_t>(i)] + 1);
        }
        text += '\n';
    }
    return text;
}

void writeObj(const std::string& path, const ObjMesh& topology, std::span<const double> positions,
              const std::string& comment) {
    writeFileAtomically(path, formatObj(topology, positions, comment));
}

ObjFrameWriter::ObjFrameWriter(Index points, std::shared_ptr<const ObjMesh> topology)
    : points_(points), topology_(std::move(topology)) {
    if (!topology_ || points_ <= 0) throw std::invalid_argument("ObjFrameWriter: no topology or no points");
}

void ObjFrameWriter::write(const std::string& path, Index frame, const double* values) const {
    const std::string text =
        formatObj(*topology_, {values, static_cast<size_t>(3 * points_)},
                  "pmsc frame " + std::to_string(frame) + ": " + std::to_string(points_) + " points, " +
                      std::to_string(topology_->polygonCount()) + " polygons");
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path.c_str(), "wb"), &std::fclose);
    if (!file) throw IoError(path + ": cannot create: " + std::strerror(errno));
    if (std::fwrite(text.data(), 1, text.size(), file.get()) != text.size() || std::fflush(file.get()) != 0)
        throw IoError(path + ": cannot write: " + std::strerror(errno));
}

bool ObjFrameWriter::isValid(const std::string& path) const {
    try {
        const ObjMesh mesh = readObj(path, ObjContent::PositionsAndPolygons);
        return mesh.vertexCount() == points_ && mesh.polygonStart == topology_->polygonStart &&
               mesh.polygonVertices == topology_->polygonVertices;
    } catch (const InputError&) {
        return false;
    }
}

}  // namespace pmsc
