#include "evaluators/scene/Image.h"

#include "evaluators/scene/Png.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <stdexcept>

namespace pmsc::scene {

namespace {

std::uint8_t toSrgb8(float linear, float exposure) {
    float x = std::max(0.0f, linear * exposure);
    x = x / (1.0f + x);
    const float s = x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x, 1.0f / 2.4f) - 0.055f;
    return static_cast<std::uint8_t>(std::clamp(std::lround(s * 255.0f), 0L, 255L));
}

}  // namespace

Image sideBySide(const std::vector<const Image*>& panels) {
    if (panels.empty()) throw std::invalid_argument("sideBySide: no panels");
    int w = 0;
    const int h = panels.front()->height;
    for (const Image* p : panels) {
        if (p->height != h) throw std::invalid_argument("sideBySide: panels of different heights");
        w += p->width;
    }
    Image out(w, h);
    int x0 = 0;
    for (const Image* p : panels) {
        for (int y = 0; y < h; ++y)
            std::memcpy(out.pixel(x0, y), p->pixel(0, y), sizeof(float) * 3 * static_cast<size_t>(p->width));
        x0 += p->width;
    }
    return out;
}

Image absDifference(const Image& a, const Image& b, float scale) {
    if (a.width != b.width || a.height != b.height)
        throw std::invalid_argument("absDifference: sizes differ");
    Image out(a.width, a.height);
    for (size_t i = 0; i < a.rgb.size(); ++i) out.rgb[i] = std::abs(a.rgb[i] - b.rgb[i]) * scale;
    return out;
}

void writePng(const std::string& path, const Image& image, float exposure) {
    std::vector<std::uint8_t> pixels(image.rgb.size());
    for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = toSrgb8(image.rgb[i], exposure);
    writePngRgb8(path, image.width, image.height, pixels.data());
}

void writePfm(const std::string& path, const Image& image) {
    std::string bytes =
        "PF\n" + std::to_string(image.width) + " " + std::to_string(image.height) + "\n-1.0\n";
    const size_t rowBytes = sizeof(float) * 3 * static_cast<size_t>(image.width);
    for (int y = image.height - 1; y >= 0; --y)
        bytes.append(reinterpret_cast<const char*>(image.pixel(0, y)), rowBytes);
    writeFileAtomically(path, bytes);
}

Image readPfm(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw InputError(path + ": cannot open");
    std::string magic;
    int w = 0, h = 0;
    double scale = 0;
    f >> magic >> w >> h >> scale;
    f.get();
    if (magic != "PF" || w <= 0 || h <= 0 || scale >= 0)
        throw InputError(path + ": not a little-endian colour PFM");
    Image img(w, h);
    for (int y = h - 1; y >= 0; --y)
        f.read(reinterpret_cast<char*>(img.pixel(0, y)),
               static_cast<std::streamsize>(sizeof(float) * 3 * static_cast<size_t>(w)));
    if (!f) throw InputError(path + ": truncated");
    return img;
}

}  // namespace pmsc::scene
