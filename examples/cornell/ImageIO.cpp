#include "examples/cornell/ImageIO.h"

#include "pmsc/Errors.h"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>

namespace pmsc::cornell {

namespace {

void commit(const std::string& tmp, const std::string& path) {
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec) {
        std::remove(tmp.c_str());
        throw IoError("cannot write " + path + ": " + ec.message());
    }
}

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
    if (a.width != b.width || a.height != b.height) throw std::invalid_argument("absDifference: sizes differ");
    Image out(a.width, a.height);
    for (size_t i = 0; i < a.rgb.size(); ++i) out.rgb[i] = std::abs(a.rgb[i] - b.rgb[i]) * scale;
    return out;
}

void writePng(const std::string& path, const Image& image, float exposure) {
    const std::string tmp = path + ".tmp";
    FILE* fp = std::fopen(tmp.c_str(), "wb");
    if (!fp) throw IoError("cannot write " + path + ": " + std::strerror(errno));
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    std::vector<std::uint8_t> row(static_cast<size_t>(image.width) * 3);
    bool ok = png && info;
    if (ok && setjmp(png_jmpbuf(png))) ok = false;
    if (ok) {
        png_init_io(png, fp);
        png_set_IHDR(png, info, static_cast<png_uint_32>(image.width), static_cast<png_uint_32>(image.height), 8,
                     PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
        png_write_info(png, info);
        for (int y = 0; y < image.height; ++y) {
            const float* src = image.pixel(0, y);
            for (size_t i = 0; i < row.size(); ++i) row[i] = toSrgb8(src[i], exposure);
            png_write_row(png, row.data());
        }
        png_write_end(png, nullptr);
    }
    png_destroy_write_struct(png ? &png : nullptr, info ? &info : nullptr);
    const bool closed = std::fclose(fp) == 0;
    if (!ok || !closed) {
        std::remove(tmp.c_str());
        throw IoError("cannot write " + path + ": libpng failed");
    }
    commit(tmp, path);
}

void writePfm(const std::string& path, const Image& image) {
    const std::string tmp = path + ".tmp";
    {
        std::ofstream f(tmp, std::ios::binary);
        if (!f) throw IoError("cannot write " + path + ": " + std::strerror(errno));
        f << "PF\n" << image.width << " " << image.height << "\n-1.0\n";
        for (int y = image.height - 1; y >= 0; --y)
            f.write(reinterpret_cast<const char*>(image.pixel(0, y)),
                    static_cast<std::streamsize>(sizeof(float) * 3 * static_cast<size_t>(image.width)));
        f.flush();
        if (!f) {
            std::remove(tmp.c_str());
            throw IoError("cannot write " + path + ": write failed");
        }
    }
    commit(tmp, path);
}

Image readPfm(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw InputError(path + ": cannot open");
    std::string magic;
    int w = 0, h = 0;
    double scale = 0;
    f >> magic >> w >> h >> scale;
    f.get();
    if (magic != "PF" || w <= 0 || h <= 0 || scale >= 0) throw InputError(path + ": not a little-endian colour PFM");
    Image img(w, h);
    for (int y = h - 1; y >= 0; --y)
        f.read(reinterpret_cast<char*>(img.pixel(0, y)), static_cast<std::streamsize>(sizeof(float) * 3 * static_cast<size_t>(w)));
    if (!f) throw InputError(path + ": truncated");
    return img;
}

}  // namespace pmsc::cornell
