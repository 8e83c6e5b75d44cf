// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"
#include "pmsc/PointEvaluator.h"

#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <vector>

namespace pmsc::examples {

/// How a demo states errors in its local fail-through report: errors are Euclidean over a point's
/// C channels (a face's displacement, a lighting cache's RGB), divided by `unit`.
struct LocalReportScale {
    double unit = 1;   ///< data units per report unit (face: 1% of the head diagonal; Cornell: its tolerance)
    double limit = 1;  ///< frames whose max error passes this are counted
    std::string maxErrorKey = "soft_max_error_pct_bbox_max";  ///< largest point error of the set
    std::string rmsErrorKey =
        "soft_rms_error_pct_bbox";             ///< RMS point error over the set's points and frames
    std::string overKey = "frames_over_1pct";  ///< frames whose largest error passes `limit`
};

/// A frame's full values (N*C doubles into `out`): the reference of the errors. Empty: the
/// evaluator's evaluateAll() (a demo that already holds its full calculations passes them here).
using FullValues = std::function<void(Index frame, double* out)>;

/// Local fail-through on one set of frames, measured both ways against the full evaluation:
/// - errors: the engine with local fail-through (`threads` cores), each output against the full
///   values: largest point error (scale.maxErrorKey), RMS point error (scale.rmsErrorKey), relative
///   RMS error (soft_rms_rel_error), frames over the limit, local frames, fraction of points
///   evaluated fully (mean over the set's frames and over its non-hit frames); the same with
///   whole-frame fail-through (`--whole-frame-fail-through`);
/// - speed: the same frames at ONE thread through the engine with local fail-through, with
///   whole-frame fail-through, and full evaluations (evaluateAll in a one-thread arena), all in
///   this run, timed by process CPU time: seconds per frame and speedups over the full evaluation.
/// Keys: frames, hit_rate, non_hit_frames, local_fail_through, local{...}, whole_frame{...}, clock,
/// one_thread_seconds_per_frame{full_pose, local_fail_through, whole_frame_fail_through},
/// speedup_local, speedup_whole_frame.
/// @param regionsEveryFrame also a third way, "regions_every_frame" (errors, frames_without_gathers,
///        speedup_regions_every_frame): whole-frame thresholds (0, 0), so the regions decide every
///        frame, also those the whole-frame test would accept (an experiment: the engine's rule
///        asks the regions only on frames that do not hit as a whole)
/// @param progress called with the done fraction in [0, 1]; may throw to cancel
nlohmann::json localFailThroughReport(const Model& model, const PointEvaluator& evaluator,
                                      const std::vector<Index>& frames, const LocalReportScale& scale,
                                      int threads, const std::function<void(double done)>& progress = {},
                                      const FullValues& fullValues = {}, bool regionsEveryFrame = false);

}  // namespace pmsc::examples
