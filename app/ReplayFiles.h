// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/CrossReplay.h"
#include "app/OptionError.h"
#include "app/Replay.h"
#include "pmsc/Model.h"

#include <optional>
#include <string>

namespace pmsc::app {

/// Everything `pmsc replay` is asked: the files in and out and the replay's settings.
struct ReplayFileOptions {
    std::string model;    ///< the model file (read by the caller, named in messages)
    std::string frames;   ///< recorded frames (.npy): the model's points, or a cross model's control
    std::string report;   ///< REPORT.json, written atomically
    std::string out;      ///< soft-cached (or cross target) frames; empty: none
    std::string keep;     ///< --keep-misses: frames that blended or missed appended here; empty: none
    std::string targets;  ///< a cross model's true targets, to measure its bound; empty: none
    ReplayOptions replay;
};

/// The options a model of this kind cannot take (a cross model has no fail-through, a plain model
/// no targets). @throws OptionError naming the option as `spelling` names it.
void validate(const ReplayFileOptions& options, const Model& model, Spelling spelling);

/// What a replay of files did: a soft-cache replay or a cross replay, and the frames kept.
struct ReplayFileOutcome {
    std::optional<ReplayResult> replay;
    std::optional<CrossReplayResult> cross;
    Index kept = 0, keptBefore = 0;  ///< frames appended to `keep`, and those it held before
};

/// Replays the recorded frames through `model` and writes the report (and `out`, `keep`). Every
/// output is a temporary file until everything succeeded: a failure or an interrupt leaves none
/// behind. The frames buffered in flight stay within the environment's memory limit.
/// @throws InputError when the frames do not fit the model; the replay's own errors.
ReplayFileOutcome replayFiles(const ReplayFileOptions& options, const Model& model);

}  // namespace pmsc::app
