// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <cstring>
#include <string>
#include <type_traits>

namespace pmsc::viewer {

/// Appends the bytes of a trivially copyable value (the page reads them little-endian, as x86-64
/// and ARM64 store them).
template <class T>
void appendBytes(std::string& out, const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    char b[sizeof(T)];
    std::memcpy(b, &value, sizeof(T));
    out.append(b, sizeof(T));
}

}  // namespace pmsc::viewer
