// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"

#include <cstdint>
#include <string>
#include <string_view>

namespace pmsc {

/// Newest model file layout this build writes and reads (it reads every older one too).
inline constexpr std::uint32_t kModelFormatVersion = 3;
/// Version 2 with the header's flags word (offset 60) in use: written only for a model with a
/// flag set (shared channels), so an older build says "unsupported version 3" instead
/// of misreading the arrays.
inline constexpr std::uint32_t kModelFormatVersionFlags = 3;
/// Version 1 with tagged sections.
inline constexpr std::uint32_t kModelFormatVersionSections = 2;
/// The layout without sections. A model with no optional part is still written as version 1,
/// byte for byte the same, so builds that read only version 1 keep reading it.
inline constexpr std::uint32_t kModelFormatVersionCore = 1;

/// The .pmsc model file. Little-endian, no padding:
///
///   offset  size        field
///   0       8           magic "PMSCMODL"
///   8       4  u32      format version (1)
///   12      4  u32      reserved, 0
///   16      8  u64      N  points
///   24      8  u64      C  channels
///   32      8  u64      M  basis vectors
///   40      8  u64      K  key points
///   48      8  u64      training frames
///   56      4  u32      selector (0 teleconnection, 1 Q-DEIM)
///   60      4  u32      reserved, 0; version 3: flags, 1 = the channels share the basis
///                       (then B = 1 below, else B = C)
///   64      8  f64      eps_min
///   72      8  f64      eps_max
///   80      8  f64      tolerance (0: not calibrated)
///   88      8  f64      largest point residual of PM on the training set
///   96      8  f64      total energy of the mean-removed training matrix
///   104     8*N*C       mean, f64, point-major, channel-minor
///           8*N*B*M     basis, f64, column-major ((N*B) x M)
///           8*M         singular values, f64
///           8*K         key point indices, u64, selection order
///           8*M*K*B     projector, f64, column-major (M x (K*B))
///   end-8   8  u64      FNV-1a 64 checksum of every byte before it
///
/// The whole file size follows from the header, so a reader knows before it
/// allocates anything whether the file can hold what the header claims.
///
/// Version 3 (shared channels) is version 2 with the flags word in use; it is written only when a flag
/// is set. Version 2 is version 1 with version 2 in the header and, between the
/// projector and the checksum, optional tagged sections (version 3 has them too):
///
///           8  u64      S  section count
///           S times:    char tag[8] (ASCII, '\0'-padded), u64 payload length L, L bytes payload
///   end-8   8  u64      FNV-1a 64 checksum of every byte before it
///
/// Each section is one feature's data, encoded by that feature's own codec (ModelSections.h); a
/// reader rejects a tag it does not know (a file written by a newer pmsc), a tag seen twice, a
/// length past the end, and a payload its codec does not read exactly.
inline constexpr std::size_t kModelHeaderBytes = 104;

/// Header flag (offset 60): Model::sharedChannels.
inline constexpr std::uint32_t kModelFlagSharedChannels = 1;

/// FNV-1a, 64 bit (offset basis 0xcbf29ce484222325, prime 0x100000001b3).
std::uint64_t fnv1a64(const void* data, std::size_t bytes);

/// The version encodeModel() writes for `model`: 3 with a header flag, else 2 with sections, else 1.
std::uint32_t modelFormatVersion(const Model& model);

/// The bytes of a model file. @throws std::invalid_argument if model.validate() fails.
std::string encodeModel(const Model& model);

/// Where decodeModel computes the checksum of a file of at least kChecksumThreadBytes: on a thread
/// of its own beside the decode (the default), or first, on the calling thread (smaller files
/// always). The verdict is the same either way: a checksum mismatch is reported before anything
/// the contents would be refused for.
enum class ChecksumThread { Beside, First };

/// Decision: a file of at least this many bytes has its checksum computed beside its decode. Why:
/// FNV-1a is one multiply per byte in a single dependent chain, about as long as the decode's copies
/// and checks together (a quarter of `pmsc inspect`'s time on an 88 MB volume model), and beside
/// them it costs no wall time on a second core (`pmsc_engine_bench --benchmark_filter=DecodeModel`).
/// Under 4 MiB a thread's start is not worth it.
inline constexpr std::size_t kChecksumThreadBytes = std::size_t{4} << 20;

/// Parses the bytes of a model file. `name` (the path) starts every message.
/// @throws InputError for a truncated file, a wrong magic number, an
///         unsupported version (found vs supported), sizes inconsistent with the
///         file length or with each other, a checksum mismatch, a bad section (unknown or
///         repeated tag, bad length, a payload its codec rejects: the message names the
///         section), or a model that fails Model::validate().
Model decodeModel(std::string_view bytes, const std::string& name,
                  ChecksumThread checksum = ChecksumThread::Beside);

/// Writes a model atomically (temporary file in the same folder, fsync, rename).
/// @throws IoError naming the path; std::invalid_argument for an invalid model.
void writeModel(const std::string& path, const Model& model);

/// Reads and validates a model file. @throws InputError naming the path and the
/// problem (missing, unreadable, or everything decodeModel() rejects).
Model readModel(const std::string& path);

}  // namespace pmsc
