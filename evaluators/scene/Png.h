// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <cstdint>
#include <string>

namespace pmsc::scene {

/// Encodes 8-bit RGB pixels (rows top to bottom, 3 bytes per pixel) as a PNG file's bytes,
/// with libpng's simplified API (no setjmp/longjmp crosses C++ code).
/// @throws pmsc::IoError with libpng's reason.
std::string encodePngRgb8(int width, int height, const std::uint8_t* rgb);

/// encodePngRgb8, then pmsc::writeFileAtomically: the file appears whole or not at all.
/// @throws pmsc::IoError naming the path.
void writePngRgb8(const std::string& path, int width, int height, const std::uint8_t* rgb);

}  // namespace pmsc::scene
