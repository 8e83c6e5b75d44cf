// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// The wire format between pmsc and a calculation in a child process (`exec:COMMAND`), version 2
// (version 1 without the positions request; pmsc speaks both).
// docs/exec-protocol.md is its reference for child authors; this header is the same in code.
//
// One Unix stream socket is the child's standard input and output. All integers are
// little-endian, all values IEEE-754 float64 (little-endian), with no padding between fields.
//
//   child -> pmsc, once at start (Hello, 32 bytes):
//     char[8] "PMSCEXEC", u32 version (1 or 2), u32 C channels, u64 N points, u64 F frames
//   pmsc -> child, per request (Request, 32 bytes), then for a list the indices:
//     u32 kind (1 = list, 2 = range, 3 = positions), u32 0, i64 frame, u64 count, u64 first
//     kind 1: count u64 point indices follow (any order); first is 0
//     kind 2: the points first .. first+count-1; nothing follows
//     kind 3 (version 2 only): where the points are, frame 0, count N, first 0; the answer is
//             N x 3 float64 (x y z, world units), or an error when the points have no places
//   child -> pmsc, per request (Response, 16 bytes), then its payload:
//     u32 status (0 = values, 1 = error), u32 0, u64 length
//     status 0: length = count*C float64, point-major (value i*C + c is channel c of the i-th point
//               asked for)
//     status 1: length bytes of UTF-8 saying what went wrong (one line); the child serves on
//   pmsc closes the socket when it is done: the child reads end of file and exits with code 0.
#pragma once

#include "pmsc/PointEvaluator.h"

#include <bit>
#include <cstdint>
#include <cstring>

namespace pmsc::evaluators::exec {

static_assert(std::endian::native == std::endian::little, "the exec protocol's fields are little-endian");

inline constexpr char kMagic[8] = {'P', 'M', 'S', 'C', 'E', 'X', 'E', 'C'};
/// The version pmsc serves (`pmsc serve`); it reads children of version 1 and 2.
inline constexpr std::uint32_t kProtocolVersion = 2;
/// The first version whose children answer kRequestPositions.
inline constexpr std::uint32_t kPositionsVersion = 2;

enum RequestKind : std::uint32_t { kRequestList = 1, kRequestRange = 2, kRequestPositions = 3 };
enum ResponseStatus : std::uint32_t { kResponseValues = 0, kResponseError = 1 };

#pragma pack(push, 1)
struct Hello {
    char magic[8];
    std::uint32_t version;
    std::uint32_t channels;
    std::uint64_t points;
    std::uint64_t frames;
};
struct Request {
    std::uint32_t kind;
    std::uint32_t reserved;
    std::int64_t frame;
    std::uint64_t count;
    std::uint64_t first;
};
struct Response {
    std::uint32_t status;
    std::uint32_t reserved;
    std::uint64_t length;
};
#pragma pack(pop)
static_assert(sizeof(Hello) == 32 && sizeof(Request) == 32 && sizeof(Response) == 16);

/// Requests longer than this many bytes of error text are refused as garbage.
inline constexpr std::uint64_t kMaxErrorBytes = 1 << 16;

/// Serves `evaluator` over the protocol on descriptors `in` and `out` (a child's standard input
/// and output) until end of file on `in`: writes the hello (version 2), then answers every request,
/// an evaluator's exception as an error response; a positions request with the evaluator's
/// PointPositionsProvider, or an error when it has none. What `pmsc serve SPEC` runs.
/// @return 0 at end of file; 1 when `in` carried a malformed request or `out` could not be
///         written (the message goes to standard error).
int serve(const PointEvaluator& evaluator, int in, int out);

}  // namespace pmsc::evaluators::exec
