// `pmsc export-frames`: an evaluator's full frames as a .npy training set (a user's own
// character, posed by skin:ASSET, becomes the frames `pmsc train` learns from).
#include "app/ExitCodes.h"
#include "app/FarmFrames.h"
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/Interrupt.h"
#include "cli/Progress.h"
#include "evaluators/EvaluatorRegistry.h"
#include "pmsc/Errors.h"
#include "pmsc/NpyIO.h"
#include "pmsc/PointPositions.h"
#include "pmsc/Training.h"  // pmsc::Cancelled

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <iostream>
#include <mutex>
#include <optional>

namespace pmsc::cli {

namespace {

/// "skin:ASSET", "cornell", "replay:F.npy" stay as they are; anything else is an asset path
/// for the skin evaluator, so `pmsc export-frames character.glb` does what it says.
std::string specOrAsset(const std::string& text) {
    const std::string name = text.substr(0, text.find(':'));
    for (const auto& kind : evaluators::builtinRegistry().kinds())
        if (kind.name == name) return text;
    return "skin:" + text;
}

}  // namespace

int runExportFrames(const std::vector<std::string>& args) {
    std::string spec, outPath, framesText, positionsPath, dtype = "float64";
    int threads = 0;
    bool quiet = false;
    ArgParser parser("export-frames", "SPEC|ASSET --out FRAMES.npy [--frames A-B[:STEP]] [options]",
                     "Evaluates every point of the chosen frames and writes them as a (frames, points, 3)\n"
                     ".npy file for `pmsc train`. SPEC is an evaluator (skin:ASSET[:fps=F][:animation=A],\n"
                     "face:DIR, cornell, replay:FILE.npy); a plain ASSET path means skin:ASSET. The file\n"
                     "appears only when complete. Default frames: all the evaluator has.");
    parser.positional("SPEC|ASSET", "evaluator spec or animated asset (glTF 2, FBX, Collada, X, BVH, ...)",
                      spec);
    parser.option("--out", "FRAMES.npy", "frames file to write", outPath, true);
    parser.option("--frames", "A-B[:STEP]", "frames to export (default: all)", framesText);
    parser.option("--dtype", "float64|float32", "element type (default float64)", dtype);
    parser.option(
        "--positions", "POINTS.npy",
        "also write the points' positions, (1, points, 3) float64, for `pmsc train --positions` "
        "(evaluators whose values are not positions: cornell, volume, exec children of protocol version 2)",
        positionsPath);
    parser.option(
        "--threads", "T", "worker threads (default: every core; the file does not depend on it)",
        [&](const std::string& v) { threads = static_cast<int>(parseIndex("--threads", v, 1, 4096)); });
    parser.flag("--quiet", "no progress display", quiet);
    if (!parser.parse(args)) return kExitOk;
    NpyDtype type = NpyDtype::Float64;
    try {
        type = parseDtype("--dtype", dtype);
    } catch (const UsageError& e) {
        parser.fail(e.what());
    }

    spec = specOrAsset(spec);
    const std::unique_ptr<PointEvaluator> evaluator = evaluators::makeEvaluator(spec);
    app::FrameSpan span{0, evaluator->frameCount() - 1, 1};
    if (!framesText.empty()) {
        try {
            span = parseFrameSpan("--frames", framesText);
        } catch (const UsageError& e) {
            parser.fail(e.what());
        }
    }
    app::checkFramesInside(span, *evaluator, spec);
    const auto* placed = dynamic_cast<const PointPositionsProvider*>(evaluator.get());
    if (!positionsPath.empty() && placed == nullptr)
        throw InputError("export-frames: --positions: evaluator '" + evaluator->name() +
                         "' has no point positions of its own (values that are positions give theirs by "
                         "their mean: train needs no --positions)");
    const Index n = evaluator->pointCount(), c = evaluator->channelCount(), count = span.count();
    // The positions first: an evaluator that cannot give them (an exec child of protocol version 1)
    // fails before any frame is computed or written. Both files are renamed into place at the end.
    std::optional<NpyFrameWriter> positionsWriter;
    if (!positionsPath.empty()) {
        const FrameSet positions = placed->pointPositions();
        if (positions.values.size() != static_cast<std::size_t>(n) * 3)
            throw EvaluatorError("export-frames: --positions: evaluator '" + evaluator->name() + "' gave " +
                                 std::to_string(positions.values.size()) + " position values for " +
                                 std::to_string(n) + " points");
        positionsWriter.emplace(positionsPath, 1, n, 3, NpyDtype::Float64);
        positionsWriter->writeFrame(0, positions.values.data());
    }

    NpyFrameWriter writer(outPath, count, n, c, type);  // a temporary file until commit()
    Progress progress("export-frames", !quiet);
    std::mutex progressMutex;
    std::atomic<Index> done{0};
    const std::atomic<bool>& stop = interruptFlag();

    // Frames are independent: evaluate them in parallel, each into its own place in the file. An
    // evaluator whose frames share work (framesSharingWork) gets them in groups of that many, as
    // large as 256 MB of values allow, one group at a time: it spreads each group's points over the
    // threads itself, and one group's buffer is all the memory the export holds beside the file.
    const std::size_t frameValues = static_cast<std::size_t>(n * c);
    const Index byMemory =
        std::max<Index>(1, static_cast<Index>((std::size_t{256} << 20) / (8 * frameValues)));
    const Index group = std::clamp<Index>(evaluator->framesSharingWork(), 1, byMemory);
    const Index groups = (count + group - 1) / group;
    auto exportGroup = [&](Index g, std::vector<Index>& frames, std::vector<double>& buffer) {
        if (stop.load(std::memory_order_relaxed)) throw Cancelled("export-frames interrupted");
        frames.clear();
        for (Index i = g * group; i < std::min(count, (g + 1) * group); ++i) frames.push_back(span.frame(i));
        buffer.resize(frames.size() * frameValues);
        try {
            evaluator->evaluateAllFrames(frames, buffer.data());
        } catch (const InputError&) {
            throw;
        } catch (const std::exception& e) {
            const std::string which = frames.size() == 1 ? "frame " + std::to_string(frames.front())
                                                         : "frames " + std::to_string(frames.front()) +
                                                               " to " + std::to_string(frames.back());
            throw EvaluatorError(which + ": " + evaluator->name() + ": " + e.what());
        }
        for (std::size_t k = 0; k < frames.size(); ++k)
            writer.writeFrame(g * group + static_cast<Index>(k), buffer.data() + k * frameValues);
        const Index d = done += static_cast<Index>(frames.size());
        if (std::unique_lock lock(progressMutex, std::try_to_lock); lock)
            progress.update("frames", static_cast<double>(d), static_cast<double>(count));
    };
    tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
    arena.execute([&] {
        if (group > 1) {
            std::vector<Index> frames;
            std::vector<double> buffer;
            for (Index g = 0; g < groups; ++g) exportGroup(g, frames, buffer);
            return;
        }
        tbb::parallel_for(tbb::blocked_range<Index>(0, groups, 1), [&](const tbb::blocked_range<Index>& r) {
            std::vector<Index> frames;
            std::vector<double> buffer;
            for (Index g = r.begin(); g < r.end(); ++g) exportGroup(g, frames, buffer);
        });
    });
    progress.finish();
    writer.commit();
    std::cout << "pmsc export-frames: " << outPath << ": " << count << " frames x " << n << " points x " << c
              << " channels of " << spec << " (frames " << span.text() << ")\n";
    if (positionsWriter) {
        positionsWriter->commit();
        std::cout << "pmsc export-frames: " << positionsPath << ": positions of the " << n << " points\n";
    }
    return kExitOk;
}

}  // namespace pmsc::cli
