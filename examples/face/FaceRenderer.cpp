#include "examples/face/FaceRenderer.h"

#include "evaluators/face/IctFace.h"
#include "evaluators/scene/Png.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

namespace pmsc::face {

RgbImage::RgbImage(int w, int h, std::array<std::uint8_t, 3> fill) : width(w), height(h) {
    pixels.resize(3 * static_cast<size_t>(w) * h);
    for (size_t i = 0; i < pixels.size(); i += 3) {
        pixels[i] = fill[0];
        pixels[i + 1] = fill[1];
        pixels[i + 2] = fill[2];
    }
}

void RgbImage::paste(const RgbImage& other, int x0, int y0) {
    for (int y = 0; y < other.height; ++y) {
        if (y + y0 < 0 || y + y0 >= height) continue;
        for (int x = 0; x < other.width; ++x) {
            if (x + x0 < 0 || x + x0 >= width) continue;
            const std::uint8_t* s = &other.pixels[3 * (static_cast<size_t>(y) * other.width + x)];
            std::uint8_t* d = at(x + x0, y + y0);
            d[0] = s[0];
            d[1] = s[1];
            d[2] = s[2];
        }
    }
}

std::vector<char> FaceRenderer::ictHiddenVertices(Index vertexCount) {
    std::vector<char> hidden(static_cast<size_t>(vertexCount), 0);
    for (const char* name : {"lacrimal_left", "lacrimal_right", "eye_blend_left", "eye_blend_right",
                             "eye_occlusion_left", "eye_occlusion_right"}) {
        const VertexRegion& r = IctFace::region(name);
        for (Index v = r.first; v <= r.last && v < vertexCount; ++v) hidden[v] = 1;
    }
    return hidden;
}

FaceRenderer::FaceRenderer(const MeshTopology& topology, std::vector<char> hidden)
    : topology_(topology), hidden_(std::move(hidden)) {}

namespace {

Eigen::Vector3d toView(const Eigen::Vector3d& p, const OrthoView& view, const Eigen::Matrix3d& turn) {
    const Eigen::Vector3d q = turn * (p - view.centre);
    return {view.width * 0.5 + view.pixelsPerUnit * q[0], view.height * 0.5 - view.pixelsPerUnit * q[1],
            q[2]};
}

Eigen::Matrix3d turnOf(const OrthoView& view) {
    const double a = view.yawDegrees * std::numbers::pi / 180.0;
    Eigen::Matrix3d r;
    r << std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a);
    return r;
}

}  // namespace

RgbImage FaceRenderer::render(std::span<const double> positions, std::span<const float> colours,
                              const OrthoView& view) const {
    RgbImage image(view.width, view.height, {38, 40, 46});
    depth_.assign(static_cast<size_t>(view.width) * view.height, -INFINITY);
    const Eigen::Matrix3d turn = turnOf(view);
    const Index n = topology_.vertexCount();
    std::vector<Eigen::Vector3d> screen(static_cast<size_t>(n));
    for (Index v = 0; v < n; ++v) screen[v] = toView(Eigen::Vector3d(&positions[3 * v]), view, turn);
    const std::vector<double> normals = topology_.vertexNormals(positions);
    const Eigen::Vector3d light = Eigen::Vector3d(-0.35, 0.45, 1.0).normalized();
    std::vector<float> shade(static_cast<size_t>(n));
    for (Index v = 0; v < n; ++v) {
        const Eigen::Vector3d nrm = turn * Eigen::Vector3d(&normals[3 * v]);
        shade[v] = static_cast<float>(0.25 + 0.75 * std::abs(nrm.dot(light)));  // two-sided: open meshes
    }
    for (const auto& tri : topology_.triangles()) {
        if (hidden_[tri[0]] || hidden_[tri[1]] || hidden_[tri[2]]) continue;
        const Eigen::Vector3d& a = screen[tri[0]];
        const Eigen::Vector3d& b = screen[tri[1]];
        const Eigen::Vector3d& c = screen[tri[2]];
        const double area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        if (std::abs(area) < 1e-12) continue;
        const int x0 = std::max(0, static_cast<int>(std::floor(std::min({a[0], b[0], c[0]}))));
        const int x1 = std::min(view.width - 1, static_cast<int>(std::ceil(std::max({a[0], b[0], c[0]}))));
        const int y0 = std::max(0, static_cast<int>(std::floor(std::min({a[1], b[1], c[1]}))));
        const int y1 = std::min(view.height - 1, static_cast<int>(std::ceil(std::max({a[1], b[1], c[1]}))));
        for (int y = y0; y <= y1; ++y) {
            for (int x = x0; x <= x1; ++x) {
                const double px = x + 0.5, py = y + 0.5;
                const double w0 = ((b[0] - px) * (c[1] - py) - (b[1] - py) * (c[0] - px)) / area;
                const double w1 = ((c[0] - px) * (a[1] - py) - (c[1] - py) * (a[0] - px)) / area;
                const double w2 = 1.0 - w0 - w1;
                if (w0 < 0 || w1 < 0 || w2 < 0) continue;
                const double z = w0 * a[2] + w1 * b[2] + w2 * c[2];
                float& depth = depth_[static_cast<size_t>(y) * view.width + x];
                if (z <= depth) continue;
                depth = static_cast<float>(z);
                const double s = w0 * shade[tri[0]] + w1 * shade[tri[1]] + w2 * shade[tri[2]];
                std::uint8_t* pixel = image.at(x, y);
                for (int ch = 0; ch < 3; ++ch) {
                    const double col = w0 * colours[3 * tri[0] + ch] + w1 * colours[3 * tri[1] + ch] +
                                       w2 * colours[3 * tri[2] + ch];
                    pixel[ch] = static_cast<std::uint8_t>(std::clamp(255.0 * s * col, 0.0, 255.0));
                }
            }
        }
    }
    return image;
}

void FaceRenderer::drawPoints(RgbImage& image, std::span<const double> positions,
                              std::span<const Index> points, const OrthoView& view,
                              std::array<std::uint8_t, 3> colour, int radius) const {
    const Eigen::Matrix3d turn = turnOf(view);
    for (Index p : points) {
        const Eigen::Vector3d s = toView(Eigen::Vector3d(&positions[3 * p]), view, turn);
        const int cx = static_cast<int>(s[0]), cy = static_cast<int>(s[1]);
        if (cx < 0 || cy < 0 || cx >= image.width || cy >= image.height) continue;
        // Visible if nothing in front by more than a small tolerance (the point is on the surface).
        if (s[2] < depth_[static_cast<size_t>(cy) * view.width + cx] - 0.05) continue;
        for (int dy = -radius; dy <= radius; ++dy) {
            for (int dx = -radius; dx <= radius; ++dx) {
                if (dx * dx + dy * dy > radius * radius) continue;
                const int x = cx + dx, y = cy + dy;
                if (x < 0 || y < 0 || x >= image.width || y >= image.height) continue;
                std::uint8_t* pixel = image.at(x, y);
                pixel[0] = colour[0];
                pixel[1] = colour[1];
                pixel[2] = colour[2];
            }
        }
    }
}

std::array<float, 3> errorColour(double error, double full) {
    const double t = std::clamp(error / full, 0.0, 1.0);
    const std::array<float, 3> grey = {0.80f, 0.80f, 0.80f}, yellow = {1.0f, 0.85f, 0.1f},
                               red = {0.95f, 0.1f, 0.05f};
    std::array<float, 3> out;
    for (int c = 0; c < 3; ++c) {
        out[c] = t < 0.5 ? static_cast<float>(grey[c] + (yellow[c] - grey[c]) * (t / 0.5))
                         : static_cast<float>(yellow[c] + (red[c] - yellow[c]) * ((t - 0.5) / 0.5));
    }
    return out;
}

void writePng(const std::string& path, const RgbImage& image) {
    scene::writePngRgb8(path, image.width, image.height, image.pixels.data());
}

}  // namespace pmsc::face
