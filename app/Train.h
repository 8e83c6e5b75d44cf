// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/OptionError.h"
#include "app/TrainingDefaults.h"
#include "pmsc/Communicator.h"
#include "pmsc/Cross.h"
#include "pmsc/Model.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Training.h"

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace pmsc::app {

/// Everything `pmsc train` and Python's `pmsc.train` are asked, in one struct: the frames, where the
/// model goes, and the training settings with their defaults (defaultTrainingOptions()). The front
/// ends fill it from their arguments; validate() checks it once.
struct TrainOptions {
    std::vector<std::string> frames;  ///< training frames (.npy), one file per shot
    std::string out;                  ///< the model file, written atomically (empty: not written)
    std::string targets;              ///< cross PM's target frames (.npy); empty: a soft-cache model
    /// Point positions (.npy, N x 3 or more columns: the first three are x, y, z), for values that
    /// are not themselves positions (light): the regions, key neighbours and sentinels read them.
    std::string positions;
    TrainingOptions training = defaultTrainingOptions();
    std::optional<double> coverage;  ///< the calibration coverage, when asked for
    std::uint64_t memoryLimit = 0;   ///< bytes training may use; 0: the environment's limit
    Index blockPoints = 0;           ///< points per streamed block; 0: ~64 MiB blocks
    bool outOfCore = false;          ///< stream the frames from disk even when they fit
};

/// Names a front end takes for an enumerated setting. @throws OptionError naming the option.
Selector selectorNamed(const std::string& name, Spelling spelling);
/// "auto" or a region count (0 = none) into `regions`. @throws OptionError naming the option.
void setRegions(RegionOptions& regions, const std::string& value, Spelling spelling);
/// An empty name leaves the choice to TrainingOptions (resolvedCalibrationRule / resolvedKeyErrorNorm).
std::optional<CalibrationRule> calibrationNamed(const std::string& name, Spelling spelling);
std::optional<KeyErrorNorm> keyErrorNamed(const std::string& name, Spelling spelling);

/// Checks the options and their combinations once, for both front ends, and settles what follows
/// from them (shared channels and cross models have no regions; the coverage goes into
/// `training`). Ranges the library checks itself (pmsc::train's preconditions) are not repeated.
/// @throws OptionError with the option named as `spelling` names it.
void validate(TrainOptions& options, Spelling spelling);

/// The frames' sizes over all the shots: N points, C channels, F frames.
struct TrainSizes {
    Index n = 0, c = 0, f = 0;
};

/// In memory or streamed, and how large a block, with the memory bounds (Training.h's).
struct MemoryPlan {
    std::uint64_t limit = 0;          ///< bytes training may use; 0 = none known
    std::string limitSource;          ///< where `limit` comes from, for the messages
    std::uint64_t inMemoryBytes = 0;  ///< the bound of training in memory
    bool stream = false;              ///< the frames are streamed from disk in blocks of points
    Index blockPoints = 0;            ///< points per block when streaming
    std::uint64_t streamBytes = 0;    ///< the bound of streaming blocks of `blockPoints` (rank 0)
};

/// What training from files will do, known from the files' headers alone.
struct TrainPlan {
    std::vector<Shot> shots;
    TrainSizes sizes;
    MemoryPlan memory;
    Eigen::MatrixXd positions;  ///< N x 3 from TrainOptions::positions; empty without
};

/// Opens the shots and decides in memory or streamed (every rank plans with the tightest limit of
/// all, so they take the same decisions). Fails before any frame is read when the destination is
/// not writable, the shots do not match or the limit cannot be met.
TrainPlan planTraining(const TrainOptions& options, Communicator& comm);

/// The first three columns of a point table (one frame of `points` rows of at least 3 values: x, y,
/// z, ...) as the N x 3 positions TrainingOptions::regions and LearnOptions::positions take.
/// @throws InputError naming `command` and `what` for another shape or a value that is not finite.
Eigen::MatrixXd positionsFromTable(const FrameSet& table, Index points, const std::string& what,
                                   std::string_view command = "train");

/// A model trained from files, and what training said about it.
struct TrainOutcome {
    Model model;
    TrainingReport report;
    double seconds = 0;  ///< wall time of planning, reading and training
};

/// Trains from the planned files on this process or the MPI ranks of `comm`; rank 0 writes
/// `options.out` (when not empty). `progress` is TrainingOptions::progress (null: none).
TrainOutcome trainPlanned(const TrainOptions& options, TrainPlan& plan, Communicator& comm,
                          ProgressFn progress = {});

/// A cross model (paper section 7) trained from `options.frames` (the control, one file) and
/// `options.targets`, and what training said.
struct CrossOutcome {
    Model model;
    CrossReport report;
    Index controlPoints = 0, targetPoints = 0, channels = 0, pairs = 0;
    double seconds = 0;  ///< wall time of reading, training and writing
};

/// Trains a cross model and writes `options.out` (when not empty). Fails on an unwritable
/// destination and on pairs that cannot match (frame or channel counts) from the headers, before
/// anything is read.
CrossOutcome trainCrossFiles(const TrainOptions& options, ProgressFn progress = {});

/// The whole training set in memory: the shots read one after the other into one FrameSet.
FrameSet readShots(const std::vector<Shot>& shots);

/// "1.5 GiB" or "512.0 MiB", for the messages and summaries about memory.
std::string bytesText(double bytes);

}  // namespace pmsc::app
