// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/MeshTopology.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace pmsc::face {

/// An 8-bit RGB image, rows top to bottom.
struct RgbImage {
    int width = 0;
    int height = 0;
    std::vector<std::uint8_t> pixels;  ///< 3 per pixel

    RgbImage() = default;
    RgbImage(int w, int h, std::array<std::uint8_t, 3> fill);
    std::uint8_t* at(int x, int y) { return &pixels[3 * (static_cast<size_t>(y) * width + x)]; }
    /// Copies `other` with its top-left corner at (x, y).
    void paste(const RgbImage& other, int x, int y);
};

/// An orthographic camera: looks down -z of its frame at `centre`; `pixelsPerUnit` zoom.
struct OrthoView {
    int width = 400;
    int height = 480;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    double pixelsPerUnit = 15;
    double yawDegrees = 0;  ///< turns the head (about y) before projecting
};

/// A small software rasterizer for posed faces: triangles with a z-buffer, per-vertex colours
/// interpolated across the triangle, and two-sided Lambert shading from one key light plus
/// ambient. Enough to look at an error map; no textures, no anti-aliasing.
class FaceRenderer {
public:
    /// @param hidden per vertex: true for helper geometry not to draw (the ICT eye occlusion,
    ///               eye blend and lacrimal shells, which are transparent in a real shader).
    FaceRenderer(const MeshTopology& topology, std::vector<char> hidden);

    /// Renders `positions` (3 per vertex) with per-vertex colours (3 per vertex, 0..1).
    RgbImage render(std::span<const double> positions, std::span<const float> colours,
                    const OrthoView& view) const;
    /// Draws a dot of `radius` pixels at each of `points` that is visible in `image`'s depth
    /// (call right after render() with the same view and positions).
    void drawPoints(RgbImage& image, std::span<const double> positions, std::span<const Index> points,
                    const OrthoView& view, std::array<std::uint8_t, 3> colour, int radius) const;

    /// The ICT helpers that a renderer hides (eye occlusion, eye blend, lacrimal fluid).
    static std::vector<char> ictHiddenVertices(Index vertexCount);

private:
    const MeshTopology& topology_;
    std::vector<char> hidden_;
    mutable std::vector<float> depth_;  // of the last render (drawPoints uses it); not thread-safe
};

/// Error colour ramp: grey at 0, yellow at half of `full`, red at `full` and above.
std::array<float, 3> errorColour(double error, double full);

/// Encodes an image as PNG (libpng) and writes it atomically. @throws IoError naming the path.
void writePng(const std::string& path, const RgbImage& image);

}  // namespace pmsc::face
