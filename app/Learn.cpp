#include "app/Learn.h"

#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"

#include <algorithm>
#include <chrono>

namespace pmsc::app {

void validate(const LearnOptions& o, Spelling spelling) {
    const auto name = [spelling](std::string_view n) { return optionName(n, spelling); };
    const pmsc::LearnOptions& l = o.learning;
    if (l.basis > 0 && l.energy > 0)
        throw OptionError(name("basis") + " and " + name("energy") + " both set M: give one");
    if (l.coverage && !(*l.coverage > 0 && *l.coverage < 1))
        throw OptionError(name("coverage") + ": must be in (0, 1)");
    if (!(l.energy >= 0 && l.energy <= 1)) throw OptionError(name("energy") + ": must be in (0, 1]");
}

void checkLearnable(const Model& model, const std::string& modelName) {
    if (model.cross)
        throw InputError(modelName +
                         " is a cross model (train --targets): pmsc learn updates plain models; retrain "
                         "on all (control, target) pairs");
    if (model.sharedChannels)
        throw InputError(modelName +
                         " shares one basis among its channels (train --shared-channels): pmsc learn "
                         "updates models with a basis per channel in this version; retrain on all frames");
}

void checkFramesFit(const Model& model, const std::string& modelName, const FrameSet& frames,
                    const std::string& framesName) {
    if (frames.points != model.points || frames.channels != model.channels)
        throw InputError(framesName + ": frames have " + std::to_string(frames.points) + " points x " +
                         std::to_string(frames.channels) + " channels, but the model " + modelName + " has " +
                         std::to_string(model.points) + " x " + std::to_string(model.channels));
}

FrameSet readFrameFiles(const std::vector<std::string>& paths) {
    std::vector<FrameFile> files;
    Index frames = 0;
    for (const auto& p : paths) {
        files.push_back(readFrames(p));
        const FrameSet& f = files.back().frames;
        const FrameSet& first = files.front().frames;
        if (f.points != first.points || f.channels != first.channels)
            throw InputError(p + ": frames have " + std::to_string(f.points) + " points x " +
                             std::to_string(f.channels) + " channels, " + paths.front() + " has " +
                             std::to_string(first.points) + " x " + std::to_string(first.channels));
        frames += f.frames;
    }
    if (files.size() == 1) return std::move(files.front().frames);
    FrameSet all(frames, files.front().frames.points, files.front().frames.channels,
                 FrameSet::Uninitialised{});
    auto at = all.values.begin();
    for (const auto& f : files) at = std::copy(f.frames.values.begin(), f.frames.values.end(), at);
    return all;
}

LearnOutcome learnFiles(const LearnOptions& options, ProgressFn progress) {
    if (!options.out.empty()) AtomicFile(options.out).abandon();  // fails now, not after the work
    const auto start = std::chrono::steady_clock::now();
    LearnOutcome outcome;
    outcome.before = readModel(options.model);
    checkLearnable(outcome.before, options.model);
    pmsc::LearnOptions learning = options.learning;
    if (!options.positions.empty())  // small: read before the frames, so a bad file fails first
        learning.positions =
            positionsFromTable(readPointTable(options.positions).frames, outcome.before.points,
                               "--positions " + options.positions, "learn");
    const FrameSet frames = readFrameFiles(options.frames);
    checkFramesFit(outcome.before, options.model, frames, options.frames.front());
    learning.progress = std::move(progress);
    outcome.learned = learn(outcome.before, frames, learning, &outcome.report);
    if (!options.out.empty()) writeModel(options.out, outcome.learned);
    outcome.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return outcome;
}

}  // namespace pmsc::app
