#include "app/ReplayFiles.h"

#include "app/MemoryLimit.h"
#include "evaluators/ReplayEvaluator.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/KeptFrames.h"

namespace pmsc::app {

void validate(const ReplayFileOptions& o, const Model& model, Spelling spelling) {
    const auto name = [spelling](std::string_view n) { return optionName(n, spelling); };
    if (model.cross) {
        if (o.replay.eps)
            throw OptionError(name("eps") + ": " + o.model +
                              " is a cross model, which has no fail-through to threshold");
        if (!o.keep.empty())
            throw OptionError(name("keep-misses") + ": " + o.model +
                              " is a cross model, which has no misses");
        if (!o.replay.localFailThrough)
            throw OptionError(name("whole-frame-fail-through") + ": " + o.model +
                              " is a cross model, which cannot fail through");
    } else if (!o.targets.empty()) {
        throw OptionError(name("targets") + ": " + o.model + " is not a cross model (pmsc train --targets)");
    }
}

namespace {

/// Cross point multiplication: control frames in, target frames out, no fail-through.
CrossReplayResult replayCrossFiles(const ReplayFileOptions& o, const Model& model) {
    const Index nc = model.cross->controlPoints, nt = model.points - nc;
    const evaluators::ReplayEvaluator control(o.frames);
    if (control.pointCount() != nc || control.channelCount() != model.channels)
        throw InputError(o.frames + ": control frames have " + std::to_string(control.pointCount()) +
                         " points x " + std::to_string(control.channelCount()) +
                         " channels, but the cross model " + o.model + " takes " + std::to_string(nc) +
                         " control points x " + std::to_string(model.channels) + " channels");
    std::optional<evaluators::ReplayEvaluator> truth;
    if (!o.targets.empty()) {
        truth.emplace(o.targets);
        if (truth->pointCount() != nt || truth->channelCount() != model.channels ||
            truth->frameCount() != control.frameCount())
            throw InputError(
                o.targets + ": targets have " + std::to_string(truth->frameCount()) + " frames x " +
                std::to_string(truth->pointCount()) + " points x " + std::to_string(truth->channelCount()) +
                " channels, expected " + std::to_string(control.frameCount()) + " x " + std::to_string(nt) +
                " x " + std::to_string(model.channels) + " (the control frames' count, the model's target)");
    }
    AtomicFile report(o.report);
    std::optional<NpyFrameWriter> out;
    if (!o.out.empty()) out.emplace(o.out, control.frameCount(), nt, model.channels, control.dtype());
    CrossReplayOptions co;
    co.threads = o.replay.threads;
    co.cancel = o.replay.cancel;
    co.progress = o.replay.progress;
    CrossReplayResult result =
        crossReplay(model, control, truth ? &*truth : nullptr, co, out ? &*out : nullptr);
    const std::string text = crossReplayReport(model, result).dump(2) + "\n";
    report.write(text.data(), text.size());
    if (out) out->commit();
    report.commit();
    return result;
}

}  // namespace

ReplayFileOutcome replayFiles(const ReplayFileOptions& o, const Model& model) {
    ReplayFileOutcome outcome;
    if (model.cross) {
        outcome.cross = replayCrossFiles(o, model);
        return outcome;
    }
    const evaluators::ReplayEvaluator recorded(o.frames);
    if (recorded.pointCount() != model.points || recorded.channelCount() != model.channels)
        throw InputError(o.frames + ": frames have " + std::to_string(recorded.pointCount()) + " points x " +
                         std::to_string(recorded.channelCount()) + " channels, but the model " + o.model +
                         " was trained on " + std::to_string(model.points) + " points x " +
                         std::to_string(model.channels) + " channels");
    // Both outputs are temporary files until everything succeeded: a failure or an interrupt
    // leaves neither behind.
    AtomicFile report(o.report);
    std::optional<NpyFrameWriter> out;
    if (!o.out.empty())
        out.emplace(o.out, recorded.frameCount(), recorded.pointCount(), recorded.channelCount(),
                    recorded.dtype());
    ReplayOptions options = o.replay;
    std::optional<KeptFrames> keep;
    if (!o.keep.empty()) {
        keep.emplace(o.keep, recorded.pointCount(), recorded.channelCount(), recorded.dtype(),
                     "model=" + o.model + " frames=" + o.frames);
        options.keep = &*keep;
    }
    // The farm's limit (memory cgroup, ulimit -v), read with the model and the frames mapped.
    options.memoryLimit = frameBufferBudget(environmentMemoryLimit(), options.threads);
    outcome.replay = replay(model, recorded, options, out ? &*out : nullptr);
    const std::string text = replayReport(model, *outcome.replay).dump(2) + "\n";
    report.write(text.data(), text.size());
    if (out) out->commit();
    if (keep) {
        keep->commit();
        outcome.kept = keep->count();
        outcome.keptBefore = keep->countBefore();
    }
    report.commit();
    return outcome;
}

}  // namespace pmsc::app
