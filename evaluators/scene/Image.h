// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <string>
#include <vector>

namespace pmsc::scene {

/// A linear RGB image, rows top to bottom, 3 floats per pixel.
struct Image {
    int width = 0, height = 0;
    std::vector<float> rgb;

    Image() = default;
    Image(int w, int h) : width(w), height(h), rgb(static_cast<size_t>(w) * h * 3, 0.0f) {}
    float* pixel(int x, int y) { return rgb.data() + 3 * (static_cast<size_t>(y) * width + x); }
    const float* pixel(int x, int y) const { return rgb.data() + 3 * (static_cast<size_t>(y) * width + x); }
};

/// Images placed left to right (same height). @throws std::invalid_argument otherwise.
Image sideBySide(const std::vector<const Image*>& panels);
/// |a - b| * scale per channel. @throws std::invalid_argument for different sizes.
Image absDifference(const Image& a, const Image& b, float scale);

/// Writes 8-bit sRGB PNG: value * exposure, Reinhard x/(1+x) on each channel, sRGB curve.
/// Atomic (temporary file, then rename). @throws pmsc::IoError naming the path.
void writePng(const std::string& path, const Image& image, float exposure);
/// Writes the linear values as a little-endian colour PFM ("PF", bottom row first).
/// Atomic. @throws pmsc::IoError naming the path.
void writePfm(const std::string& path, const Image& image);
/// Reads a PFM written by writePfm (for tests). @throws pmsc::InputError.
Image readPfm(const std::string& path);

}  // namespace pmsc::scene
