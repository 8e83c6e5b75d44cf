// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <cstdio>
#include <string>

namespace pmsc::cli {

/// One number through a printf format ("%.3g", "%.1f%%"), for the commands' summaries.
inline std::string fmt(const char* format, double v) {
    char buffer[64];
    std::snprintf(buffer, sizeof buffer, format, v);
    return buffer;
}

}  // namespace pmsc::cli
