#include "examples/volume/VolumeDemo.h"

#include "engine/Engine.h"
#include "examples/cornell/DemoValidation.h"
#include "examples/cornell/ImageIO.h"
#include "examples/volume/VolumeRenderer.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/SpatialGrid.h"
#include "pmsc/Training.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
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

extern char** environ;

namespace pmsc::volume {

using cornell::RelError;
using cornell::ValidationSink;

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::string frameTag(Index pathFrame) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "path%03ld", static_cast<long>(pathFrame));
    return buf;
}

std::string triple(double a, double b, double c) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "%.6g,%.6g,%.6g", a, b, c);
    return buf;
}

/// Runs a program found on PATH with arguments, no shell; its exit status (-1 if it did not start).
int runProgram(const std::vector<std::string>& argv) {
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
    pid_t pid = 0;
    const int rc = posix_spawnp(&pid, argv[0].c_str(), &actions, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) return -1;
    int status = 0;
    if (waitpid(pid, &status, 0) != pid) return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/// Exposure that maps the mean luminance of the medium's pixels (the background is black and
/// would make a small object glare) to 0.3 before writePng's tone curve.
float mediumExposure(const Image& img) {
    double sum = 0;
    std::size_t count = 0;
    for (std::size_t i = 0; i < img.rgb.size(); i += 3) {
        const double y = 0.2126 * img.rgb[i] + 0.7152 * img.rgb[i + 1] + 0.0722 * img.rgb[i + 2];
        if (y > 1e-6) sum += y, ++count;
    }
    return sum > 0 ? static_cast<float>(0.3 * static_cast<double>(count) / sum) : 1.0f;
}

/// Adds to `err` the distance of a frame from its orthogonal projection onto the model's affine
/// subspace (mean + span of the basis): the best any reconstruction from this basis can do, with
/// every voxel known. PM's error above it is the price of knowing only the key voxels.
void addProjectionError(const Model& model, const double* x, RelError& err) {
    if (model.sharedChannels) {
        // Every channel onto mean_c + span(basis): the basis is N x M, the values N x C.
        using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
        const Eigen::Map<const RowMajor> v(x, model.points, model.channels);
        const Eigen::Map<const RowMajor> mean(model.mean.data(), model.points, model.channels);
        const RowMajor r = v - mean;
        const Eigen::MatrixXd c = model.basis.transpose() * r;
        const RowMajor proj = mean + model.basis * c;
        err.add(proj.data(), x, static_cast<std::size_t>(proj.size()));
        return;
    }
    const Eigen::Map<const Eigen::VectorXd> v(x, model.mean.size());
    const Eigen::VectorXd r = v - model.mean;
    const Eigen::VectorXd c = model.basis.transpose() * r;
    const Eigen::VectorXd proj = model.mean + model.basis * c;
    err.add(proj.data(), x, static_cast<std::size_t>(proj.size()));
}

}  // namespace

VolumeDemoOptions VolumeDemoOptions::quickOptions() {
    VolumeDemoOptions o;
    o.fog.targetVoxels = 12000;
    o.medium.lightSamples = 4;
    o.rig.azimuths = 8;
    o.rig.elevations = {10, 40, 70};
    o.basis = 16;
    o.keys = 120;
    o.gridKeys = 32;
    o.betweenLights = 4;
    o.pathFrames = 16;
    o.pathFullEvery = 4;
    o.referenceMultiplier = 4;
    o.referencePoints = 400;
    o.referenceFrames = 2;
    o.imageSize = 96;
    o.vdbRender = false;
    o.quick = true;
    return o;
}

nlohmann::json runVolumeDemo(const VolumeDemoOptions& o) {
    const auto start = Clock::now();
    if (o.outDir.empty()) throw InputError("demo volume: --out DIR is required");
    if (o.basis < 1 || o.keys < 1 || o.gridKeys < 0 || o.gridKeys > o.keys || o.betweenLights < 1 ||
        o.pathFrames < 1 || o.pathFullEvery < 1 || o.referenceMultiplier < 1 || o.referencePoints < 1 ||
        o.referenceFrames < 1 || o.imageSize < 8 || o.renderFrames < 0 || o.threads < 0 ||
        !(o.toleranceFraction > 0) || o.rig.azimuths < 1 || o.rig.elevations.empty())
        throw InputError("demo volume: an option is out of range");
    {
        std::error_code ec;
        std::filesystem::create_directories(o.outDir, ec);
        if (ec || !std::filesystem::is_directory(o.outDir))
            throw IoError("cannot create " + o.outDir + ": " + (ec ? ec.message() : "not a directory"));
    }
    const int threads = o.threads > 0 ? o.threads : tbb::info::default_concurrency();
    tbb::task_arena arena(threads);
    auto progress = [&](std::string_view stage, double done, double total) {
        if (o.progress && !o.progress(stage, done, total)) throw Cancelled("demo volume: interrupted");
    };
    nlohmann::json report, timings;

    // 1. The medium: smoke from the mesh (or the user's density), written beside the caches.
    auto t = Clock::now();
    progress("density", 0, 1);
    std::shared_ptr<const VolumeWorld> world;
    arena.execute([&] {
        world = o.density.empty()
                    ? VolumeWorld::create(DensityVolume::fromMesh(o.mesh, o.fog), o.medium, o.mesh)
                    : VolumeWorld::create(DensityVolume::read(o.density, o.grid), o.medium, o.density);
    });
    const Index n = static_cast<Index>(world->density.voxelCount());
    world->density.write(o.outDir + "/density.vdb");
    timings["density"] = secondsSince(t);

    // 2. Training frames: the light on the rig around and over the medium in two colours. With
    // rig.colourPairs a position's second colour is the first's per-channel rescaling (recolour).
    const VolumeEvaluator trainEval(world, o.rig.training(*world), "volume-train");
    const Index trainFrames = trainEval.frameCount();
    t = Clock::now();
    FrameSet q(trainFrames, n, 3);
    Index trainCalculations = 0;
    for (Index f = 0; f < trainFrames; ++f) {
        progress("training frames", static_cast<double>(f), static_cast<double>(trainFrames));
        const auto& l = trainEval.lights();
        const auto same = [&](const VolumeLight& a, const VolumeLight& b) {
            return a.position.x == b.position.x && a.position.y == b.position.y &&
                   a.position.z == b.position.z;
        };
        if (f > 0 && same(l[static_cast<std::size_t>(f - 1)], l[static_cast<std::size_t>(f)])) {
            std::copy(q.frame(f - 1), q.frame(f - 1) + 3 * n, q.frame(f));
            recolour(l[static_cast<std::size_t>(f - 1)], l[static_cast<std::size_t>(f)], q.frame(f), n);
        } else {
            arena.execute([&] { trainEval.evaluateAll(f, q.frame(f)); });
            ++trainCalculations;
        }
    }
    const double trainSeconds = secondsSince(t);
    timings["training_frames"] = trainSeconds;

    // 3. Train: basis, key voxels (seeded with a sparse spatial grid), calibrated eps.
    t = Clock::now();
    double peak = 0;
    for (Index i = 0; i < q.frames * n; ++i) {
        const double* v = q.values.data() + 3 * i;
        peak = std::max(peak, std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
    }
    TrainingOptions topt;
    topt.basis = o.basis;
    topt.maxKeys = o.keys;
    topt.sharedChannels = o.sharedChannels;
    topt.tolerance = o.toleranceFraction * peak;
    if (o.gridKeys > 0) {
        Eigen::MatrixXd positions(n, 3);
        for (Index i = 0; i < n; ++i) {
            const Vec3 p = world->density.voxelPositions()[static_cast<std::size_t>(i)];
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
    // The training frames' own distance from the basis (truncation to M vectors).
    RelError trainProjection;
    for (Index f = 0; f < trainFrames; ++f) addProjectionError(model, q.frame(f), trainProjection);
    q = FrameSet();
    timings["train"] = secondsSince(t);

    // 4. Validation: settings between the training ones, then the path. Full calculations of the
    // frames whose errors are measured and that are rendered.
    std::vector<VolumeLight> lights = o.rig.between(*world, o.betweenLights);
    const Index between = static_cast<Index>(lights.size());
    for (const VolumeLight& l : o.rig.path(*world, o.pathFrames)) lights.push_back(l);
    const VolumeEvaluator valEval(world, lights, "volume");
    const Index testFrames = valEval.frameCount();
    std::set<Index> fullFrames, renderFrames;
    for (Index f = 0; f < between; ++f) fullFrames.insert(f);
    for (Index p = 0; p < o.pathFrames; p += o.pathFullEvery) fullFrames.insert(between + p);
    for (int r = 0; r < o.renderFrames; ++r) {
        Index p = static_cast<Index>(r + 1) * o.pathFrames / (o.renderFrames + 1);
        p -= p % o.pathFullEvery;
        renderFrames.insert(between + p);
        fullFrames.insert(between + p);
    }
    std::map<Index, std::vector<double>> full;
    t = Clock::now();
    Index done = 0;
    for (Index f : fullFrames) {
        progress("validation full calculations", static_cast<double>(done++),
                 static_cast<double>(fullFrames.size()));
        auto& v = full[f];
        v.resize(static_cast<std::size_t>(3 * n));
        arena.execute([&] { valEval.evaluateAll(f, v.data()); });
    }
    const double fullSecondsPerFrame = secondsSince(t) / static_cast<double>(fullFrames.size());
    timings["validation_full"] = fullSecondsPerFrame * static_cast<double>(fullFrames.size());

    std::vector<Index> subset(static_cast<std::size_t>(n));
    std::iota(subset.begin(), subset.end(), Index{0});
    std::mt19937 rng(20130711);
    std::shuffle(subset.begin(), subset.end(), rng);
    subset.resize(std::min<std::size_t>(subset.size(), static_cast<std::size_t>(o.referencePoints)));
    std::sort(subset.begin(), subset.end());
    const Index referenceFrames = std::min<Index>(between, o.referenceFrames);
    std::set<Index> subsetFrames;
    for (Index f = 0; f < referenceFrames; ++f) subsetFrames.insert(f);

    // 5. The validation frames through the engine: key voxels, projection, soft cache per frame.
    ValidationSink sink("volume", full, renderFrames, subset, subsetFrames);
    sink.scatteredCount = between;
    engine::EngineOptions eopt;
    eopt.threads = threads;
    eopt.keepPointMultiplication = true;
    eopt.progress = [&](const engine::Progress& p) {
        progress("validation through the engine", static_cast<double>(p.framesDone),
                 static_cast<double>(p.framesTotal));
    };
    engine::Engine eng(model, valEval, eopt);
    const engine::RunStats stats = eng.run(engine::FrameRange{0, testFrames, 1}, sink);
    const double pmscSecondsPerFrame = stats.wallSeconds / static_cast<double>(testFrames);
    timings["engine"] = stats.wallSeconds;
    // The validation frames' distance from the basis: what M and the training lights allow.
    RelError valProjection;
    for (const auto& [f, v] : full) addProjectionError(model, v.data(), valProjection);

    // 6. Converged reference on the subset: referenceMultiplier x the light samples, 1/4 the step.
    MediumSettings refMedium = world->medium;
    refMedium.lightSamples *= o.referenceMultiplier;
    refMedium.stepVoxels /= 4;
    const VolumeEvaluator refEval(VolumeWorld::create(world->density, refMedium, world->source),
                                  o.rig.between(*world, o.betweenLights), "volume-reference");
    RelError refFull, refPm, refSelf;
    t = Clock::now();
    for (Index f = 0; f < referenceFrames; ++f) {
        progress("converged reference", static_cast<double>(f), static_cast<double>(referenceFrames));
        std::vector<double> ref(3 * subset.size());
        arena.execute([&] {
            tbb::parallel_for(tbb::blocked_range<std::size_t>(0, subset.size(), 16), [&](const auto& r) {
                refEval.evaluate(f, std::span<const Index>(subset.data() + r.begin(), r.size()),
                                 ref.data() + 3 * r.begin());
            });
        });
        std::vector<double> fullAt(3 * subset.size());
        for (std::size_t i = 0; i < subset.size(); ++i)
            for (int c = 0; c < 3; ++c)
                fullAt[3 * i + c] = full[f][static_cast<std::size_t>(3 * subset[i] + c)];
        refFull.add(fullAt.data(), ref.data(), ref.size());
        refPm.add(sink.pmAtSubset[f].data(), ref.data(), ref.size());
        if (f == 0) {
            // How converged the reference is: its distance from one with twice its shadow rays
            // and half its step, on the first frame's subset.
            progress("converged reference (check)", 0, 1);
            MediumSettings fineMedium = refMedium;
            fineMedium.lightSamples *= 2;
            fineMedium.stepVoxels /= 2;
            const VolumeEvaluator fineEval(VolumeWorld::create(world->density, fineMedium, world->source),
                                           {refEval.lights()[0]}, "volume-reference-check");
            std::vector<double> fine(3 * subset.size());
            arena.execute([&] {
                tbb::parallel_for(tbb::blocked_range<std::size_t>(0, subset.size(), 16), [&](const auto& r) {
                    fineEval.evaluate(0, std::span<const Index>(subset.data() + r.begin(), r.size()),
                                      fine.data() + 3 * r.begin());
                });
            });
            refSelf.add(ref.data(), fine.data(), fine.size());
        }
    }
    timings["reference"] = secondsSince(t);

    // 7. Cache files and renders from the moving cameras.
    t = Clock::now();
    nlohmann::json images = nlohmann::json::array(), vdbs = nlohmann::json::array();
    std::uint64_t cacheBytes = 0;
    const auto cameraCount = volumeCameras(*world, 0).size();
    Index rendered = 0;
    for (Index f : renderFrames) {
        const Index pathFrame = f - between;
        const auto rec = std::find_if(sink.records.begin(), sink.records.end(),
                                      [&](const auto& r) { return r.frame == f; });
        const ScatterCache pmCache(world->density, sink.soft[f],
                                   valEval.info(f, std::string(toString(rec->state))));
        const ScatterCache fullCache(world->density, full[f], valEval.info(f, "full"));
        cacheBytes = pmCache.memoryBytes();
        const std::string tag = frameTag(pathFrame);
        for (const auto& [name, cache] : {std::pair{"pmsc", &pmCache}, std::pair{"full", &fullCache}}) {
            const std::string path = o.outDir + "/cache_" + name + "_" + tag + ".vdb";
            cache->write(path);
            vdbs.push_back(std::filesystem::path(path).filename().string());
        }
        const double camT = o.pathFrames > 1 ? static_cast<double>(pathFrame) / (o.pathFrames - 1) : 0.0;
        for (const cornell::Camera& cam : volumeCameras(*world, camT)) {
            progress("renders", static_cast<double>(rendered++),
                     static_cast<double>(renderFrames.size() * cameraCount));
            std::vector<Image> imgs;
            arena.execute([&] { imgs = renderVolume(*world, cam, {&fullCache, &pmCache}, o.imageSize); });
            const Image diff = cornell::absDifference(imgs[0], imgs[1], 10.0f);
            const Image panel = cornell::sideBySide({&imgs[0], &imgs[1], &diff});
            const std::string name = cam.name + "_" + tag + ".png";
            cornell::writePng(o.outDir + "/" + name, panel, mediumExposure(imgs[0]));
            RelError imgErr;
            std::vector<double> a(imgs[1].rgb.begin(), imgs[1].rgb.end()),
                b(imgs[0].rgb.begin(), imgs[0].rgb.end());
            imgErr.add(a.data(), b.data(), a.size());
            images.push_back({{"camera", cam.name},
                              {"path_frame", pathFrame},
                              {"png", name},
                              {"state", toString(rec->state)},
                              {"image_rms_rel_error", imgErr.value()}});
        }
    }
    timings["caches_and_renders"] = secondsSince(t);

    // 8. OpenVDB's own renderer on the density, as an independent view of the input: the same
    // extinction and albedo, a distant light from the first rendered frame's light direction.
    nlohmann::json vdbRender = nullptr;
    if (o.vdbRender) {
        t = Clock::now();
        progress("vdb_render", 0, 1);
        const cornell::Camera cam = volumeCameras(*world, 0.5)[0];
        const VolumeLight& l =
            lights[static_cast<std::size_t>(renderFrames.empty() ? 0 : *renderFrames.begin())];
        const Vec3 dir = cornell::normalize(l.position - world->centre);
        const double s = world->medium.sigmaT;
        const Rgb& a = world->medium.albedo;
        const std::string png = o.outDir + "/vdb_render_density.png";
        std::vector<std::string> argv{"vdb_render",
                                      o.outDir + "/density.vdb",
                                      png,
                                      "-res",
                                      std::to_string(o.imageSize) + "x" + std::to_string(o.imageSize),
                                      "-translate",
                                      triple(cam.eye.x, cam.eye.y, cam.eye.z),
                                      "-lookat",
                                      triple(cam.target.x, cam.target.y, cam.target.z),
                                      "-fov",
                                      "45",
                                      "-scatter",
                                      triple(s * a[0], s * a[1], s * a[2]),
                                      "-absorb",
                                      triple(s * (1 - a[0]), s * (1 - a[1]), s * (1 - a[2])),
                                      "-light",
                                      triple(dir.x, dir.y, dir.z) + ",1,1,1",
                                      "-step",
                                      "0.5",
                                      "-shadowstep",
                                      "1",
                                      "-cpus",
                                      std::to_string(threads)};
        const int rc = runProgram(argv);
        vdbRender = {{"png", rc == 0 ? nlohmann::json("vdb_render_density.png") : nlohmann::json(nullptr)},
                     {"exit_status", rc},
                     {"command", argv}};
        timings["vdb_render"] = secondsSince(t);
    }

    // 9. The report.
    nlohmann::json frames = nlohmann::json::array();
    for (const auto& r : sink.records) {
        nlohmann::json fr{
            {"frame", r.frame},           {"kind", r.frame < between ? "between" : "path"},
            {"state", toString(r.state)}, {"weight", r.weight},
            {"key_rms", r.keyRms},        {"kelvin", lights[static_cast<std::size_t>(r.frame)].kelvin}};
        if (r.pmRelError >= 0) {
            fr["pm_rel_error"] = r.pmRelError;
            fr["soft_rel_error"] = r.softRelError;
        }
        frames.push_back(fr);
    }
    const auto [lo, hi] = world->density.worldBounds();
    report["points"] = n;
    report["active_voxels"] = n;
    report["voxel_size_m"] = world->density.voxelSize();
    report["bounds_m"] = {{lo.x, lo.y, lo.z}, {hi.x, hi.y, hi.z}};
    report["source"] = world->source;
    report["sigma_t_per_m"] = world->medium.sigmaT;
    report["albedo"] = world->medium.albedo;
    report["max_density"] = world->density.maxDensity();
    report["light_samples"] = world->medium.lightSamples;
    report["step_voxels"] = world->medium.stepVoxels;
    report["multiple_scattering_octaves"] = world->medium.octaves;
    report["key_points"] = model.keyCount();
    report["basis"] = model.basisSize();
    report["shared_channels"] = model.sharedChannels;
    report["train_frames"] = trainFrames;
    report["train_full_calculations"] = trainCalculations;
    report["test_frames"] = testFrames;
    report["full_seconds_per_frame"] = fullSecondsPerFrame;
    report["pmsc_seconds_per_frame"] = pmscSecondsPerFrame;
    report["speedup"] = fullSecondsPerFrame / pmscSecondsPerFrame;
    report["rms_rel_error"] = sink.pmError.value();
    report["soft_rms_rel_error"] = sink.softError.value();
    report["rms_rel_error_between"] = sink.pmScattered.value();
    report["rms_rel_error_path"] = sink.pmPath.value();
    report["error_frames"] = fullFrames.size();
    report["train_projection_rel_error"] = trainProjection.value();
    report["projection_rel_error"] = valProjection.value();
    {
        // How far the validation lights are from the training ones (angles seen from the centre).
        const std::vector<Vec3> dirs = o.rig.trainingDirections();
        auto dirOf = [&](const VolumeLight& l) { return cornell::normalize(l.position - world->centre); };
        auto nearestDeg = [&](const Vec3& d, const Vec3* skip) {
            double best = 1e9;
            for (const Vec3& t : dirs) {
                if (skip && t.x == skip->x && t.y == skip->y && t.z == skip->z) continue;
                best = std::min(
                    best, std::acos(std::clamp(d.x * t.x + d.y * t.y + d.z * t.z, -1.0, 1.0)) * 180 / M_PI);
            }
            return best;
        };
        std::vector<double> spacing;
        for (const Vec3& d : dirs) spacing.push_back(nearestDeg(d, &d));
        std::sort(spacing.begin(), spacing.end());
        report["training_spacing_deg_median"] = spacing[spacing.size() / 2];
        report["training_spacing_deg_max"] = spacing.back();
        nlohmann::json gaps = nlohmann::json::array();
        for (Index f = 0; f < between; ++f)
            gaps.push_back(nearestDeg(dirOf(lights[static_cast<std::size_t>(f)]), nullptr));
        report["between_nearest_training_deg"] = gaps;
    }
    report["hit_rate"] = static_cast<double>(stats.hits) / static_cast<double>(testFrames);
    report["hits"] = stats.hits;
    report["blends"] = stats.blends;
    report["misses"] = stats.misses;
    report["reference_rms_rel_error_full"] = refFull.value();
    report["reference_rms_rel_error_pm"] = refPm.value();
    report["reference_ratio_pm_to_full"] = refFull.value() > 0 ? refPm.value() / refFull.value() : 0.0;
    report["reference_points"] = subset.size();
    report["reference_self_rel_error"] = refSelf.value();
    report["reference_light_samples"] = refMedium.lightSamples;
    report["reference_step_voxels"] = refMedium.stepVoxels;
    report["reference_frames"] = referenceFrames;
    report["grid_key_points"] = topt.gridPoints.size();
    report["eps_min"] = model.epsMin;
    report["eps_max"] = model.epsMax;
    report["tolerance"] = topt.tolerance;
    report["peak_training_radiance"] = peak;
    report["energy_captured"] = model.energyCaptured();
    report["training_warnings"] = trep.warnings;
    report["threads"] = threads;
    report["density_tree_bytes"] = world->density.memoryBytes();
    report["cache_tree_bytes"] = cacheBytes;
    report["quick"] = o.quick;
    report["engine"] = nlohmann::json::parse(stats.toJson());
    report["frames"] = frames;
    report["images"] = images;
    report["vdb_files"] = vdbs;
    report["vdb_render"] = vdbRender;
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    report["peak_rss_mb"] = static_cast<double>(usage.ru_maxrss) / 1024.0;
    timings["total"] = secondsSince(start);
    report["seconds"] = timings;
    writeFileAtomically(o.outDir + "/report.json", report.dump(2) + "\n");
    progress("done", 1, 1);
    return report;
}

}  // namespace pmsc::volume
