// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/FarmFrames.h"
#include "pmsc/Model.h"
#include "pmsc/NpyIO.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/PointMultiplier.h"  // BasisPrecision
#include "pmsc/Training.h"         // ProgressFn

#include <atomic>
#include <optional>
#include <string>

namespace pmsc::app {

/// What `pmsc run` was asked to do (a render-farm task).
struct RunOptions {
    std::string modelPath;               ///< for the stats only (the model is passed in)
    std::string evaluatorSpec;           ///< NAME[:ARGS], for the stats only
    FrameSpan frames;                    ///< the task's frames
    std::string outDir;                  ///< one file per frame goes here
    std::string format = "npy";          ///< "npy" or an extension the evaluator offers ("obj", "vdb")
    NpyDtype dtype = NpyDtype::Float64;  ///< of .npy frames
    /// The basis a hit's reconstruction reads; empty: runBasisPrecision's choice for the format.
    std::optional<BasisPrecision> basisPrecision;
    std::string statsPath;               ///< empty: OUT/pmsc-run.<A-B>.json
    int threads = 0;                     ///< 0: every core
    std::uint64_t memoryLimit = 0;       ///< bytes the frames in flight may hold; 0 = no limit
    bool force = false;                  ///< redo frames whose output is already valid
    bool wholeFrameFailThrough = false;  ///< models with regions: no local fail-through
    /// Called as frames are delivered ("D/T frames, F frames/s, hits H%", done, total), at most ten
    /// times a second; returning false does not stop the run (`cancel` does). Null: none.
    ProgressFn progress;
    std::string commandLine;                    ///< as typed, for the stats
    const std::atomic<bool>* cancel = nullptr;  ///< set by another thread (SIGINT/SIGTERM) to stop
    /// Non-empty: append the frames that blended or missed (full values) to this .npy
    /// (`--keep-misses`, pmsc::KeptFrames), also when the run fails or is interrupted afterwards.
    std::string keepMisses;
};

/// What a run did; also written, with per-frame states and timings, to the stats file.
struct RunReport {
    Index frames = 0;            ///< in the task's range
    Index evaluated = 0;         ///< frames run through the engine and written
    Index skipped = 0;           ///< frames whose valid output was already there
    Index replaced = 0;          ///< frames whose existing output was invalid (redone)
    Index staleTemporaries = 0;  ///< temporary files of a killed run, removed
    Index hits = 0, blends = 0, misses = 0;
    Index kept = 0;      ///< frames appended to options.keepMisses
    double seconds = 0;  ///< wall time of the whole run
    std::string statsPath;
};

/// The basis precision a run reconstructs with: options.basisPrecision when given, else Single when
/// every frame is stored in float (.vdb, .npy float32) and Double otherwise. Why: a hit's time on a
/// large cache is the pass over the basis, and the float basis halves its bytes; its values
/// differ from the double's by about 1e-7 relative, the rounding the float file applies anyway.
BasisPrecision runBasisPrecision(const RunOptions& options);

/// The stats file's default name for a range: OUT/pmsc-run.A-B.json (":S" -> "_byS").
std::string defaultStatsPath(const std::string& outDir, const FrameSpan& frames);

/// Runs the task's frames of `evaluator` through the soft-caching engine and writes
/// one file per frame (FrameOutput: atomic, resumable). Frames whose output exists and is valid
/// are skipped unless options.force.
///
/// Checks, in this order, before any evaluation or any file is written:
/// evaluator N and C == the model's (InputError), frames inside 0..frameCount()-1 (InputError),
/// the format is npy or offered by the evaluator (OptionError), the output folder can be created
/// and written (IoError).
/// Afterwards the stats JSON is written atomically, also when the run then fails (evaluator
/// failure, I/O failure, interruption: "status" and "error" say which), and the error rethrown.
/// @throws InputError, OptionError, IoError, EvaluatorError, pmsc::Cancelled.
RunReport runFrames(const Model& model, const PointEvaluator& evaluator, const RunOptions& options);

}  // namespace pmsc::app
