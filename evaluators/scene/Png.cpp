#include "evaluators/scene/Png.h"

#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include <png.h>

#include <cstring>

namespace pmsc::scene {

std::string encodePngRgb8(int width, int height, const std::uint8_t* rgb) {
    png_image png;
    std::memset(&png, 0, sizeof png);
    png.version = PNG_IMAGE_VERSION;
    png.width = static_cast<png_uint_32>(width);
    png.height = static_cast<png_uint_32>(height);
    png.format = PNG_FORMAT_RGB;
    // The first call measures the encoded size, the second encodes.
    png_alloc_size_t size = 0;
    std::string bytes;
    bool ok = png_image_write_to_memory(&png, nullptr, &size, 0, rgb, 0, nullptr) != 0;
    if (ok) {
        bytes.resize(size);
        ok = png_image_write_to_memory(&png, bytes.data(), &size, 0, rgb, 0, nullptr) != 0;
        bytes.resize(size);
    }
    const std::string why = ok ? "" : png.message;
    png_image_free(&png);
    if (!ok) throw IoError("PNG encoding failed: " + why);
    return bytes;
}

void writePngRgb8(const std::string& path, int width, int height, const std::uint8_t* rgb) {
    std::string bytes;
    try {
        bytes = encodePngRgb8(width, height, rgb);
    } catch (const IoError& e) {
        throw IoError(path + ": " + e.what());
    }
    writeFileAtomically(path, bytes);
}

}  // namespace pmsc::scene
