#pragma once
// Byte-level edits of an encoded .pmsc model, for the tests of its decoder's checks: read or
// overwrite a value at an offset, and reseal the checksum so only the check under test objects.
#include "pmsc/ModelIO.h"

#include <cstdint>
#include <cstring>
#include <string>

namespace pmsc::test {

template <class T>
T peek(const std::string& bytes, std::size_t offset) {
    T v;
    std::memcpy(&v, bytes.data() + offset, sizeof(T));
    return v;
}

template <class T>
void poke(std::string& bytes, std::size_t offset, T value) {
    std::memcpy(bytes.data() + offset, &value, sizeof(T));
}

/// Replaces the checksum (the last 8 bytes) so only the check under test can object.
inline void reseal(std::string& bytes) {
    poke<std::uint64_t>(bytes, bytes.size() - 8, pmsc::fnv1a64(bytes.data(), bytes.size() - 8));
}

}  // namespace pmsc::test
