// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Errors.h"
#include "pmsc/FrameSet.h"  // Index

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace pmsc {

static_assert(std::endian::native == std::endian::little, "pmsc's file formats assume a little-endian host");

/// Appends little-endian values to a byte string: the writing half of a model-file section codec
/// (ModelSections.h). No padding, no alignment: every value is exactly its size.
class ByteWriter {
public:
    explicit ByteWriter(std::string& out) : out_(out) {}

    void u32(std::uint32_t v) { put(v); }
    void u64(std::uint64_t v) { put(v); }
    void f64(double v) { put(v); }
    /// A non-negative Index as a u64.
    void index(Index v) { put(static_cast<std::uint64_t>(v)); }
    void doubles(const double* values, std::size_t count) {
        if (count == 0) return;  // an empty Eigen array's data() is null
        out_.append(reinterpret_cast<const char*>(values), count * sizeof(double));
    }
    /// Each index as a u64, in order.
    void indices(std::span<const Index> values) {
        for (const Index v : values) index(v);
    }
    std::size_t size() const { return out_.size(); }

private:
    template <class T>
    void put(T value) {
        char bytes[sizeof(T)];
        std::memcpy(bytes, &value, sizeof(T));
        out_.append(bytes, sizeof(T));
    }
    std::string& out_;
};

/// Reads little-endian values from a byte range with a bounds check on every read: the reading
/// half of a section codec. Every problem (a read past the end, a count larger than the bytes
/// left could hold, an index out of range, bytes left over) throws one InputError that starts
/// with `context` (e.g. "m.pmsc: section 'REGIONS'") and names the field, so a codec is a list of
/// reads with no checks of its own for truncation.
///
/// Decision: counts are checked against the bytes that remain BEFORE anything is allocated from
/// them (count()), so a corrupted count can never make a reader allocate more than the file holds.
class ByteReader {
public:
    ByteReader(std::string_view bytes, std::string context) : bytes_(bytes), context_(std::move(context)) {}

    std::uint32_t u32(std::string_view what) { return get<std::uint32_t>(what); }
    std::uint64_t u64(std::string_view what) { return get<std::uint64_t>(what); }
    double f64(std::string_view what) { return get<double>(what); }
    /// A finite double.
    double finite(std::string_view what) {
        const double v = f64(what);
        if (!std::isfinite(v))
            fail(std::string(what) + " is " + std::to_string(v) + ", expected a finite number");
        return v;
    }
    /// A u64 in [0, bound), as an Index.
    Index index(std::string_view what, std::uint64_t bound) {
        const std::uint64_t v = u64(what);
        if (v >= bound)
            fail(std::string(what) + " " + std::to_string(v) + " is outside [0, " + std::to_string(bound) +
                 ")");
        return static_cast<Index>(v);
    }
    /// A u64 count of elements of `elementBytes` bytes each that must still fit in what is left.
    std::uint64_t count(std::string_view what, std::uint64_t elementBytes) {
        const std::uint64_t n = u64(what);
        if (elementBytes > 0 && n > remaining() / elementBytes)
            fail(std::string(what) + " " + std::to_string(n) + " needs " +
                 (n > UINT64_MAX / elementBytes ? std::string("more") : std::to_string(n * elementBytes)) +
                 " bytes, only " + std::to_string(remaining()) + " left");
        return n;
    }
    void doubles(double* out, std::uint64_t count, std::string_view what) {
        need(count, sizeof(double), what);
        // An empty Eigen array's data() is null, and memcpy(nullptr, p, 0) is undefined behaviour
        // (found by fuzz_model on a region with no feather entries, a model `pmsc train` writes).
        if (count == 0) return;
        std::memcpy(out, bytes_.data() + at_, count * sizeof(double));
        at_ += count * sizeof(double);
    }
    /// `count` indices, each in [0, bound).
    std::vector<Index> indices(std::uint64_t count, std::uint64_t bound, std::string_view what) {
        need(count, 8, what);
        std::vector<Index> out(count);
        for (auto& v : out) v = index(what, bound);
        return out;
    }

    /// The next `count` bytes as they are (a tag, a nested section's payload).
    std::string_view take(std::uint64_t count, std::string_view what) {
        need(count, 1, what);
        const std::string_view out = bytes_.substr(at_, count);
        at_ += count;
        return out;
    }
    /// Fails unless `count` elements of `size` bytes are still left to read (checked before a
    /// caller allocates for them).
    void require(std::uint64_t count, std::uint64_t size, std::string_view what) const {
        need(count, size, what);
    }

    std::size_t remaining() const { return bytes_.size() - at_; }
    std::size_t offset() const { return at_; }
    /// Fails unless every byte was read.
    void expectEnd() const {
        if (remaining() != 0) fail(std::to_string(remaining()) + " unexpected bytes after the last field");
    }
    [[noreturn]] void fail(const std::string& what) const { throw InputError(context_ + ": " + what); }
    const std::string& context() const { return context_; }

private:
    void need(std::uint64_t count, std::uint64_t size, std::string_view what) const {
        if (count > remaining() / size)
            fail("truncated: " + std::string(what) + " needs " + std::to_string(count) + " x " +
                 std::to_string(size) + " bytes at offset " + std::to_string(at_) + ", only " +
                 std::to_string(remaining()) + " left");
    }
    template <class T>
    T get(std::string_view what) {
        need(1, sizeof(T), what);
        T value;
        std::memcpy(&value, bytes_.data() + at_, sizeof(T));
        at_ += sizeof(T);
        return value;
    }

    std::string_view bytes_;
    std::string context_;
    std::size_t at_ = 0;
};

}  // namespace pmsc
