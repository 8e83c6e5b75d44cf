// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"
#include "pmsc/NpyIO.h"
#include "pmsc/SoftCache.h"

#include <string>
#include <vector>

namespace pmsc {

/// The frames a soft cache sent to the full calculation, kept as training for `pmsc learn`
/// (paper section 5: "poses identified as cache misses can be tagged and used as additional
/// training"; `pmsc replay|run --keep-misses FILE.npy`).
///
/// Files: FILE.npy, frames (F, N, C) like any training file, and the sidecar FILE.npy.frames,
/// text, one tab-separated line per frame in the same order after a '#' header:
/// `frame  state  key_rms  source` (frame number in the shot, "blend" or "miss", the key RMS
/// error that decided it, and where it came from: the model and the frames file or evaluator).
/// Appendable: a later run adds its frames after the ones already there (same N, C and dtype),
/// so a day's runs, or a farm's tasks run one after the other, collect into one file.
///
/// Decision: kept are blends and misses, the frames that were computed fully; a blend's full
/// values (not the blended output) are what is kept, since they are the truth to learn from.
/// Frames are held in memory until commit() (N*C doubles each); commit() writes FILE.npy as
/// the old frames (copied from a memory map, never loaded whole) followed by the new ones, then
/// the sidecar, each atomically, so an interrupted run leaves the previous files as they were.
class KeptFrames {
public:
    /// Checks at once, before any work, that `path` can be appended to: if it exists it must be
    /// a valid frames file of `points` x `channels` in `dtype`, and its sidecar must exist and
    /// list exactly its frame count.
    /// @throws InputError naming the file and the problem.
    KeptFrames(std::string path, Index points, Index channels, NpyDtype dtype, std::string source);

    /// Keeps one frame (N*C doubles). Not thread-safe: call from one serial sink.
    void add(Index frame, CacheState state, double keyRms, const double* values);

    Index count() const { return static_cast<Index>(frames_.size()); }
    Index countBefore() const { return before_; }
    const std::string& path() const { return path_; }
    static std::string sidecarPath(const std::string& path) { return path + ".frames"; }

    /// Appends the kept frames to the files (creating them if needed). Nothing is written when
    /// no frame was kept. @throws IoError naming the path.
    void commit();

private:
    std::string path_;
    Index points_, channels_;
    NpyDtype dtype_;
    std::string source_;
    Index before_ = 0;
    std::vector<Index> frames_;
    std::vector<std::string> lines_;
    std::vector<double> values_;
};

/// The frame numbers listed in a sidecar (KeptFrames), in order.
/// @throws InputError for a missing or malformed sidecar.
std::vector<Index> readKeptFrameNumbers(const std::string& npyPath);

}  // namespace pmsc
