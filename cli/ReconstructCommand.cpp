// `pmsc reconstruct`: the soft cache driven pass by pass through files, for a renderer that bakes
// values at the points it is given (app/Passes.h, docs/passes.md).
#include "app/Passes.h"
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/Interrupt.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"

#include <cstdint>
#include <cstring>
#include <iostream>
#include <memory>
#include <optional>

namespace pmsc::cli {

namespace {

/// What `pmsc reconstruct` was asked.
struct ReconstructArgs {
    std::string modelPath, keysPath, outPath, reportPath, pointsPath, plyPath;
    std::vector<std::string> answerPaths;
    app::PassOptions options;
    bool wholeFrame = false;
};

std::optional<ReconstructArgs> parseReconstructArgs(const std::vector<std::string>& args) {
    ReconstructArgs a;
    ArgParser parser(
        "reconstruct",
        "--model MODEL.pmsc --keys KEYS.npy [--full FULL.npy ...] --out OUT.npy --report REPORT.json "
        "[options]",
        "Drives the soft cache pass by pass through files, for a renderer that bakes values at the\n"
        "points it is given. KEYS.npy holds each frame's values at the model's key points\n"
        "(frames, keys, channels), in the order of `pmsc inspect MODEL --json`'s key_indices. The report\n"
        "says per frame hit, blend or miss and `needs`: the points whose full values the next pass\n"
        "must compute. Give each pass's answer as one more --full (frames, points, channels), in pass\n"
        "order; only the entries a pass asked for are read. When no frame needs anything, OUT.npy\n"
        "equals `pmsc replay`'s output on the same frames, byte for byte; until then a waiting frame\n"
        "holds its point-multiplication estimate.");
    parser.option("--model", "MODEL.pmsc", "model from pmsc train", a.modelPath, true);
    parser.option("--keys", "KEYS.npy", "key values (frames, keys, channels), float32/64", a.keysPath, true);
    parser.option("--full", "FULL.npy",
                  "the answer to one pass: (frames, points, channels), read only where the pass asked; "
                  "repeat, in pass order",
                  [&](const std::string& v) { a.answerPaths.push_back(v); });
    parser.repeatable("--full");
    parser.option("--out", "OUT.npy", "soft-cached frames to write (the dtype of --keys)", a.outPath, true);
    parser.option("--report", "REPORT.json", "report to write: states and each frame's needs", a.reportPath,
                  true);
    parser.option("--points", "POSITIONS.npy",
                  "positions of the model's points (points, 3): also write the next pass's needs as a PLY "
                  "point cloud",
                  a.pointsPath);
    parser.option("--needs-ply", "NEEDS.ply",
                  "where the needs go as points (default: REPORT with .ply for .json); needs --points",
                  a.plyPath);
    parser.option("--eps", "MIN,MAX",
                  "override the model's thresholds (in its key error, which pmsc inspect names; data units)",
                  [&](const std::string& v) {
                      const auto eps = parseDoublePair("--eps", v);
                      if (!(eps.first >= 0 && eps.first <= eps.second))
                          throw UsageError("--eps: need 0 <= MIN <= MAX, got " + v);
                      a.options.eps = eps;
                  });
    parser.option("--threads", "T", "worker threads (default: every core; results do not depend on it)",
                  [&](const std::string& v) {
                      a.options.threads = static_cast<int>(parseIndex("--threads", v, 1, 4096));
                  });
    parser.flag("--whole-frame-fail-through",
                "models with regions: a frame that does not hit asks for every point (as `pmsc replay "
                "--whole-frame-fail-through`)",
                a.wholeFrame);
    if (!parser.parse(args)) return std::nullopt;
    a.options.localFailThrough = !a.wholeFrame;
    if (!a.plyPath.empty() && a.pointsPath.empty()) parser.fail("--needs-ply: needs --points POSITIONS.npy");
    if (!a.pointsPath.empty() && a.plyPath.empty()) {
        const std::string& r = a.reportPath;
        const bool json = r.size() > 5 && r.compare(r.size() - 5, 5, ".json") == 0;
        a.plyPath = (json ? r.substr(0, r.size() - 5) : r) + ".ply";
    }
    return a;
}

/// The positions of the model's points, checked against it.
FrameSet readPositions(const std::string& path, const Model& model) {
    FrameFile table = readPointTable(path);
    if (table.frames.points != model.points || table.frames.channels != 3)
        throw InputError(path + ": positions of " + std::to_string(table.frames.points) + " points x " +
                         std::to_string(table.frames.channels) + ", expected (" +
                         std::to_string(model.points) + ", 3): x, y, z of each of the model's points");
    return std::move(table.frames);
}

/// The next pass's needs as one binary PLY point cloud: x, y, z, the frame and the point index.
std::string needsPly(const app::PassResult& result, const FrameSet& positions) {
    const Index count = result.pointsNeeded();
    std::string out =
        "ply\nformat binary_little_endian 1.0\n"
        "comment pmsc reconstruct: the points the next pass needs\n"
        "element vertex " +
        std::to_string(count) +
        "\nproperty float x\nproperty float y\nproperty float z\n"
        "property int frame\nproperty int index\nend_header\n";
    for (const app::PassFrame& f : result.frames) {
        for (const Index p : f.needs) {
            const double* xyz = positions.frame(0) + p * 3;
            const float v[3] = {static_cast<float>(xyz[0]), static_cast<float>(xyz[1]),
                                static_cast<float>(xyz[2])};
            const std::int32_t ids[2] = {static_cast<std::int32_t>(f.frame), static_cast<std::int32_t>(p)};
            out.append(reinterpret_cast<const char*>(v), sizeof v);
            out.append(reinterpret_cast<const char*>(ids), sizeof ids);
        }
    }
    return out;
}

void printSummary(const app::PassResult& r, const ReconstructArgs& a) {
    const Index frames = static_cast<Index>(r.frames.size()), done = r.framesDone();
    std::cout << "pmsc reconstruct: " << frames << " frames, " << r.answersGiven << " answered passes\n"
              << "  done        " << done << " frames\n"
              << "  waiting     " << frames - done << " frames, " << r.pointsNeeded()
              << " points for the next pass\n"
              << "  report      " << a.reportPath << "\n  output      " << a.outPath << "\n";
    if (!a.pointsPath.empty()) std::cout << "  needs       " << a.plyPath << "\n";
}

}  // namespace

int runReconstruct(const std::vector<std::string>& args) {
    const std::optional<ReconstructArgs> a = parseReconstructArgs(args);
    if (!a) return kExitOk;
    const Model model = readModel(a->modelPath);
    if (model.cross)
        ArgParser("reconstruct", "", "")
            .fail(a->modelPath + " is a cross model, which has no fail-through to drive pass by pass");
    const FrameFile keys = readFrames(a->keysPath);
    if (keys.frames.points != model.keyCount() || keys.frames.channels != model.channels)
        throw InputError(a->keysPath + ": " + std::to_string(keys.frames.points) + " points x " +
                         std::to_string(keys.frames.channels) + " channels, but the model " + a->modelPath +
                         " has " + std::to_string(model.keyCount()) + " key points x " +
                         std::to_string(model.channels) + " channels");
    std::vector<std::unique_ptr<MappedFrames>> files;
    std::vector<const MappedFrames*> answers;
    for (const std::string& path : a->answerPaths) {
        files.push_back(std::make_unique<MappedFrames>(path, MappedFrames::ValueCheck::None));
        answers.push_back(files.back().get());
    }
    std::optional<FrameSet> positions;
    if (!a->pointsPath.empty()) positions = readPositions(a->pointsPath, model);

    // Every output is a temporary file until everything succeeded.
    AtomicFile report(a->reportPath);
    std::optional<AtomicFile> ply;
    if (positions) ply.emplace(a->plyPath);
    NpyFrameWriter out(a->outPath, keys.frames.frames, model.points, model.channels, keys.dtype);
    app::PassOptions options = a->options;
    options.cancel = &interruptFlag();
    const app::PassResult result = app::reconstructPasses(model, keys.frames, answers, options, &out);

    const std::string text = app::passReport(model, result).dump(2) + "\n";
    report.write(text.data(), text.size());
    if (ply) {
        const std::string cloud = needsPly(result, *positions);
        ply->write(cloud.data(), cloud.size());
    }
    out.commit();
    if (ply) ply->commit();
    report.commit();
    printSummary(result, *a);
    return kExitOk;
}

}  // namespace pmsc::cli
