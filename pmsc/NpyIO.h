// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/AtomicFile.h"
#include "pmsc/FrameSet.h"

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace pmsc {

/// Element type of a frames file. Computation is always in double; the type is
/// remembered so that an output can be written in the type its input came in.
enum class NpyDtype : int {
    Float32 = 0,  ///< NumPy '<f4'
    Float64 = 1,  ///< NumPy '<f8'
};

/// NumPy's name of the type ("float32", "float64").
std::string_view toString(NpyDtype dtype);
/// Bytes per value (4 or 8).
std::size_t itemSize(NpyDtype dtype);

/// What the header of a frames file says, after every check that does not need
/// the values themselves: a supported little-endian float dtype, C order, shape
/// (F, N, C) with all three positive, and a data block of exactly F*N*C values
/// (no truncation, no trailing bytes).
struct NpyInfo {
    Index frames = 0;    ///< F
    Index points = 0;    ///< N
    Index channels = 0;  ///< C
    NpyDtype dtype = NpyDtype::Float64;
    std::uint64_t dataOffset = 0;  ///< byte offset of value (0, 0, 0)
    int majorVersion = 1;          ///< .npy format version the file uses (1, 2 or 3)
};

/// A frames file read into memory, plus the dtype it was stored in.
struct FrameFile {
    FrameSet frames;
    NpyDtype dtype = NpyDtype::Float64;
};

/// Reads and checks only the header of a NumPy .npy frames file (versions 1.0,
/// 2.0 and 3.0), and checks the file length against the shape.
/// @throws InputError naming `path` and what is wrong: missing or unreadable
///         file, bad magic, malformed header, unsupported dtype (named),
///         fortran_order True, a rank other than 3 (the shape is shown), a zero
///         dimension, truncated data (expected vs actual bytes) or trailing bytes.
NpyInfo readNpyInfo(const std::string& path);

/// Reads a whole frames file: shape (F, N, C), float32 or float64, C order.
/// Values are converted to double; the stored dtype is returned alongside.
/// @throws InputError for everything readNpyInfo() rejects, and for a NaN or
///         infinite value (the message names the frame, point and channel of
///         the first one).
FrameFile readFrames(const std::string& path);

/// Reads frames [first, first+count) only, seeking past the others, so a farm
/// task can load its slice of a long shot without reading the whole file.
/// The header and the whole file's length are checked as in readFrames(); only
/// the values read are checked for NaN/Inf (reported with their frame number in
/// the file, not in the slice).
/// @throws InputError also when the range is empty or outside [0, F).
FrameFile readFrameRange(const std::string& path, Index first, Index count);

/// Reads a table of per-point values, such as point positions: a .npy of shape (N, C), or
/// (1, N, C), float32 or float64, every value finite. Returned as one frame of N points.
/// @throws InputError as readFrames(), naming the expected shape for any other rank.
FrameFile readPointTable(const std::string& path);

/// A frames file mapped read-only into memory (mmap), for inputs larger than memory: values
/// are read where they lie, so the process holds no copy of the file (the page cache holds what
/// was read, and the kernel may drop it). Opening checks the header as readNpyInfo() and every
/// value for NaN/Inf in one streaming pass, so a bad file fails at once, as with readFrames().
/// Reading is thread-safe. The file must not be truncated while it is mapped (reading a page
/// past the new end raises SIGBUS, as for any mapping).
class MappedFrames {
public:
    /// Whether opening checks every value for NaN/Inf.
    enum class ValueCheck : int {
        AllFinite = 0,  ///< every value must be finite (frames of a shot)
        None = 1,       ///< values are checked by the reader where it reads them (answers of a pass, where
                        ///< only the entries asked for are meaningful)
    };
    /// @throws InputError for everything readFrames() rejects (the NaN/Inf check only under
    ///         ValueCheck::AllFinite), or if the file cannot be mapped.
    explicit MappedFrames(const std::string& path, ValueCheck check = ValueCheck::AllFinite);
    ~MappedFrames();
    MappedFrames(const MappedFrames&) = delete;
    MappedFrames& operator=(const MappedFrames&) = delete;

    const NpyInfo& info() const { return info_; }
    const std::string& path() const { return path_; }

    /// The C values of each of `points` in `frame`, as doubles, point after point.
    /// @throws std::out_of_range for a frame or point outside the file.
    void read(Index frame, std::span<const Index> points, double* out) const;
    /// All N*C values of `frame`. @throws std::out_of_range.
    void readFrame(Index frame, double* out) const;

private:
    void convert(std::uint64_t first, std::uint64_t count, double* out) const;

    std::string path_;
    NpyInfo info_;
    const unsigned char* base_ = nullptr;
    std::size_t mappedBytes_ = 0;
};

/// Writes frames to a .npy file of shape (F, N, C) in the given dtype (values
/// are rounded to nearest when writing float32). The file appears atomically:
/// the data go to a temporary file in the same folder, which is flushed to
/// disk (fsync) and then renamed over `path`; on any failure the temporary
/// file is removed and `path` is left untouched.
/// @throws IoError naming the path and the system's reason.
/// @throws std::invalid_argument if `frames` has a non-positive size or the
///         wrong number of values.
void writeFrames(const std::string& path, const FrameSet& frames, NpyDtype dtype);

/// Writes a .npy frames file frame by frame, in any order and from several
/// threads at once (each frame has its own place in the file), for outputs too
/// large to hold in memory. Nothing appears at `path` until commit(); an
/// object destroyed without commit() removes its temporary file.
class NpyFrameWriter {
public:
    /// Creates the temporary file next to `path` and writes the header.
    /// @throws IoError if the temporary file cannot be created or written.
    /// @throws std::invalid_argument for a non-positive size.
    NpyFrameWriter(std::string path, Index frames, Index points, Index channels, NpyDtype dtype);
    NpyFrameWriter(const NpyFrameWriter&) = delete;
    NpyFrameWriter& operator=(const NpyFrameWriter&) = delete;

    /// Writes frame `frame` (N*C doubles, point-major, channel-minor).
    /// Thread-safe for distinct frames. @throws IoError, std::out_of_range.
    void writeFrame(Index frame, const double* values);

    /// Flushes to disk and renames the temporary file to the final path.
    /// @throws IoError; the temporary file is then removed.
    void commit();

    /// Removes the temporary file; the final path is left untouched.
    void abandon() noexcept;

    const std::string& path() const { return file_.path(); }
    /// Where the data go until commit().
    const std::string& temporaryPath() const { return file_.temporaryPath(); }

private:
    AtomicFile file_;
    Index frames_, points_, channels_;
    NpyDtype dtype_;
    std::uint64_t dataOffset_ = 0;
};

}  // namespace pmsc
