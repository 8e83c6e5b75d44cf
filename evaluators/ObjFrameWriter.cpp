// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "evaluators/ObjFrameWriter.h"

#include "pmsc/Errors.h"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>

namespace pmsc::evaluators {

ObjFrameWriter::ObjFrameWriter(Index points, const std::vector<std::int64_t>* triangles)
    : points_(points), triangles_(triangles) {}

void ObjFrameWriter::write(const std::string& path, Index frame, const double* values) const {
    std::string text;
    text.reserve(static_cast<std::size_t>(points_) * 40 + triangles_->size() * 10 + 64);
    text += "# pmsc frame " + std::to_string(frame) + ": " + std::to_string(points_) + " points, " +
            std::to_string(triangles_->size() / 3) + " triangles\n";
    char buf[64];
    for (Index p = 0; p < points_; ++p) {
        text += 'v';
        for (int c = 0; c < 3; ++c) {
            text += ' ';
            auto [end, ec] = std::to_chars(buf, buf + sizeof buf, values[3 * p + c]);
            text.append(buf, end);
        }
        text += '\n';
    }
    for (std::size_t t = 0; t + 2 < triangles_->size(); t += 3) {
        text += 'f';
        for (int k = 0; k < 3; ++k) {
            text += ' ';
            text += std::to_string((*triangles_)[t + static_cast<std::size_t>(k)] + 1);
        }
        text += '\n';
    }

    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) throw IoError(path + ": cannot create: " + std::strerror(errno));
    const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
    const int writeErrno = errno;
    if (std::fclose(f) != 0 || !ok)
        throw IoError(path + ": cannot write: " + std::strerror(ok ? errno : writeErrno));
}

bool ObjFrameWriter::isValid(const std::string& path) const {
    std::ifstream in(path, std::ios::binary);
    if (!in) return false;
    Index vertices = 0;
    std::size_t faces = 0;
    std::string line;
    while (std::getline(in, line)) {
        if (line.empty() || line[0] == '#') continue;
        const char* p = line.data();
        const char* end = p + line.size();
        if (line.size() > 2 && line[0] == 'v' && line[1] == ' ') {
            p += 2;
            for (int c = 0; c < 3; ++c) {
                while (p < end && *p == ' ') ++p;
                double x;
                auto [q, ec] = std::from_chars(p, end, x);
                if (ec != std::errc() || !std::isfinite(x)) return false;
                p = q;
            }
            if (p != end) return false;
            ++vertices;
        } else if (line.size() > 2 && line[0] == 'f' && line[1] == ' ') {
            p += 2;
            for (int k = 0; k < 3; ++k) {
                while (p < end && *p == ' ') ++p;
                long long i;
                auto [q, ec] = std::from_chars(p, end, i);
                if (ec != std::errc() || i < 1 || i > points_) return false;
                p = q;
            }
            if (p != end) return false;
            ++faces;
        } else {
            return false;
        }
    }
    return !in.bad() && vertices == points_ && faces * 3 == triangles_->size();
}

}  // namespace pmsc::evaluators
