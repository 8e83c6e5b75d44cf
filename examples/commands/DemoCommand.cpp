// `pmsc demo`: the whole method on a shot the program generates, start to end, in seconds.
//
// Until the Cornell box demo exists this is what `./pmsc.sh demo` runs: generate training and test
// frames of a deforming surface (examples/synthetic), train, replay the test frames through the
// soft cache, and measure what the key points buy on the real evaluator.
#include "app/ExitCodes.h"
#include "app/Replay.h"
#include "cli/Args.h"
#include "cli/CommandRegistry.h"
#include "cli/Interrupt.h"
#include "cli/Progress.h"
#include "cli/ReplaySummary.h"
#include "cli/TrainSummary.h"
#include "evaluators/ReplayEvaluator.h"
#include "evaluators/synthetic/SyntheticSurface.h"
#include "examples/commands/DemoCommands.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/Training.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <system_error>
#include <utility>

namespace pmsc::demos {

using namespace pmsc::app;
using namespace pmsc::cli;

namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

std::string fmt(const char* format, double v) {
    char buffer[64];
    std::snprintf(buffer, sizeof buffer, format, v);
    return buffer;
}

/// Milliseconds per frame of the two ways to get a frame from the real evaluator, one
/// thread: all points evaluated, versus key points evaluated + projection + reconstruction.
struct Speed {
    double fullMs = 0, keysMs = 0, pmMs = 0;
};

Speed measureSpeed(const PointEvaluator& evaluator, const Model& model, Index frames) {
    const PointMultiplier multiplier(model);
    std::vector<double> full(static_cast<std::size_t>(model.points * model.channels)), out(full.size());
    std::vector<double> keys(static_cast<std::size_t>(model.keyCount() * model.channels));
    std::vector<double> coords(static_cast<std::size_t>(model.coordCount()));
    Speed s;
    double sink = 0;
    // Repeat until each measurement has run for a while, so the figure is not timer noise.
    Index rounds = 0;
    const auto start = Clock::now();
    do {
        for (Index f = 0; f < frames; ++f) {
            auto t0 = Clock::now();
            evaluator.evaluateAll(f, full.data());
            auto t1 = Clock::now();
            evaluator.evaluate(f, model.keyPoints, keys.data());
            auto t2 = Clock::now();
            multiplier.project(keys.data(), coords.data());
            sink += multiplier.keyError(keys.data(), coords.data());
            multiplier.reconstruct(coords.data(), out.data());
            auto t3 = Clock::now();
            s.fullMs += std::chrono::duration<double, std::milli>(t1 - t0).count();
            s.keysMs += std::chrono::duration<double, std::milli>(t2 - t1).count();
            s.pmMs += std::chrono::duration<double, std::milli>(t3 - t2).count();
            sink += full[0] + out[0];
        }
        ++rounds;
    } while (since(start) < 0.5);
    const double n = static_cast<double>(rounds * frames);
    s.fullMs /= n;
    s.keysMs /= n;
    s.pmMs /= n;
    if (sink == 12345.678) std::cout << "";  // keeps the work observable
    return s;
}

/// What `pmsc demo synthetic` was asked.
struct SyntheticArgs {
    std::string outDir = "pmsc-demo-out";
    synthetic::SurfaceOptions trainShot, testShot;
    double tolerance = 0.02;
    Index maxKeys = 48;
    bool quiet = false;
};

/// Declares the options, parses and checks them; std::nullopt when --help was asked for.
std::optional<SyntheticArgs> parseSyntheticArgs(const std::vector<std::string>& args) {
    SyntheticArgs a;
    synthetic::SurfaceOptions &trainShot = a.trainShot, &testShot = a.testShot;
    trainShot.frames = 1000;
    trainShot.seed = 1;
    testShot.frames = 200;
    testShot.seed = 2;
    testShot.novelFrames = 40;
    ArgParser parser(
        "demo synthetic", "[--out DIR] [options]",
        "Generates a shot of a deforming surface (a sheet with sliding bumps and a twisting\n"
        "\"jaw\"; examples/synthetic), trains a model on one take, replays another take through\n"
        "the soft cache, and prints what happened. The test take ends with a motion the\n"
        "training never saw, which the soft cache must catch. Files go to --out.");
    parser.option("--out", "DIR", "output folder (default pmsc-demo-out)", a.outDir);
    parser.option("--grid", "G", "G x G points (default 64)", [&](const std::string& v) {
        trainShot.grid = testShot.grid = parseIndex("--grid", v, 4, 1024);
    });
    parser.option("--train-frames", "F", "training frames (default 1000)", [&](const std::string& v) {
        trainShot.frames = parseIndex("--train-frames", v, 10, 100000);
    });
    parser.option("--test-frames", "F", "test frames (default 200)",
                  [&](const std::string& v) { testShot.frames = parseIndex("--test-frames", v, 1, 100000); });
    parser.option(
        "--novel-frames", "F", "test frames at the end with the unseen motion (default 40)",
        [&](const std::string& v) { testShot.novelFrames = parseIndex("--novel-frames", v, 0, 100000); });
    parser.option("--tolerance", "T",
                  "largest point error a hit may have (default 0.02, 0.7% of the sheet's diagonal)",
                  [&](const std::string& v) { a.tolerance = parseDouble("--tolerance", v, 1e-12); });
    parser.option("--max-keys", "K", "key point budget (default 48)",
                  [&](const std::string& v) { a.maxKeys = parseIndex("--max-keys", v, 1); });
    parser.flag("--quiet", "no progress display", a.quiet);
    if (!parser.parse(args)) return std::nullopt;
    if (testShot.novelFrames > testShot.frames) parser.fail("--novel-frames exceeds --test-frames");
    return a;
}

/// The files the demo writes, all in --out.
struct DemoFiles {
    std::string trainPath, testPath, modelPath, reportPath, outPath;
};

/// Creates the output folder and names the files in it.
DemoFiles demoFiles(const std::string& outDir) {
    std::error_code error;
    std::filesystem::create_directories(outDir, error);
    if (error) throw IoError(outDir + ": cannot create the folder: " + error.message());
    const auto file = [&](const char* name) { return (std::filesystem::path(outDir) / name).string(); };
    return {file("train.npy"), file("test.npy"), file("model.pmsc"), file("report.json"), file("out.npy")};
}

/// 1. Data: the training and the test take, written to --out and described.
std::pair<FrameFile, FrameFile> generateTakes(const SyntheticArgs& a,
                                              const synthetic::SyntheticSurface& trainRig,
                                              const synthetic::SyntheticSurface& testRig,
                                              const DemoFiles& files) {
    const synthetic::SurfaceOptions &trainShot = a.trainShot, &testShot = a.testShot;
    const std::string &trainPath = files.trainPath, &testPath = files.testPath;
    auto t = Clock::now();
    FrameFile train{evaluateFrames(trainRig, 0, trainShot.frames), NpyDtype::Float64};
    FrameFile test{evaluateFrames(testRig, 0, testShot.frames), NpyDtype::Float64};
    writeFrames(trainPath, train.frames, NpyDtype::Float64);
    writeFrames(testPath, test.frames, NpyDtype::Float64);
    std::cout << "1. generated a " << trainShot.grid << " x " << trainShot.grid
              << " sheet (sliding bumps, a twisting \"jaw\") in " << fmt("%.2f", since(t)) << " s\n"
              << "   training take " << trainPath << ": " << trainShot.frames << " frames x "
              << trainRig.pointCount() << " points x 3\n"
              << "   test take     " << testPath << ": " << testShot.frames
              << " frames, other motion; the last " << testShot.novelFrames
              << " ramp in a pucker of the \"jaw\" never seen in training\n\n";
    return {std::move(train), std::move(test)};
}

/// 2. Train: the model, written to --out, and its summary.
Model trainStep(const SyntheticArgs& a, const FrameSet& frames, const DemoFiles& files,
                TrainingReport& report) {
    const std::string &trainPath = files.trainPath, &modelPath = files.modelPath;
    TrainingOptions options;
    options.tolerance = a.tolerance;
    options.maxKeys = a.maxKeys;
    Model model;
    Clock::time_point t;
    {
        Progress progress("train", !a.quiet);
        options.progress = [&](std::string_view stage, double done, double all) {
            return progress.update(stage, done, all);
        };
        t = Clock::now();
        model = pmsc::train(frames, options, &report);
        writeModel(modelPath, model);
        progress.finish();
    }
    std::cout << "2. pmsc train --frames " << trainPath << " --out " << modelPath << " --max-keys "
              << a.maxKeys << " --tolerance " << a.tolerance << "\n";
    printTrainSummary(std::cout, modelPath, frames, model, report, since(t));
    std::cout << "\n";
    return model;
}

/// 3. Replay: the test take through the soft cache, the report and the output written to --out.
ReplayResult replayStep(const Model& model, FrameFile test, const DemoFiles& files) {
    const std::string &testPath = files.testPath, &modelPath = files.modelPath, &outPath = files.outPath,
                      &reportPath = files.reportPath;
    const evaluators::ReplayEvaluator recorded(std::move(test), testPath);
    ReplayOptions replayOptions;
    replayOptions.cancel = &interruptFlag();
    AtomicFile reportFile(reportPath);
    NpyFrameWriter out(outPath, recorded.frameCount(), recorded.pointCount(), recorded.channelCount(),
                       recorded.dtype());
    ReplayResult result = replay(model, recorded, replayOptions, &out);
    const std::string json = replayReport(model, result).dump(2) + "\n";
    reportFile.write(json.data(), json.size());
    out.commit();
    reportFile.commit();
    std::cout << "3. pmsc replay --model " << modelPath << " --frames " << testPath << " --out " << outPath
              << " --report " << reportPath << "\n";
    printReplaySummary(std::cout, model, result, false);
    return result;
}

/// What the soft cache did with the trained and the unseen motion, and whether it kept the tolerance.
void printTakeOutcome(const SyntheticArgs& a, const ReplayResult& result, const TrainingReport& report) {
    const synthetic::SurfaceOptions& testShot = a.testShot;
    const double tolerance = a.tolerance;
    const Index novelStart = testShot.frames - testShot.novelFrames;
    Index seenHits = 0, novelCaught = 0, novelMisses = 0;
    for (const auto& f : result.frames) {
        if (f.frame < novelStart) {
            seenHits += f.decision.state == CacheState::Hit;
        } else {
            novelCaught += f.decision.state != CacheState::Hit;
            novelMisses += f.decision.state == CacheState::Miss;
        }
    }
    std::cout << "  frames with trained motion: " << seenHits << " of " << novelStart << " hit\n";
    if (testShot.novelFrames > 0)
        std::cout << "  frames with the unseen pucker: " << novelCaught << " of " << testShot.novelFrames
                  << " failed through (" << novelMisses << " full misses, the rest blends)\n";
    // Calibration bounds the point error by r x key error with r measured on held-out TRAINING
    // frames; motion unlike training can have a larger ratio, so say when the tolerance was broken.
    Index over = 0, overSeen = 0;
    double worst = 0, worstRatio = 0;
    for (const auto& f : result.frames) {
        if (f.softMaxPointError <= tolerance) continue;
        ++over;
        overSeen += f.frame < novelStart;
        worst = std::max(worst, f.softMaxPointError);
        if (f.keyRms > 0) worstRatio = std::max(worstRatio, f.pmMaxPointError / f.keyRms);
    }
    if (over == 0) {
        std::cout << "  every soft-cached frame is within the tolerance " << tolerance << "\n";
    } else {
        std::cout << "  " << over << " soft-cached frames exceed the tolerance " << tolerance << " (largest "
                  << fmt("%.4g", worst) << "; " << over - overSeen
                  << " of them with the unseen pucker): their point "
                  << "error is up to " << fmt("%.3g", worstRatio) << " x their key RMS, above the "
                  << fmt("%.3g", report.calibration.ratio) << " x measured on held-out training frames\n";
    }
    std::cout << "\n";
}

/// 4. Speed on the real evaluator (the recorded frames would make the full path a memcpy).
void printSpeed(const synthetic::SyntheticSurface& testRig, const Model& model,
                const synthetic::SurfaceOptions& testShot) {
    const Speed speed = measureSpeed(testRig, model, std::min<Index>(testShot.frames, 50));
    std::cout << "4. speed on the generating evaluator, one thread, per frame:\n"
              << "   full evaluation of " << model.points << " points        " << fmt("%8.3f", speed.fullMs)
              << " ms\n"
              << "   " << model.keyCount() << " key points + projection + PM "
              << fmt("%8.3f", speed.keysMs + speed.pmMs) << " ms (keys " << fmt("%.3f", speed.keysMs)
              << ", PM " << fmt("%.3f", speed.pmMs)
              << ") = " << fmt("%.1f", speed.fullMs / (speed.keysMs + speed.pmMs)) << "x faster on a hit\n\n";
}

}  // namespace

int runDemo(const std::vector<std::string>& args) {
    // `pmsc demo` alone (what ./pmsc.sh demo runs) is the paper's main experiment, the Cornell box
    // (CornellDemoCommand.cpp); with options it is this generated shot.
    if (args.empty()) return runDemoCornell({"--out", "pmsc-demo-cornell"});
    return runDemoSynthetic(args);
}

int runDemoSynthetic(const std::vector<std::string>& args) {
    const std::optional<SyntheticArgs> a = parseSyntheticArgs(args);
    if (!a) return kExitOk;
    const std::string& outDir = a->outDir;
    const DemoFiles files = demoFiles(outDir);

    const auto total = Clock::now();
    std::cout << "pmsc demo: point multiplication and soft caching on a generated shot\n\n";
    const synthetic::SyntheticSurface trainRig(a->trainShot), testRig(a->testShot);
    auto [train, test] = generateTakes(*a, trainRig, testRig, files);
    TrainingReport report;
    const Model model = trainStep(*a, train.frames, files, report);
    const ReplayResult result = replayStep(model, std::move(test), files);
    printTakeOutcome(*a, result, report);
    printSpeed(testRig, model, a->testShot);
    std::cout << "done in " << fmt("%.1f", since(total)) << " s; files in " << outDir << "/\n";
    return kExitOk;
}

// `pmsc demo` and the line `pmsc --help` shows for it.
const cli::CommandRegistration kDemo{
    {"demo", "the main demo (the Cornell box); with options, the generated shot of 'demo synthetic'",
     runDemo}};
const cli::CommandRegistration kDemoSynthetic{
    {"demo synthetic", "train and replay on a generated shot, and print what the soft cache did",
     runDemoSynthetic}};

}  // namespace pmsc::demos
