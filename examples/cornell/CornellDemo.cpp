#include "examples/cornell/CornellDemo.h"

#include "engine/Engine.h"
#include "evaluators/cornell/CornellEvaluator.h"
#include "evaluators/cornell/LightingCacheGrid.h"
#include "evaluators/scene/Image.h"
#include "examples/common/DemoSetup.h"
#include "examples/common/DemoValidation.h"
#include "examples/cornell/CornellLocalChange.h"
#include "examples/cornell/Renderer.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/SpatialGrid.h"
#include "pmsc/Training.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <numeric>
#include <random>
#include <set>

namespace pmsc::cornell {

using examples::chooseReferenceSubset;
using examples::createOutputFolder;
using examples::DemoClock;
using examples::DemoSetup;
using examples::FolderErrorWording;
using examples::ReferenceSubset;
using examples::RelError;
using examples::secondsSince;
using examples::ValidationSink;

namespace {

float exposureFor(const Image& img) {
    double sum = 0;
    for (std::size_t i = 0; i < img.rgb.size(); i += 3)
        sum += 0.2126 * img.rgb[i] + 0.7152 * img.rgb[i + 1] + 0.0722 * img.rgb[i + 2];
    const double mean = sum / std::max<std::size_t>(1, img.rgb.size() / 3);
    return mean > 0 ? static_cast<float>(0.6 / mean) : 1.0f;
}

std::string frameTag(Index pathFrame) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "path%03ld", static_cast<long>(pathFrame));
    return buf;
}

// --- the steps of runCornellDemo, in the order it runs them ------------------------------------

// A number as a user typed it: 5, not 5.000000.
std::string shortNumber(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

void checkOptions(const CornellDemoOptions& o) {
    if (o.outDir.empty()) throw InputError("demo cornell: --out DIR is required");
    if (o.points < 1000 || o.points > 4000000)
        throw InputError("demo cornell: --points " + std::to_string(o.points) + " outside [1000, 4000000]");
    if (o.samples < 2 || o.samples > 65536)
        throw InputError("demo cornell: --samples " + std::to_string(o.samples) + " outside [2, 65536]");
    if (o.basis < 1 || o.keys < 1 || o.gridKeys < 0 || o.gridKeys > o.keys || o.scatteredLights < 1 ||
        o.pathFrames < 1 || o.pathFullEvery < 1 || o.referenceMultiplier < 1 || o.referencePoints < 1 ||
        o.referenceFrames < 1 || o.imageSize < 8 || o.renderFrames < 0 || o.threads < 0 ||
        !(o.toleranceFraction > 0))
        throw InputError("demo cornell: an option is out of range");
    if (o.regions < 0 || o.regions > 1024)
        throw InputError("demo cornell: --regions " + std::to_string(o.regions) + " outside [0, 1024]");
    if (!(o.featherPercent >= 0 && o.featherPercent <= 50))
        throw InputError("demo cornell: --feather " + shortNumber(o.featherPercent) +
                         " outside [0, 50] (% of the box's diagonal)");
    if (!(o.localChangeMm == 0 || (o.localChangeMm >= 10 && o.localChangeMm <= 150)))
        throw InputError("demo cornell: --local-change " + shortNumber(o.localChangeMm) +
                         " is not 0 (none) or an edge in [10, 150] mm");
    if (o.localChangeMm > 0 && o.regions == 0)
        throw InputError("demo cornell: --local-change needs --regions R > 0 (or --local-change 0)");
    if (o.localChangeMm > 0 && (o.localChangeLights < 1 || o.localChangeLights > o.scatteredLights))
        throw InputError("demo cornell: the local change's lights (" + std::to_string(o.localChangeLights) +
                         ") must be in [1, scattered lights = " + std::to_string(o.scatteredLights) + "]");
}

// 1. The cache's points: surfaces voxelized to about `points` active voxels.
std::shared_ptr<const CornellWorld> voxelizeBox(DemoSetup& run, const CornellDemoOptions& o) {
    const auto t = DemoClock::now();
    run.progress("voxelize", 0, 1);
    auto world = CornellWorld::create(o.points);
    run.lap("voxelize", t);
    return world;
}

// 2. Training frames: one point light each on the 12 x 12 grid below the ceiling, by full gathers.
FrameSet gatherTrainingFrames(DemoSetup& run, const CornellDemoOptions& o,
                              const std::shared_ptr<const CornellWorld>& world, const LightRig& rig) {
    const Index n = static_cast<Index>(world->voxels.size());
    const CornellEvaluator trainEval(world, rig.trainingLights(), o.samples, "cornell-train");
    const Index trainFrames = trainEval.frameCount();
    const auto t = DemoClock::now();
    FrameSet q(trainFrames, n, 3);
    // A row of the rig's lights at a time: each point's gather rays are traced once per call and
    // shaded for each light (evaluateAllFrames), the same frames as one evaluateAll() each.
    const Index perCall = trainEval.framesSharingWork();
    std::vector<Index> frames;
    for (Index f = 0; f < trainFrames; f += perCall) {
        run.progress("training frames", static_cast<double>(f), static_cast<double>(trainFrames));
        frames.resize(static_cast<std::size_t>(std::min(perCall, trainFrames - f)));
        std::iota(frames.begin(), frames.end(), f);
        run.arena.execute([&] { trainEval.evaluateAllFrames(frames, q.frame(f)); });
    }
    run.lap("training_gathers", t);
    return q;
}

// The largest indirect irradiance (Euclidean over RGB) of any point in any training frame.
double peakIrradiance(const FrameSet& q) {
    double peak = 0;
    for (Index i = 0; i < q.frames * q.points; ++i) {
        const double* v = q.values.data() + 3 * i;
        peak = std::max(peak, std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
    }
    return peak;
}

// About `count` key points from a sparse spatial grid over the voxels (section 4).
std::vector<Index> gridKeyPoints(const CornellWorld& world, int count) {
    const Index n = static_cast<Index>(world.voxels.size());
    Eigen::MatrixXd positions(n, 3);
    for (Index i = 0; i < n; ++i) {
        const Vec3 p = world.voxels.position[static_cast<std::size_t>(i)];
        positions.row(i) << p.x, p.y, p.z;
    }
    return sparseGridPointsByCount(positions, count);
}

struct TrainedModel {
    Model model;
    TrainingReport report;
    double peak = 0;                // peakIrradiance() of the training frames
    double tolerance = 0;           // of a hit, toleranceFraction x peak
    std::size_t gridKeyPoints = 0;  // key points asked of the spatial grid
    Index trainFrames = 0;
};

// 3. Train: basis, key points (seeded with a sparse spatial grid), calibrated eps. Training
// consumes the frames (144 x N x 3 doubles), centred where they lie.
TrainedModel trainModel(DemoSetup& run, const CornellDemoOptions& o, const CornellWorld& world, FrameSet q) {
    const auto t = DemoClock::now();
    TrainedModel trained;
    trained.trainFrames = q.frames;
    trained.peak = peakIrradiance(q);
    TrainingOptions topt;
    topt.basis = o.basis;
    topt.maxKeys = o.keys;
    topt.tolerance = o.toleranceFraction * trained.peak;
    if (o.gridKeys > 0) topt.gridPoints = gridKeyPoints(world, o.gridKeys);
    if (o.regions > 0) {
        // Local fail-through: regions clustered on the voxels' positions (RGB values are
        // no positions) and their loading patterns.
        topt.regions.count = o.regions;
        topt.regions.featherFraction = o.featherPercent / 100.0;
        const Index n = static_cast<Index>(world.voxels.size());
        topt.regions.positions.resize(n, 3);
        for (Index i = 0; i < n; ++i) {
            const Vec3 p = world.voxels.position[static_cast<std::size_t>(i)];
            topt.regions.positions.row(i) << p.x, p.y, p.z;
        }
    }
    topt.progress = [&](std::string_view stage, double done, double total) {
        run.progress(std::string("train: ") + std::string(stage), done, total);
        return true;
    };
    // Consumed: training centres the 144 x N x 3 doubles where they lie.
    run.arena.execute([&] { trained.model = train(std::move(q), topt, &trained.report); });
    run.lap("train", t);
    trained.tolerance = topt.tolerance;
    trained.gridKeyPoints = topt.gridPoints.size();
    return trained;
}

// 4. Validation frames: scattered lights, then the animation path; which get a full gather
// (errors measured) and which are rendered.
struct ValidationFrames {
    std::vector<PointLight> lights;  // one per frame
    Index scattered = 0;             // frames [0, scattered) are the scattered lights
    std::set<Index> fullFrames, renderFrames;
};

ValidationFrames chooseValidationFrames(const CornellDemoOptions& o, const LightRig& rig) {
    ValidationFrames v;
    v.lights = rig.scatteredLights(o.scatteredLights);
    v.scattered = static_cast<Index>(v.lights.size());
    for (const PointLight& l : rig.animationPath(o.pathFrames)) v.lights.push_back(l);
    for (Index f = 0; f < v.scattered; ++f) v.fullFrames.insert(f);
    for (Index p = 0; p < o.pathFrames; p += o.pathFullEvery) v.fullFrames.insert(v.scattered + p);
    for (int r = 0; r < o.renderFrames; ++r) {
        Index p = static_cast<Index>(r) * o.pathFrames / std::max(1, o.renderFrames);
        p -= p % o.pathFullEvery;  // a frame that has a full gather
        v.renderFrames.insert(v.scattered + p);
        v.fullFrames.insert(v.scattered + p);
    }
    return v;
}

struct FullGathers {
    std::map<Index, std::vector<double>> full;  // per frame of ValidationFrames::fullFrames
    double secondsPerFrame = 0;
};

FullGathers gatherFullFrames(DemoSetup& run, const CornellEvaluator& valEval,
                             const std::set<Index>& fullFrames) {
    const Index n = valEval.pointCount();
    FullGathers g;
    const auto t = DemoClock::now();
    Index done = 0;
    for (Index f : fullFrames) {
        run.progress("validation full gathers", static_cast<double>(done++),
                     static_cast<double>(fullFrames.size()));
        auto& v = g.full[f];
        v.resize(static_cast<std::size_t>(3 * n));
        run.arena.execute([&] { valEval.evaluateAll(f, v.data()); });
    }
    g.secondsPerFrame = secondsSince(t) / static_cast<double>(fullFrames.size());
    return g;
}

// 5. The validation frames through the engine: key points, projection, soft cache per frame.
engine::RunStats runValidationThroughEngine(DemoSetup& run, const Model& model,
                                            const CornellEvaluator& valEval, ValidationSink& sink) {
    engine::EngineOptions eopt;
    eopt.threads = run.threads;
    eopt.keepPointMultiplication = true;
    // The cache goes out as float grids (.vdb): the float basis, as `pmsc run --format vdb` reads.
    eopt.basisPrecision = BasisPrecision::Single;
    eopt.progress = [&](const engine::Progress& p) {
        run.progress("validation through the engine", static_cast<double>(p.framesDone),
                     static_cast<double>(p.framesTotal));
    };
    engine::Engine eng(model, valEval, eopt);
    return eng.run(engine::FrameRange{0, valEval.frameCount(), 1}, sink);
}

struct ReferenceErrors {
    RelError full, pm;  // the full gather's and PM's against the converged reference
};

// 6. Converged reference (referenceMultiplier x the samples) on the subset, scattered frames.
ReferenceErrors measureAgainstConvergedReference(DemoSetup& run, const CornellDemoOptions& o,
                                                 const std::shared_ptr<const CornellWorld>& world,
                                                 const LightRig& rig, const ReferenceSubset& reference,
                                                 std::map<Index, std::vector<double>>& full,
                                                 ValidationSink& sink) {
    const std::vector<Index>& subset = reference.points;
    const CornellEvaluator refEval(world, rig.scatteredLights(o.scatteredLights),
                                   o.samples * o.referenceMultiplier, "cornell-reference");
    ReferenceErrors errors;
    const auto t = DemoClock::now();
    for (Index f = 0; f < reference.frames; ++f) {
        run.progress("converged reference", static_cast<double>(f), static_cast<double>(reference.frames));
        std::vector<double> ref(3 * subset.size());
        run.arena.execute([&] {
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, subset.size(), 16), [&](const auto& r) {
                refEval.evaluate(f, std::span<const Index>(subset.data() + r.begin(), r.size()),
                                 ref.data() + 3 * r.begin());
            });
        });
        std::vector<double> fullAt(3 * subset.size());
        for (std::size_t i = 0; i < subset.size(); ++i)
            for (int c = 0; c < 3; ++c)
                fullAt[3 * i + c] = full[f][static_cast<std::size_t>(3 * subset[i] + c)];
        errors.full.add(fullAt.data(), ref.data(), ref.size());
        errors.pm.add(sink.pmAtSubset[f].data(), ref.data(), ref.size());
    }
    run.lap("reference", t);
    return errors;
}

// One camera's render of a frame with both grids: DIR/CAMERA_TAG.png (full | PMSC | |diff| x 10)
// and .pfm; returns its entry of "images".
nlohmann::json renderWithBothGrids(DemoSetup& run, const CornellDemoOptions& o, const CornellWorld& world,
                                   const Camera& cam, const PointLight& light,
                                   const LightingCacheGrid& fullGrid, const LightingCacheGrid& pmGrid,
                                   const std::string& tag, Index pathFrame, CacheState state) {
    std::vector<Image> imgs;
    run.arena.execute([&] { imgs = renderWithCaches(world, cam, light, {&fullGrid, &pmGrid}, o.imageSize); });
    const Image diff = absDifference(imgs[0], imgs[1], 10.0f);
    const Image panel = sideBySide({&imgs[0], &imgs[1], &diff});
    const std::string base = o.outDir + "/" + cam.name + "_" + tag;
    writePng(base + ".png", panel, exposureFor(imgs[0]));
    writePfm(base + ".pfm", panel);
    RelError imgErr;
    std::vector<double> a(imgs[1].rgb.begin(), imgs[1].rgb.end()), b(imgs[0].rgb.begin(), imgs[0].rgb.end());
    imgErr.add(a.data(), b.data(), a.size());
    return {{"camera", cam.name},
            {"path_frame", pathFrame},
            {"png", cam.name + "_" + tag + ".png"},
            {"pfm", cam.name + "_" + tag + ".pfm"},
            {"state", toString(state)},
            {"image_rms_rel_error", imgErr.value()}};
}

struct WrittenFiles {
    nlohmann::json images = nlohmann::json::array(), vdbs = nlohmann::json::array();
};

// 7. Lighting-cache grids and renders from the moving cameras.
WrittenFiles writeGridsAndRenders(DemoSetup& run, const CornellDemoOptions& o, const CornellWorld& world,
                                  const ValidationFrames& frames, std::map<Index, std::vector<double>>& full,
                                  ValidationSink& sink) {
    const auto t = DemoClock::now();
    WrittenFiles written;
    const auto cameraCount = demoCameras(0).size();
    Index rendered = 0;
    for (Index f : frames.renderFrames) {
        const Index pathFrame = f - frames.scattered;
        const auto rec = std::find_if(sink.records.begin(), sink.records.end(),
                                      [&](const auto& r) { return r.frame == f; });
        CacheMetadata meta{static_cast<std::int32_t>(f), frames.lights[static_cast<std::size_t>(f)].position,
                           std::string(toString(rec->state)), rec->weight, rec->keyRms};
        const LightingCacheGrid pmGrid(world.voxels, sink.soft[f], meta);
        CacheMetadata fullMeta = meta;
        fullMeta.state = "full";
        fullMeta.weight = 1;
        const LightingCacheGrid fullGrid(world.voxels, full[f], fullMeta);
        const std::string tag = frameTag(pathFrame);
        for (const auto& [name, grid] : {std::pair{"pmsc", &pmGrid}, std::pair{"full", &fullGrid}}) {
            const std::string path = o.outDir + "/cache_" + name + "_" + tag + ".vdb";
            grid->write(path);
            written.vdbs.push_back(std::filesystem::path(path).filename().string());
        }
        const double camT = o.pathFrames > 1 ? static_cast<double>(pathFrame) / (o.pathFrames - 1) : 0.0;
        for (const Camera& cam : demoCameras(camT)) {
            run.progress("renders", static_cast<double>(rendered++),
                         static_cast<double>(frames.renderFrames.size() * cameraCount));
            written.images.push_back(renderWithBothGrids(run, o, world, cam,
                                                         frames.lights[static_cast<std::size_t>(f)], fullGrid,
                                                         pmGrid, tag, pathFrame, rec->state));
        }
    }
    run.lap("grids_and_renders", t);
    return written;
}

// report.json's "frames": each validation frame's decision and, where it had a full gather, errors.
nlohmann::json frameTable(const std::vector<ValidationSink::FrameRecord>& records, Index scattered) {
    nlohmann::json frames = nlohmann::json::array();
    for (const auto& r : records) {
        nlohmann::json fr{{"frame", r.frame},
                          {"kind", r.frame < scattered ? "scattered" : "path"},
                          {"state", toString(r.state)},
                          {"weight", r.weight},
                          {"key_rms", r.keyRms}};
        if (r.pmRelError >= 0) {
            fr["pm_rel_error"] = r.pmRelError;
            fr["soft_rel_error"] = r.softRelError;
        }
        frames.push_back(fr);
    }
    return frames;
}

// Sizes, speed, decisions and errors against the full gathers and the converged reference.
void reportResults(nlohmann::json& report, const CornellDemoOptions& o, Index n, const TrainedModel& trained,
                   Index testFrames, double fullSecondsPerFrame, const engine::RunStats& stats,
                   const ValidationSink& sink, const ValidationFrames& frames,
                   const ReferenceSubset& reference, const ReferenceErrors& refErrors) {
    const double pmscSecondsPerFrame = stats.wallSeconds / static_cast<double>(testFrames);
    report["points"] = n;
    report["key_points"] = trained.model.keyCount();
    report["basis"] = trained.model.basisSize();
    report["train_frames"] = trained.trainFrames;
    report["test_frames"] = testFrames;
    report["samples_per_point"] = o.samples;
    report["full_seconds_per_frame"] = fullSecondsPerFrame;
    report["pmsc_seconds_per_frame"] = pmscSecondsPerFrame;
    report["speedup"] = fullSecondsPerFrame / pmscSecondsPerFrame;
    report["rms_rel_error"] = sink.pmError.value();
    report["soft_rms_rel_error"] = sink.softError.value();
    report["rms_rel_error_scattered"] = sink.pmScattered.value();
    report["rms_rel_error_path"] = sink.pmPath.value();
    report["error_frames"] = frames.fullFrames.size();
    report["hit_rate"] = static_cast<double>(stats.hits) / static_cast<double>(testFrames);
    report["hits"] = stats.hits;
    report["blends"] = stats.blends;
    report["misses"] = stats.misses;
    report["reference_rms_rel_error_full"] = refErrors.full.value();
    report["reference_rms_rel_error_pm"] = refErrors.pm.value();
    report["reference_points"] = reference.points.size();
    report["reference_samples_per_point"] = o.samples * o.referenceMultiplier;
    report["reference_frames"] = reference.frames;
}

// The model and its training, and the set-up of the box.
void reportModelAndSetUp(nlohmann::json& report, const DemoSetup& run, const CornellDemoOptions& o,
                         const CornellWorld& world, const TrainedModel& trained, const LightRig& rig) {
    const Model& model = trained.model;
    report["bounces"] = 1;
    report["voxel_size_mm"] = world.voxels.voxelSizeMm;
    report["grid_key_points"] = trained.gridKeyPoints;
    report["eps_min"] = model.epsMin;
    report["eps_max"] = model.epsMax;
    report["tolerance"] = trained.tolerance;
    report["peak_training_irradiance"] = trained.peak;
    report["energy_captured"] = model.energyCaptured();
    report["train_max_point_residual"] = model.trainMaxPointResidual;
    report["training_warnings"] = trained.report.warnings;
    report["threads"] = run.threads;
    report["light_below_ceiling_mm"] = rig.belowCeilingMm;
    report["quick"] = o.quick;
    report["full"] = o.localFailThroughReport;
}

}  // namespace

CornellDemoOptions CornellDemoOptions::quickOptions() {
    CornellDemoOptions o;
    o.points = 6000;
    o.samples = 32;
    o.gridKeys = 32;
    o.scatteredLights = 8;
    o.pathFullEvery = 6;
    o.referencePoints = 500;
    o.referenceFrames = 4;
    o.imageSize = 128;
    o.renderFrames = 1;
    o.localFailThroughReport = true;
    o.quick = true;
    return o;
}

nlohmann::json runCornellDemo(const CornellDemoOptions& o) {
    const auto start = DemoClock::now();
    checkOptions(o);
    createOutputFolder(o.outDir, FolderErrorWording::CannotCreate);
    DemoSetup run(o.threads > 0 ? o.threads : tbb::info::default_concurrency(), o.progress,
                  "demo cornell: interrupted", start);
    nlohmann::json report;

    const auto world = voxelizeBox(run, o);
    const Index n = static_cast<Index>(world->voxels.size());
    const LightRig rig;
    const TrainedModel trained = trainModel(run, o, *world, gatherTrainingFrames(run, o, world, rig));

    const ValidationFrames frames = chooseValidationFrames(o, rig);
    const CornellEvaluator valEval(world, frames.lights, o.samples, "cornell");
    FullGathers gathers = gatherFullFrames(run, valEval, frames.fullFrames);
    const ReferenceSubset reference =
        chooseReferenceSubset(n, o.referencePoints, frames.scattered, o.referenceFrames, /*seed=*/20070101);

    ValidationSink sink("cornell", gathers.full, frames.renderFrames, reference.points, reference.frameSet);
    sink.scatteredCount = frames.scattered;
    const engine::RunStats stats = runValidationThroughEngine(run, trained.model, valEval, sink);
    const ReferenceErrors refErrors =
        measureAgainstConvergedReference(run, o, world, rig, reference, gathers.full, sink);
    const WrittenFiles written = writeGridsAndRenders(run, o, *world, frames, gathers.full, sink);
    if (trained.model.regions && o.localFailThroughReport) {
        const auto t = DemoClock::now();
        const LocalFailThroughInputs in{
            .model = trained.model,
            .validation = valEval,
            .scattered = frames.scattered,
            .fullGathers = gathers.full,
            .tolerance = trained.tolerance,
            .changeEdgeMm = o.localChangeMm,
            .changeLights = o.localChangeLights,
            .threads = run.threads,
            .inArena = [&](const std::function<void()>& f) { run.arena.execute(f); },
            .progress = [&](std::string_view stage, double done,
                            double total) { run.progress(stage, done, total); }};
        report["local_fail_through"] = measureLocalFailThrough(in);
        run.lap("local_fail_through", t);
    }

    // 8. The report.
    reportResults(report, o, n, trained, valEval.frameCount(), gathers.secondsPerFrame, stats, sink, frames,
                  reference, refErrors);
    reportModelAndSetUp(report, run, o, *world, trained, rig);
    report["engine"] = nlohmann::json::parse(stats.toJson());
    report["frames"] = frameTable(sink.records, frames.scattered);
    report["images"] = written.images;
    report["vdb_files"] = written.vdbs;
    report["seconds"] = run.finish();
    // The model and the scene spec that rebuilds these points: what `pmsc view` and `pmsc run` take.
    writeModel(o.outDir + "/model.pmsc", trained.model);
    writeFileAtomically(o.outDir + "/scene.txt", "cornell:points=" + std::to_string(o.points) +
                                                     ",samples=" + std::to_string(o.samples) + "\n");
    writeFileAtomically(o.outDir + "/report.json", report.dump(2) + "\n");
    run.progress("done", 1, 1);
    return report;
}

}  // namespace pmsc::cornell
