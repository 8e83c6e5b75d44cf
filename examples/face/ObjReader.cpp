#include "examples/face/ObjReader.h"

#include "pmsc/Errors.h"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>

namespace pmsc::face {
namespace {

std::string readWholeFile(const std::string& path) {
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path.c_str(), "rb"), &std::fclose);
    if (!file) {
        throw InputError(path + ": cannot open: " + std::strerror(errno));
    }
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
                    if (vertex < 0 || vertex >= static_cast<long>(mesh.vertexCount()) || index == 0) {
                        malformed(path, lineNumber, "face refers to a vertex that does not exist");
                    }
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

}  // namespace pmsc::face
