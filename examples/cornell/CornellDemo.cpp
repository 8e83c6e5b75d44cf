#include "examples/cornell/CornellDemo.h"

#include "engine/Engine.h"
#include "examples/cornell/CornellEvaluator.h"
#include "examples/cornell/DemoValidation.h"
#include "examples/cornell/ImageIO.h"
#include "examples/cornell/LightingCacheGrid.h"
#include "examples/cornell/Renderer.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/SpatialGrid.h"
#include "pmsc/Training.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <numeric>
#include <random>
#include <set>

namespace pmsc::cornell {

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

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
    o.quick = true;
    return o;
}

nlohmann::json runCornellDemo(const CornellDemoOptions& o) {
    const auto start = Clock::now();
    if (o.outDir.empty()) throw InputError("demo cornell: --out DIR is required");
    if (o.points < 1000 || o.points > 4000000)
        throw InputError("demo cornell: --points " + std::to_string(o.points) + " outside [1000, 4000000]");
    if (o.samples < 2 || o.samples > 65536)
        throw InputError("demo cornell: --samples " + std::to_string(o.samples) + " outside [2, 65536]");
    if (o.basis < 1 || o.keys < 1 || o.gridKeys < 0 || o.gridKeys > o.keys || o.scatteredLights < 1 ||
        o.pathFrames < 1 || o.pathFullEvery < 1 || o.referenceMultiplier < 1 || o.referencePoints < 1 || o.referenceFrames < 1 ||
        o.imageSize < 8 || o.renderFrames < 0 || o.threads < 0 || !(o.toleranceFraction > 0))
        throw InputError("demo cornell: an option is out of range");
    {
        std::error_code ec;
        std::filesystem::create_directories(o.outDir, ec);
        if (ec || !std::filesystem::is_directory(o.outDir))
            throw IoError("cannot create " + o.outDir + ": " + (ec ? ec.message() : "not a directory"));
    }
    const int threads = o.threads > 0 ? o.threads : tbb::info::default_concurrency();
    tbb::task_arena arena(threads);
    auto progress = [&](std::string_view stage, double done, double total) {
        if (o.progress && !o.progress(stage, done, total)) throw Cancelled("demo cornell: interrupted");
    };
    nlohmann::json report;
    nlohmann::json timings;

    // 1. The cache's points: surfaces voxelized to about `points` active voxels.
    auto t = Clock::now();
    progress("voxelize", 0, 1);
    const auto world = CornellWorld::create(o.points);
    const Index n = static_cast<Index>(world->voxels.size());
    timings["voxelize"] = secondsSince(t);

    // 2. Training frames: one point light each on the 12 x 12 grid below the ceiling.
    const LightRig rig;
    const CornellEvaluator trainEval(world, rig.trainingLights(), o.samples, "cornell-train");
    const Index trainFrames = trainEval.frameCount();
    t = Clock::now();
    FrameSet q(trainFrames, n, 3);
    for (Index f = 0; f < trainFrames; ++f) {
        progress("training frames", static_cast<double>(f), static_cast<double>(trainFrames));
        arena.execute([&] { trainEval.evaluateAll(f, q.frame(f)); });
    }
    const double trainGatherSeconds = secondsSince(t);
    timings["training_gathers"] = trainGatherSeconds;

    // 3. Train: basis, key points (seeded with a sparse spatial grid), calibrated eps.
    t = Clock::now();
    double peak = 0;
    for (Index i = 0; i < q.frames * n; ++i) {
        const double* v = q.values.data() + 3 * i;
        peak = std::max(peak, std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
    }
    TrainingOptions topt;
    topt.basis = o.basis;
    topt.maxKeys = o.keys;
    topt.tolerance = o.toleranceFraction * peak;
    if (o.gridKeys > 0) {
        Eigen::MatrixXd positions(n, 3);
        for (Index i = 0; i < n; ++i) {
            const Vec3 p = world->voxels.position[static_cast<std::size_t>(i)];
            positions.row(i) << p.x, p.y, p.z;
        }
        topt.gridPoints = sparseGridPointsByCount(positions, o.gridKeys);
    }
    topt.progress = [&](std::string_view stage, double done, double total) {
        progress(std::string("train: ") + std::string(stage), done, total);
        return true;
    };
    TrainingReport trep;
    Model model;
    arena.execute([&] { model = train(q, topt, &trep); });
    q = FrameSet();  // 144 x N x 3 doubles: not needed any more
    timings["train"] = secondsSince(t);

    // 4. Validation frames: scattered lights, then the animation path. Full gathers of the
    // frames whose errors are measured and that are rendered.
    std::vector<PointLight> lights = rig.scatteredLights(o.scatteredLights);
    const Index scattered = static_cast<Index>(lights.size());
    for (const PointLight& l : rig.animationPath(o.pathFrames)) lights.push_back(l);
    const CornellEvaluator valEval(world, lights, o.samples, "cornell");
    const Index testFrames = valEval.frameCount();
    std::set<Index> fullFrames, renderFrames;
    for (Index f = 0; f < scattered; ++f) fullFrames.insert(f);
    for (Index p = 0; p < o.pathFrames; p += o.pathFullEvery) fullFrames.insert(scattered + p);
    for (int r = 0; r < o.renderFrames; ++r) {
        Index p = static_cast<Index>(r) * o.pathFrames / std::max(1, o.renderFrames);
        p -= p % o.pathFullEvery;  // a frame that has a full gather
        renderFrames.insert(scattered + p);
        fullFrames.insert(scattered + p);
    }
    std::map<Index, std::vector<double>> full;
    t = Clock::now();
    Index done = 0;
    for (Index f : fullFrames) {
        progress("validation full gathers", static_cast<double>(done++), static_cast<double>(fullFrames.size()));
        auto& v = full[f];
        v.resize(static_cast<std::size_t>(3 * n));
        arena.execute([&] { valEval.evaluateAll(f, v.data()); });
    }
    const double fullSecondsPerFrame = secondsSince(t) / static_cast<double>(fullFrames.size());

    // Reference subset (fixed seed): a few thousand random points.
    std::vector<Index> subset(static_cast<std::size_t>(n));
    std::iota(subset.begin(), subset.end(), Index{0});
    std::mt19937 rng(20070101);
    std::shuffle(subset.begin(), subset.end(), rng);
    subset.resize(std::min<std::size_t>(subset.size(), static_cast<std::size_t>(o.referencePoints)));
    std::sort(subset.begin(), subset.end());
    const Index referenceFrames = std::min<Index>(scattered, o.referenceFrames);
    std::set<Index> subsetFrames;
    for (Index f = 0; f < referenceFrames; ++f) subsetFrames.insert(f);

    // 5. The validation frames through the engine: key points, projection, soft cache per frame.
    ValidationSink sink("cornell", full, renderFrames, subset, subsetFrames);
    sink.scatteredCount = scattered;
    engine::EngineOptions eopt;
    eopt.threads = threads;
    eopt.keepPointMultiplication = true;
    eopt.progress = [&](const engine::Progress& p) {
        progress("validation through the engine", static_cast<double>(p.framesDone), static_cast<double>(p.framesTotal));
    };
    engine::Engine eng(model, valEval, eopt);
    const engine::RunStats stats = eng.run(engine::FrameRange{0, testFrames, 1}, sink);
    const double pmscSecondsPerFrame = stats.wallSeconds / static_cast<double>(testFrames);

    // 6. Converged reference (referenceMultiplier x the samples) on the subset, scattered frames.
    const CornellEvaluator refEval(world, rig.scatteredLights(o.scatteredLights), o.samples * o.referenceMultiplier,
                                   "cornell-reference");
    RelError refFull, refPm;
    t = Clock::now();
    for (Index f = 0; f < referenceFrames; ++f) {
        progress("converged reference", static_cast<double>(f), static_cast<double>(referenceFrames));
        std::vector<double> ref(3 * subset.size());
        arena.execute([&] {
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, subset.size(), 16), [&](const auto& r) {
                refEval.evaluate(f, std::span<const Index>(subset.data() + r.begin(), r.size()), ref.data() + 3 * r.begin());
            });
        });
        std::vector<double> fullAt(3 * subset.size());
        for (std::size_t i = 0; i < subset.size(); ++i)
            for (int c = 0; c < 3; ++c) fullAt[3 * i + c] = full[f][static_cast<std::size_t>(3 * subset[i] + c)];
        refFull.add(fullAt.data(), ref.data(), ref.size());
        refPm.add(sink.pmAtSubset[f].data(), ref.data(), ref.size());
    }
    timings["reference"] = secondsSince(t);

    // 7. Lighting-cache grids and renders from the moving cameras.
    t = Clock::now();
    nlohmann::json images = nlohmann::json::array(), vdbs = nlohmann::json::array();
    const auto cameraCount = demoCameras(0).size();
    Index rendered = 0;
    for (Index f : renderFrames) {
        const Index pathFrame = f - scattered;
        const auto rec = std::find_if(sink.records.begin(), sink.records.end(), [&](const auto& r) { return r.frame == f; });
        CacheMetadata meta{static_cast<std::int32_t>(f), lights[static_cast<std::size_t>(f)].position,
                           std::string(toString(rec->state)), rec->weight, rec->keyRms};
        const LightingCacheGrid pmGrid(world->voxels, sink.soft[f], meta);
        CacheMetadata fullMeta = meta;
        fullMeta.state = "full";
        fullMeta.weight = 1;
        const LightingCacheGrid fullGrid(world->voxels, full[f], fullMeta);
        const std::string tag = frameTag(pathFrame);
        for (const auto& [name, grid] : {std::pair{"pmsc", &pmGrid}, std::pair{"full", &fullGrid}}) {
            const std::string path = o.outDir + "/cache_" + name + "_" + tag + ".vdb";
            grid->write(path);
            vdbs.push_back(std::filesystem::path(path).filename().string());
        }
        const double camT = o.pathFrames > 1 ? static_cast<double>(pathFrame) / (o.pathFrames - 1) : 0.0;
        for (const Camera& cam : demoCameras(camT)) {
            progress("renders", static_cast<double>(rendered++), static_cast<double>(renderFrames.size() * cameraCount));
            std::vector<Image> imgs;
            arena.execute([&] {
                imgs = renderWithCaches(*world, cam, lights[static_cast<std::size_t>(f)], {&fullGrid, &pmGrid}, o.imageSize);
            });
            const Image diff = absDifference(imgs[0], imgs[1], 10.0f);
            const Image panel = sideBySide({&imgs[0], &imgs[1], &diff});
            const std::string base = o.outDir + "/" + cam.name + "_" + tag;
            writePng(base + ".png", panel, exposureFor(imgs[0]));
            writePfm(base + ".pfm", panel);
            RelError imgErr;
            std::vector<double> a(imgs[1].rgb.begin(), imgs[1].rgb.end()), b(imgs[0].rgb.begin(), imgs[0].rgb.end());
            imgErr.add(a.data(), b.data(), a.size());
            images.push_back({{"camera", cam.name}, {"path_frame", pathFrame}, {"png", cam.name + "_" + tag + ".png"},
                              {"pfm", cam.name + "_" + tag + ".pfm"}, {"state", toString(rec->state)},
                              {"image_rms_rel_error", imgErr.value()}});
        }
    }
    timings["grids_and_renders"] = secondsSince(t);

    // 8. The report.
    nlohmann::json frames = nlohmann::json::array();
    for (const auto& r : sink.records) {
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
    report["points"] = n;
    report["key_points"] = model.keyCount();
    report["basis"] = model.basisSize();
    report["train_frames"] = trainFrames;
    report["test_frames"] = testFrames;
    report["samples_per_point"] = o.samples;
    report["full_seconds_per_frame"] = fullSecondsPerFrame;
    report["pmsc_seconds_per_frame"] = pmscSecondsPerFrame;
    report["speedup"] = fullSecondsPerFrame / pmscSecondsPerFrame;
    report["rms_rel_error"] = sink.pmError.value();
    report["soft_rms_rel_error"] = sink.softError.value();
    report["rms_rel_error_scattered"] = sink.pmScattered.value();
    report["rms_rel_error_path"] = sink.pmPath.value();
    report["error_frames"] = fullFrames.size();
    report["hit_rate"] = static_cast<double>(stats.hits) / static_cast<double>(testFrames);
    report["hits"] = stats.hits;
    report["blends"] = stats.blends;
    report["misses"] = stats.misses;
    report["reference_rms_rel_error_full"] = refFull.value();
    report["reference_rms_rel_error_pm"] = refPm.value();
    report["reference_points"] = subset.size();
    report["reference_samples_per_point"] = o.samples * o.referenceMultiplier;
    report["reference_frames"] = referenceFrames;
    report["bounces"] = 1;
    report["voxel_size_mm"] = world->voxels.voxelSizeMm;
    report["grid_key_points"] = topt.gridPoints.size();
    report["eps_min"] = model.epsMin;
    report["eps_max"] = model.epsMax;
    report["tolerance"] = topt.tolerance;
    report["peak_training_irradiance"] = peak;
    report["energy_captured"] = model.energyCaptured();
    report["train_max_point_residual"] = model.trainMaxPointResidual;
    report["training_warnings"] = trep.warnings;
    report["threads"] = threads;
    report["light_below_ceiling_mm"] = rig.belowCeilingMm;
    report["quick"] = o.quick;
    report["engine"] = nlohmann::json::parse(stats.toJson());
    report["frames"] = frames;
    report["images"] = images;
    report["vdb_files"] = vdbs;
    timings["total"] = secondsSince(start);
    report["seconds"] = timings;
    writeFileAtomically(o.outDir + "/report.json", report.dump(2) + "\n");
    progress("done", 1, 1);
    return report;
}

}  // namespace pmsc::cornell
