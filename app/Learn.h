// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/Train.h"  // Spelling, OptionError
#include "pmsc/FrameSet.h"
#include "pmsc/Learning.h"
#include "pmsc/Model.h"

#include <string>
#include <vector>

namespace pmsc::app {

/// Everything `pmsc learn` and Python's `pmsc.learn` are asked: the model, the new frames, where
/// the learned model goes, and the update's settings (pmsc::LearnOptions, defaults from the model).
struct LearnOptions {
    std::string model;                ///< the model file to update
    std::vector<std::string> frames;  ///< the new frames (.npy), one after the other
    std::string out;                  ///< the learned model, written atomically (empty: not written)
    /// The points' positions the model was trained with (a point table, .npy: --positions); empty:
    /// none. Read into learning.positions by learnFiles.
    std::string positions;
    pmsc::LearnOptions learning;
};

/// Checks the options once for both front ends. @throws OptionError naming the option as
/// `spelling` names it.
void validate(const LearnOptions& options, Spelling spelling);

/// Refuses the models learn cannot update (cross models, shared channels), with one line naming
/// `modelName`. @throws InputError.
void checkLearnable(const Model& model, const std::string& modelName);
/// Refuses new frames whose points or channels are not the model's. @throws InputError.
void checkFramesFit(const Model& model, const std::string& modelName, const FrameSet& frames,
                    const std::string& framesName);

/// The frames of every file, one after the other; all must agree in N and C. @throws InputError.
FrameSet readFrameFiles(const std::vector<std::string>& paths);

/// The model before and after, and what the update said.
struct LearnOutcome {
    Model before, learned;
    LearnReport report;
    double seconds = 0;  ///< wall time of reading, learning and writing
};

/// Reads the model and the frames, learns, and writes `options.out` (when not empty). Fails on an
/// unwritable destination before any work.
LearnOutcome learnFiles(const LearnOptions& options, ProgressFn progress = {});

}  // namespace pmsc::app
