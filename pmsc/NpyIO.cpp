#include "pmsc/NpyIO.h"

#include "pmsc/Errors.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

namespace pmsc {

// Values are copied between the file and memory without byte swapping.
static_assert(std::endian::native == std::endian::little,
              "pmsc's .npy and model I/O assume a little-endian host");

std::string_view toString(NpyDtype dtype) { return dtype == NpyDtype::Float32 ? "float32" : "float64"; }

std::size_t itemSize(NpyDtype dtype) { return dtype == NpyDtype::Float32 ? 4 : 8; }

namespace {

constexpr char kMagic[] = "\x93NUMPY";
constexpr std::size_t kMagicSize = 6;
// A real header is a few hundred bytes; this only stops a corrupted length field
// from making us allocate the whole file.
constexpr std::uint64_t kMaxHeaderBytes = 1u << 20;

[[noreturn]] void badNpy(const std::string& path, const std::string& what) {
    throw InputError(path + ": " + what);
}

/// An open, read-only file that closes itself.
class ReadFile {
public:
    explicit ReadFile(const std::string& path) : path_(path) {
        fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
        if (fd_ < 0) {
            const int error = errno;
            badNpy(path,
                   error == ENOENT ? "no such file" : std::string("cannot open: ") + std::strerror(error));
        }
        struct stat st {};
        if (::fstat(fd_, &st) != 0) badNpy(path, std::string("cannot stat: ") + std::strerror(errno));
        if (S_ISDIR(st.st_mode)) badNpy(path, "is a folder, not a .npy file");
        size_ = static_cast<std::uint64_t>(st.st_size);
    }
    ~ReadFile() { ::close(fd_); }
    ReadFile(const ReadFile&) = delete;
    ReadFile& operator=(const ReadFile&) = delete;

    std::uint64_t size() const { return size_; }
    int fd() const { return fd_; }

    /// Reads exactly `bytes` at `offset`; a short read is truncation.
    void readAt(std::uint64_t offset, void* out, std::size_t bytes) const {
        char* p = static_cast<char*>(out);
        while (bytes > 0) {
            const ssize_t n = ::pread(fd_, p, bytes, static_cast<off_t>(offset));
            if (n < 0) {
                if (errno == EINTR) continue;
                badNpy(path_, std::string("read failed: ") + std::strerror(errno));
            }
            if (n == 0) badNpy(path_, "unexpected end of file");
            p += n;
            offset += static_cast<std::uint64_t>(n);
            bytes -= static_cast<std::size_t>(n);
        }
    }

private:
    std::string path_;
    int fd_ = -1;
    std::uint64_t size_ = 0;
};

/// Parser for the Python dict literal of a .npy header, e.g.
/// {'descr': '<f8', 'fortran_order': False, 'shape': (600, 26719, 3), }
class HeaderParser {
public:
    HeaderParser(const std::string& path, std::string_view text) : path_(path), s_(text) {}

    struct Fields {
        std::string descr;
        bool fortranOrder = false;
        std::vector<std::uint64_t> shape;
    };

    Fields parse() {
        Fields fields;
        bool haveDescr = false, haveOrder = false, haveShape = false;
        skipSpace();
        expect('{');
        for (;;) {
            skipSpace();
            if (peek() == '}') {
                ++i_;
                break;
            }
            const std::string key = parseString();
            skipSpace();
            expect(':');
            skipSpace();
            if (key == "descr") {
                if (peek() != '\'' && peek() != '"')
                    fail(
                        "unsupported dtype (structured or non-string 'descr'; pmsc reads float32 '<f4' or "
                        "float64 '<f8')");
                fields.descr = parseString();
                haveDescr = true;
            } else if (key == "fortran_order") {
                fields.fortranOrder = parseBool();
                haveOrder = true;
            } else if (key == "shape") {
                fields.shape = parseTuple();
                haveShape = true;
            } else {
                fail("bad header: unexpected key '" + key + "'");
            }
            skipSpace();
            if (peek() == ',') {
                ++i_;
                continue;
            }
            if (peek() == '}') {
                ++i_;
                break;
            }
            fail("bad header: expected ',' or '}' at byte " + std::to_string(i_));
        }
        if (!haveDescr) fail("bad header: no 'descr'");
        if (!haveOrder) fail("bad header: no 'fortran_order'");
        if (!haveShape) fail("bad header: no 'shape'");
        return fields;
    }

private:
    [[noreturn]] void fail(const std::string& what) const { badNpy(path_, what); }
    char peek() const { return i_ < s_.size() ? s_[i_] : '\0'; }
    void skipSpace() {
        while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t' || s_[i_] == '\n' || s_[i_] == '\r')) ++i_;
    }
    void expect(char c) {
        if (peek() != c) fail(std::string("bad header: expected '") + c + "' at byte " + std::to_string(i_));
        ++i_;
    }
    std::string parseString() {
        const char quote = peek();
        if (quote != '\'' && quote != '"')
            fail("bad header: expected a quoted string at byte " + std::to_string(i_));
        ++i_;
        const auto end = s_.find(quote, i_);
        if (end == std::string_view::npos) fail("bad header: unterminated string");
        std::string out(s_.substr(i_, end - i_));
        i_ = end + 1;
        return out;
    }
    bool parseBool() {
        if (s_.substr(i_, 4) == "True") {
            i_ += 4;
            return true;
        }
        if (s_.substr(i_, 5) == "False") {
            i_ += 5;
            return false;
        }
        fail("bad header: 'fortran_order' is not True or False");
    }
    std::vector<std::uint64_t> parseTuple() {
        expect('(');
        std::vector<std::uint64_t> dims;
        for (;;) {
            skipSpace();
            if (peek() == ')') {
                ++i_;
                break;
            }
            if (peek() < '0' || peek() > '9')
                fail("bad header: 'shape' is not a tuple of non-negative integers");
            std::uint64_t v = 0;
            while (peek() >= '0' && peek() <= '9') {
                const std::uint64_t digit = static_cast<std::uint64_t>(peek() - '0');
                if (v > (UINT64_MAX - digit) / 10) fail("bad header: a dimension of 'shape' overflows");
                v = v * 10 + digit;
                ++i_;
            }
            if (peek() == 'L') ++i_;  // Python 2 long
            dims.push_back(v);
            skipSpace();
            if (peek() == ',') {
                ++i_;
                continue;
            }
            if (peek() == ')') {
                ++i_;
                break;
            }
            fail("bad header: malformed 'shape'");
        }
        return dims;
    }

    const std::string& path_;
    std::string_view s_;
    std::size_t i_ = 0;
};

std::string shapeString(const std::vector<std::uint64_t>& shape) {
    std::string s = "(";
    for (std::size_t i = 0; i < shape.size(); ++i) {
        if (i) s += ", ";
        s += std::to_string(shape[i]);
    }
    if (shape.size() == 1) s += ",";
    return s + ")";
}

/// `pointTable`: a (N, C) table is read as one frame (readPointTable).
NpyInfo parseInfo(const std::string& path, const ReadFile& file, bool pointTable = false) {
    const std::uint64_t size = file.size();
    if (size < kMagicSize + 2) badNpy(path, "not a .npy file (only " + std::to_string(size) + " bytes)");
    unsigned char prefix[12] = {};
    file.readAt(0, prefix, static_cast<std::size_t>(std::min<std::uint64_t>(size, sizeof prefix)));
    if (std::memcmp(prefix, kMagic, kMagicSize) != 0) badNpy(path, "not a .npy file (bad magic)");
    NpyInfo info;
    info.majorVersion = prefix[6];
    const int minor = prefix[7];
    std::uint64_t headerLength = 0, headerStart = 0;
    if (info.majorVersion == 1) {
        if (size < 10) badNpy(path, "truncated .npy header");
        headerLength = prefix[8] | (prefix[9] << 8);
        headerStart = 10;
    } else if (info.majorVersion == 2 || info.majorVersion == 3) {
        if (size < 12) badNpy(path, "truncated .npy header");
        headerLength = std::uint64_t(prefix[8]) | (std::uint64_t(prefix[9]) << 8) |
                       (std::uint64_t(prefix[10]) << 16) | (std::uint64_t(prefix[11]) << 24);
        headerStart = 12;
    } else {
        badNpy(path, "unsupported .npy format version " + std::to_string(info.majorVersion) + "." +
                         std::to_string(minor) + " (pmsc reads 1.0, 2.0 and 3.0)");
    }
    if (headerLength > kMaxHeaderBytes)
        badNpy(path, "bad header: header length " + std::to_string(headerLength) + " bytes is implausible");
    if (headerStart + headerLength > size)
        badNpy(path, "truncated .npy header (header needs " + std::to_string(headerStart + headerLength) +
                         " bytes, file has " + std::to_string(size) + ")");
    std::string text(static_cast<std::size_t>(headerLength), '\0');
    file.readAt(headerStart, text.data(), text.size());
    info.dataOffset = headerStart + headerLength;

    HeaderParser::Fields fields = HeaderParser(path, text).parse();
    if (fields.descr == "<f4" || (fields.descr == "=f4")) {
        info.dtype = NpyDtype::Float32;
    } else if (fields.descr == "<f8" || fields.descr == "=f8") {
        info.dtype = NpyDtype::Float64;
    } else {
        badNpy(path, "unsupported dtype '" + fields.descr +
                         "' (pmsc reads little-endian float32 '<f4' or float64 '<f8')");
    }
    if (fields.fortranOrder)
        badNpy(path, "fortran_order is True (pmsc reads C-order arrays; save with numpy.ascontiguousarray)");
    if (pointTable) {
        if (fields.shape.size() == 2) {
            fields.shape.insert(fields.shape.begin(), 1);
        } else if (fields.shape.size() != 3 || fields.shape[0] != 1) {
            badNpy(path,
                   "shape " + shapeString(fields.shape) +
                       " is not a table of points: expected (points, channels) or (1, points, channels)");
        }
    }
    if (fields.shape.size() != 3)
        badNpy(path, "shape " + shapeString(fields.shape) + " has rank " +
                         std::to_string(fields.shape.size()) + ", expected 3: (frames, points, channels)");
    for (int d = 0; d < 3; ++d) {
        static const char* const names[] = {"frames", "points", "channels"};
        if (fields.shape[d] == 0)
            badNpy(path, "shape " + shapeString(fields.shape) + " has zero " + names[d]);
    }
    std::uint64_t count = 0, bytes = 0;
    if (__builtin_mul_overflow(fields.shape[0], fields.shape[1], &count) ||
        __builtin_mul_overflow(count, fields.shape[2], &count) ||
        __builtin_mul_overflow(count, std::uint64_t(itemSize(info.dtype)), &bytes) ||
        bytes > static_cast<std::uint64_t>(INT64_MAX))
        badNpy(path, "shape " + shapeString(fields.shape) + " is too large");
    const std::uint64_t actual = size - info.dataOffset;
    if (actual < bytes)
        badNpy(path, "truncated data: shape " + shapeString(fields.shape) + " " +
                         std::string(toString(info.dtype)) + " needs " + std::to_string(bytes) +
                         " bytes of data, the file has " + std::to_string(actual));
    if (actual > bytes)
        badNpy(path, "trailing garbage: " + std::to_string(actual - bytes) + " bytes after the " +
                         std::to_string(bytes) + " bytes of data of shape " + shapeString(fields.shape));
    info.frames = static_cast<Index>(fields.shape[0]);
    info.points = static_cast<Index>(fields.shape[1]);
    info.channels = static_cast<Index>(fields.shape[2]);
    return info;
}

/// Throws InputError naming the first non-finite value of values[0, count), which are
/// values [first, first + count) of the file (the message gives frame, point and channel).
void checkFinite(const std::string& path, const NpyInfo& info, std::uint64_t first, const double* values,
                 std::uint64_t count) {
    const double* bad_value =
        std::find_if(values, values + count, [](double v) { return !std::isfinite(v); });
    if (bad_value == values + count) return;
    const std::uint64_t i = first + static_cast<std::uint64_t>(bad_value - values);
    const std::uint64_t c = static_cast<std::uint64_t>(info.channels);
    const std::uint64_t n = static_cast<std::uint64_t>(info.points);
    const std::string what = std::isnan(*bad_value) ? "NaN" : (*bad_value > 0 ? "+Inf" : "-Inf");
    badNpy(path, what + " at frame " + std::to_string(i / (n * c)) + ", point " +
                     std::to_string((i / c) % n) + ", channel " + std::to_string(i % c) +
                     " (frames must be finite)");
}

/// Reads `count` values starting at value index `first` into `out` as doubles and
/// reports the first non-finite one (indices in the whole file).
void readValues(const std::string& path, const ReadFile& file, const NpyInfo& info, std::uint64_t first,
                std::uint64_t count, double* out) {
    const std::size_t item = itemSize(info.dtype);
    const std::uint64_t offset = info.dataOffset + first * item;
    if (info.dtype == NpyDtype::Float64) {
        file.readAt(offset, out, static_cast<std::size_t>(count * item));
    } else {
        // Convert in chunks so a float32 file never needs a second full-size buffer.
        constexpr std::uint64_t kChunk = 1 << 16;
        std::vector<float> buffer(static_cast<std::size_t>(std::min(count, kChunk)));
        for (std::uint64_t done = 0; done < count;) {
            const std::uint64_t n = std::min(kChunk, count - done);
            file.readAt(offset + done * item, buffer.data(), static_cast<std::size_t>(n * item));
            std::copy_n(buffer.data(), n, out + done);
            done += n;
        }
    }
    checkFinite(path, info, first, out, count);
}

std::string makeHeader(Index frames, Index points, Index channels, NpyDtype dtype) {
    std::string dict = std::string("{'descr': '") + (dtype == NpyDtype::Float32 ? "<f4" : "<f8") +
                       "', 'fortran_order': False, 'shape': (" + std::to_string(frames) + ", " +
                       std::to_string(points) + ", " + std::to_string(channels) + "), }";
    // NumPy pads with spaces and a final newline so the data start on a 64-byte boundary;
    // version 2.0 (a 4-byte length) only when the header does not fit version 1.0's 2 bytes.
    const auto padded = [&](std::size_t prefix) {
        return (prefix + dict.size() + 1 + 63) / 64 * 64 - prefix;
    };
    const bool v1 = padded(10) <= 65535;
    const std::size_t prefix = v1 ? 10 : 12;
    dict.append(padded(prefix) - dict.size() - 1, ' ');
    dict.push_back('\n');
    std::string out(kMagic, kMagicSize);
    out.push_back(static_cast<char>(v1 ? 1 : 2));
    out.push_back('\0');
    const std::uint64_t length = dict.size();
    out.push_back(static_cast<char>(length & 0xff));
    out.push_back(static_cast<char>((length >> 8) & 0xff));
    if (!v1) {
        out.push_back(static_cast<char>((length >> 16) & 0xff));
        out.push_back(static_cast<char>((length >> 24) & 0xff));
    }
    return out + dict;
}

}  // namespace

NpyInfo readNpyInfo(const std::string& path) {
    ReadFile file(path);
    return parseInfo(path, file);
}

FrameFile readFrames(const std::string& path) {
    ReadFile file(path);
    const NpyInfo info = parseInfo(path, file);
    FrameFile out;
    out.dtype = info.dtype;
    out.frames = FrameSet(info.frames, info.points, info.channels, FrameSet::Uninitialised{});
    readValues(path, file, info, 0, out.frames.values.size(), out.frames.values.data());
    return out;
}

FrameFile readFrameRange(const std::string& path, Index first, Index count) {
    ReadFile file(path);
    const NpyInfo info = parseInfo(path, file);
    if (count <= 0 || first < 0 || first > info.frames - count)
        badNpy(path, "frames [" + std::to_string(first) + ", " + std::to_string(first + count) +
                         ") are not within the file's " + std::to_string(info.frames) + " frames");
    FrameFile out;
    out.dtype = info.dtype;
    out.frames = FrameSet(count, info.points, info.channels, FrameSet::Uninitialised{});
    const std::uint64_t perFrame = static_cast<std::uint64_t>(info.points * info.channels);
    readValues(path, file, info, static_cast<std::uint64_t>(first) * perFrame, out.frames.values.size(),
               out.frames.values.data());
    return out;
}

FrameFile readPointTable(const std::string& path) {
    ReadFile file(path);
    const NpyInfo info = parseInfo(path, file, true);
    FrameFile out;
    out.dtype = info.dtype;
    out.frames = FrameSet(1, info.points, info.channels, FrameSet::Uninitialised{});
    readValues(path, file, info, 0, out.frames.values.size(), out.frames.values.data());
    return out;
}

MappedFrames::MappedFrames(const std::string& path, ValueCheck check) : path_(path) {
    ReadFile file(path);
    info_ = parseInfo(path, file);
    void* p = ::mmap(nullptr, static_cast<std::size_t>(file.size()), PROT_READ, MAP_PRIVATE, file.fd(), 0);
    if (p == MAP_FAILED) badNpy(path, std::string("cannot map: ") + std::strerror(errno));
    base_ = static_cast<const unsigned char*>(p);
    mappedBytes_ = static_cast<std::size_t>(file.size());
    // One streaming pass checks every value, as readFrames() does, in chunks of a fixed size: the
    // pages read stay in the page cache (which the kernel may drop), not in this process's heap.
    if (check == ValueCheck::None) {
        ::madvise(p, mappedBytes_, MADV_RANDOM);
        return;
    }
    try {
        ::madvise(p, mappedBytes_, MADV_SEQUENTIAL);
        const std::uint64_t total = static_cast<std::uint64_t>(info_.frames * info_.points * info_.channels);
        constexpr std::uint64_t kChunk = 1 << 16;
        std::vector<double> buffer(static_cast<std::size_t>(std::min(total, kChunk)));
        for (std::uint64_t done = 0; done < total;) {
            const std::uint64_t n = std::min(kChunk, total - done);
            convert(done, n, buffer.data());
            checkFinite(path, info_, done, buffer.data(), n);
            done += n;
        }
        ::madvise(p, mappedBytes_, MADV_RANDOM);  // the engine asks for key points here and there
    } catch (...) {
        ::munmap(p, mappedBytes_);
        throw;
    }
}

MappedFrames::~MappedFrames() {
    if (base_) ::munmap(const_cast<unsigned char*>(base_), mappedBytes_);
}

void MappedFrames::convert(std::uint64_t first, std::uint64_t count, double* out) const {
    const unsigned char* src = base_ + info_.dataOffset + first * itemSize(info_.dtype);
    if (info_.dtype == NpyDtype::Float64) {
        std::memcpy(out, src, static_cast<std::size_t>(count) * sizeof(double));  // any alignment
    } else {
        for (std::uint64_t i = 0; i < count; ++i) {
            float v;
            std::memcpy(&v, src + i * sizeof(float), sizeof v);
            out[i] = v;
        }
    }
}

void MappedFrames::read(Index frame, std::span<const Index> points, double* out) const {
    if (frame < 0 || frame >= info_.frames)
        throw std::out_of_range(path_ + ": frame " + std::to_string(frame) + " outside the " +
                                std::to_string(info_.frames) + " frames");
    const Index c = info_.channels;
    for (std::size_t i = 0; i < points.size(); ++i) {
        const Index p = points[i];
        if (p < 0 || p >= info_.points)
            throw std::out_of_range(path_ + ": point " + std::to_string(p) + " outside [0, " +
                                    std::to_string(info_.points) + ")");
        convert(static_cast<std::uint64_t>((frame * info_.points + p) * c), static_cast<std::uint64_t>(c),
                out + static_cast<Index>(i) * c);
    }
}

void MappedFrames::readFrame(Index frame, double* out) const {
    if (frame < 0 || frame >= info_.frames)
        throw std::out_of_range(path_ + ": frame " + std::to_string(frame) + " outside the " +
                                std::to_string(info_.frames) + " frames");
    const Index perFrame = info_.points * info_.channels;
    convert(static_cast<std::uint64_t>(frame * perFrame), static_cast<std::uint64_t>(perFrame), out);
}

NpyFrameWriter::NpyFrameWriter(std::string path, Index frames, Index points, Index channels, NpyDtype dtype)
    : file_((frames > 0 && points > 0 && channels > 0)
                ? std::move(path)
                : throw std::invalid_argument(
                      "NpyFrameWriter: sizes must be positive (frames=" + std::to_string(frames) +
                      ", points=" + std::to_string(points) + ", channels=" + std::to_string(channels) + ")")),
      frames_(frames),
      points_(points),
      channels_(channels),
      dtype_(dtype) {
    const std::string header = makeHeader(frames, points, channels, dtype);
    file_.write(header.data(), header.size());
    dataOffset_ = header.size();
    // Size the file now so frames may arrive in any order (and a full disk shows up early
    // for file systems that allocate on truncate).
    const std::uint64_t bytes = static_cast<std::uint64_t>(frames * points * channels) * itemSize(dtype);
    if (bytes > 0) {
        const char zero = 0;
        file_.writeAt(dataOffset_ + bytes - 1, &zero, 1);
    }
}

void NpyFrameWriter::writeFrame(Index frame, const double* values) {
    if (frame < 0 || frame >= frames_)
        throw std::out_of_range("NpyFrameWriter: frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(frames_) + ")");
    const std::size_t n = static_cast<std::size_t>(points_ * channels_);
    const std::uint64_t offset = dataOffset_ + static_cast<std::uint64_t>(frame) * n * itemSize(dtype_);
    if (dtype_ == NpyDtype::Float64) {
        file_.writeAt(offset, values, n * sizeof(double));
    } else {
        std::vector<float> buffer(n);
        std::transform(values, values + n, buffer.begin(), [](double v) { return static_cast<float>(v); });
        file_.writeAt(offset, buffer.data(), n * sizeof(float));
    }
}

void NpyFrameWriter::commit() { file_.commit(); }

void NpyFrameWriter::abandon() noexcept { file_.abandon(); }

void writeFrames(const std::string& path, const FrameSet& frames, NpyDtype dtype) {
    if (frames.frames <= 0 || frames.points <= 0 || frames.channels <= 0 ||
        frames.values.size() != static_cast<std::size_t>(frames.frames * frames.points * frames.channels))
        throw std::invalid_argument("writeFrames: frame set sizes (" + std::to_string(frames.frames) + ", " +
                                    std::to_string(frames.points) + ", " + std::to_string(frames.channels) +
                                    ") do not match its " + std::to_string(frames.values.size()) + " values");
    NpyFrameWriter writer(path, frames.frames, frames.points, frames.channels, dtype);
    for (Index f = 0; f < frames.frames; ++f) writer.writeFrame(f, frames.frame(f));
    writer.commit();
}

}  // namespace pmsc
