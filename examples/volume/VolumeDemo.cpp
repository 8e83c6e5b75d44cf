#include "examples/volume/VolumeDemo.h"

#include "engine/Engine.h"
#include "evaluators/scene/Image.h"
#include "examples/common/DemoSetup.h"
#include "examples/common/DemoValidation.h"
#include "examples/volume/VolumeRenderer.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/SpatialGrid.h"
#include "pmsc/Training.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <Eigen/Eigenvalues>

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
    args.reserve(argv.size() + 1);
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
    o.rigFromMedium = false;
    o.maxBasis = 16;  // the energy rule would take more; the smoke test stays seconds
    o.keysPerBasis = 7.5;
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

// --- the steps of runVolumeDemo, in the order it runs them ------------------------------------
namespace {

/// Throws InputError unless the options are usable.
void checkOptions(const VolumeDemoOptions& o) {
    if (o.outDir.empty()) throw InputError("demo volume: --out DIR is required");
    if (o.basis < 0 || o.keys < 0 || o.gridKeys < -1 || (o.keys > 0 && o.gridKeys > o.keys) ||
        !(o.basisEnergy > 0 && o.basisEnergy <= 1) || o.maxBasis < 1 || !(o.keysPerBasis >= 1) ||
        o.betweenLights < 1 || o.pathFrames < 1 || o.pathFullEvery < 1 || o.referenceMultiplier < 1 ||
        o.referencePoints < 1 || o.referenceFrames < 1 || o.imageSize < 8 || o.renderFrames < 0 ||
        o.threads < 0 || !(o.toleranceFraction > 0) || o.rig.azimuths < 1 || o.rig.elevations.empty())
        throw InputError("demo volume: an option is out of range");
}

/// 1. The medium: smoke from the mesh (or the user's density), written beside the caches.
std::shared_ptr<const VolumeWorld> makeMedium(DemoSetup& run, const VolumeDemoOptions& o) {
    const auto t = DemoClock::now();
    run.progress("density", 0, 1);
    std::shared_ptr<const VolumeWorld> world;
    run.arena.execute([&] {
        world = o.density.empty()
                    ? VolumeWorld::create(DensityVolume::fromMesh(o.mesh, o.fog), o.medium, o.mesh)
                    : VolumeWorld::create(DensityVolume::read(o.density, o.grid), o.medium, o.density);
    });
    world->density.write(o.outDir + "/density.vdb");
    run.lap("density", t);
    return world;
}

/// 1. (continued) The options with the rig this medium needs (VolumeRig::forMedium).
VolumeDemoOptions withRigForMedium(DemoSetup& run, const VolumeDemoOptions& o, const VolumeWorld& world) {
    VolumeDemoOptions out = o;
    if (!o.rigFromMedium) return out;
    const auto t = DemoClock::now();
    run.progress("rig for the medium", 0, 1);
    run.arena.execute([&] { out.rig = VolumeRig::forMedium(world, o.rig); });
    run.lap("rig", t);
    return out;
}

/// The training frames, and how many of them were full calculations (the others recoloured).
struct TrainingFrames {
    FrameSet q;
    Index calculations = 0;
};

/// 2. Training frames: the light on the rig around and over the medium in two colours. With
/// rig.colourPairs a position's second colour is the first's per-channel rescaling (recolour).
TrainingFrames makeTrainingFrames(DemoSetup& run, const VolumeEvaluator& trainEval, Index n) {
    const Index trainFrames = trainEval.frameCount();
    const auto t = DemoClock::now();
    TrainingFrames training{FrameSet(trainFrames, n, 3)};
    FrameSet& q = training.q;
    for (Index f = 0; f < trainFrames; ++f) {
        run.progress("training frames", static_cast<double>(f), static_cast<double>(trainFrames));
        const auto& l = trainEval.lights();
        const auto same = [&](const VolumeLight& a, const VolumeLight& b) {
            return a.position.x == b.position.x && a.position.y == b.position.y &&
                   a.position.z == b.position.z;
        };
        if (f > 0 && same(l[static_cast<std::size_t>(f - 1)], l[static_cast<std::size_t>(f)])) {
            std::copy(q.frame(f - 1), q.frame(f - 1) + 3 * n, q.frame(f));
            recolour(l[static_cast<std::size_t>(f - 1)], l[static_cast<std::size_t>(f)], q.frame(f), n);
        } else {
            run.arena.execute([&] { trainEval.evaluateAll(f, q.frame(f)); });
            ++training.calculations;
        }
    }
    run.lap("training_frames", t);
    return training;
}

/// The model and what training made of the frames.
struct Trained {
    TrainingOptions options;
    TrainingReport report;
    Model model;
    double peak = 0;      // the largest training radiance (Euclidean over RGB)
    RelError projection;  // the training frames' own distance from the basis
    ModelSize size;       // M, K, grid keys chosen for the medium
};

/// 3. Train: basis, key voxels (seeded with a sparse spatial grid), calibrated eps; hands `q` to
/// training, which takes its values (the frames are held once: at a million voxels they are
/// 2.25 GB).
Trained trainModel(DemoSetup& run, const VolumeDemoOptions& o, const VolumeWorld& world, FrameSet&& q,
                   Index n) {
    const auto t = DemoClock::now();
    Trained trained;
    for (Index i = 0; i < q.frames * n; ++i) {
        const double* v = q.values.data() + 3 * i;
        trained.peak = std::max(trained.peak, std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
        trained.projection.ref2 += v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    }
    trained.size = chooseModelSize(o, q);
    // The training frames' own distance from the basis (truncation to M vectors): the energy the
    // M principal directions leave out, which is what the model's mean and basis leave out of the
    // frames (training keeps the same M principal directions, rotated within their span).
    trained.projection.err2 = trained.size.discardedEnergy;
    TrainingOptions& topt = trained.options;
    topt.basis = trained.size.basis;
    topt.maxKeys = trained.size.keys;
    topt.sharedChannels = o.sharedChannels;
    topt.tolerance = o.toleranceFraction * trained.peak;
    Eigen::MatrixXd positions(n, 3);
    for (Index i = 0; i < n; ++i) {
        const Vec3 p = world.density.voxelPositions()[static_cast<std::size_t>(i)];
        positions.row(i) << p.x, p.y, p.z;
    }
    if (trained.size.gridKeys > 0)
        topt.gridPoints = sparseGridPointsByCount(positions, trained.size.gridKeys);
    // The voxels' positions spread the sentinels over the medium (Sentinels.h); no regions: the
    // demo's cache fails through whole frames.
    topt.regions.positions = std::move(positions);
    topt.regions.automatic = false;
    topt.progress = [&run](std::string_view stage, double done, double total) {
        run.progress(std::string("train: ") + std::string(stage), done, total);
        return true;
    };
    run.arena.execute([&] { trained.model = train(std::move(q), topt, &trained.report); });
    run.lap("train", t);
    return trained;
}

/// The validation lights and which of their frames get full calculations and renders.
struct ValidationFrames {
    std::vector<VolumeLight> lights;  // the settings between the training ones, then the path
    Index between = 0;
    std::set<Index> fullFrames, renderFrames;
};

/// 4. Validation: settings between the training ones, then the path. Full calculations of the
/// frames whose errors are measured and that are rendered.
ValidationFrames chooseValidationFrames(const VolumeDemoOptions& o, const VolumeWorld& world) {
    ValidationFrames v;
    v.lights = o.rig.between(world, o.betweenLights);
    v.between = static_cast<Index>(v.lights.size());
    for (const VolumeLight& l : o.rig.path(world, o.pathFrames)) v.lights.push_back(l);
    for (Index f = 0; f < v.between; ++f) v.fullFrames.insert(f);
    for (Index p = 0; p < o.pathFrames; p += o.pathFullEvery) v.fullFrames.insert(v.between + p);
    for (int r = 0; r < o.renderFrames; ++r) {
        Index p = static_cast<Index>(r + 1) * o.pathFrames / (o.renderFrames + 1);
        p -= p % o.pathFullEvery;
        v.renderFrames.insert(v.between + p);
        v.fullFrames.insert(v.between + p);
    }
    return v;
}

/// The full calculations of the validation frames that have them.
struct FullFrames {
    std::map<Index, std::vector<double>> values;
    double secondsPerFrame = 0;
};

/// 4. (continued) The full calculations, timed.
FullFrames calculateFullFrames(DemoSetup& run, const VolumeEvaluator& valEval,
                               const std::set<Index>& fullFrames, Index n) {
    FullFrames full;
    const auto t = DemoClock::now();
    Index done = 0;
    for (Index f : fullFrames) {
        run.progress("validation full calculations", static_cast<double>(done++),
                     static_cast<double>(fullFrames.size()));
        auto& v = full.values[f];
        v.resize(static_cast<std::size_t>(3 * n));
        run.arena.execute([&] { valEval.evaluateAll(f, v.data()); });
    }
    full.secondsPerFrame = secondsSince(t) / static_cast<double>(fullFrames.size());
    run.timings["validation_full"] = full.secondsPerFrame * static_cast<double>(fullFrames.size());
    return full;
}

/// 5. The validation frames through the engine: key voxels, projection, soft cache per frame.
engine::RunStats runThroughEngine(DemoSetup& run, const Model& model, const VolumeEvaluator& valEval,
                                  ValidationSink& sink) {
    engine::EngineOptions eopt;
    eopt.threads = run.threads;
    eopt.keepPointMultiplication = true;
    // The cache goes out as float grids (.vdb): the float basis, as `pmsc run --format vdb` reads.
    eopt.basisPrecision = BasisPrecision::Single;
    eopt.progress = [&run](const engine::Progress& p) {
        run.progress("validation through the engine", static_cast<double>(p.framesDone),
                     static_cast<double>(p.framesTotal));
    };
    engine::Engine eng(model, valEval, eopt);
    engine::RunStats stats = eng.run(engine::FrameRange{0, valEval.frameCount(), 1}, sink);
    run.timings["engine"] = stats.wallSeconds;
    return stats;
}

/// One frame of an evaluator at the subset's voxels (3 doubles a voxel into `out`), in the arena.
void evaluateAtSubset(DemoSetup& run, const VolumeEvaluator& eval, Index frame,
                      const std::vector<Index>& subset, std::vector<double>& out) {
    run.arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, subset.size(), 16), [&](const auto& r) {
            eval.evaluate(frame, std::span<const Index>(subset.data() + r.begin(), r.size()),
                          out.data() + 3 * r.begin());
        });
    });
}

/// The converged reference's errors: of the full calculation, of PM, and its own (convergence).
struct ReferenceErrors {
    RelError full, pm, self;
    MediumSettings medium;  // the reference's
};

/// 6. (check) How converged the reference is: its distance from one with twice its shadow rays
/// and half its step, on the first frame's subset.
void checkReferenceConvergence(DemoSetup& run, const VolumeWorld& world, const VolumeEvaluator& refEval,
                               const std::vector<Index>& subset, const std::vector<double>& ref,
                               ReferenceErrors& errors) {
    run.progress("converged reference (check)", 0, 1);
    MediumSettings fineMedium = errors.medium;
    fineMedium.lightSamples *= 2;
    fineMedium.stepVoxels /= 2;
    const VolumeEvaluator fineEval(VolumeWorld::create(world.density, fineMedium, world.source),
                                   {refEval.lights()[0]}, "volume-reference-check");
    std::vector<double> fine(3 * subset.size());
    evaluateAtSubset(run, fineEval, 0, subset, fine);
    errors.self.add(ref.data(), fine.data(), fine.size());
}

/// 6. Converged reference on the subset: referenceMultiplier x the light samples, 1/4 the step.
ReferenceErrors measureAgainstReference(DemoSetup& run, const VolumeDemoOptions& o, const VolumeWorld& world,
                                        const ReferenceSubset& reference,
                                        std::map<Index, std::vector<double>>& full, ValidationSink& sink) {
    ReferenceErrors errors;
    errors.medium = world.medium;
    errors.medium.lightSamples *= o.referenceMultiplier;
    errors.medium.stepVoxels /= 4;
    const VolumeEvaluator refEval(VolumeWorld::create(world.density, errors.medium, world.source),
                                  o.rig.between(world, o.betweenLights), "volume-reference");
    const std::vector<Index>& subset = reference.points;
    const auto t = DemoClock::now();
    for (Index f = 0; f < reference.frames; ++f) {
        run.progress("converged reference", static_cast<double>(f), static_cast<double>(reference.frames));
        std::vector<double> ref(3 * subset.size());
        evaluateAtSubset(run, refEval, f, subset, ref);
        std::vector<double> fullAt(3 * subset.size());
        for (std::size_t i = 0; i < subset.size(); ++i)
            for (int c = 0; c < 3; ++c)
                fullAt[3 * i + c] = full[f][static_cast<std::size_t>(3 * subset[i] + c)];
        errors.full.add(fullAt.data(), ref.data(), ref.size());
        errors.pm.add(sink.pmAtSubset[f].data(), ref.data(), ref.size());
        if (f == 0) checkReferenceConvergence(run, world, refEval, subset, ref, errors);
    }
    run.lap("reference", t);
    return errors;
}

/// What the caches and renders step wrote.
struct WrittenFiles {
    nlohmann::json images = nlohmann::json::array(), vdbs = nlohmann::json::array();
    std::uint64_t cacheBytes = 0;  // of the last PMSC cache written
};

/// 7. One camera's panel (full | PMSC | |diff| x 10) of a path frame; its entry in "images".
nlohmann::json renderPanel(DemoSetup& run, const VolumeDemoOptions& o, const VolumeWorld& world,
                           const scene::Camera& cam, const ScatterCache& fullCache,
                           const ScatterCache& pmCache, Index pathFrame, const std::string& tag,
                           CacheState state) {
    std::vector<Image> imgs;
    run.arena.execute([&] { imgs = renderVolume(world, cam, {&fullCache, &pmCache}, o.imageSize); });
    const Image diff = scene::absDifference(imgs[0], imgs[1], 10.0f);
    const Image panel = scene::sideBySide({&imgs[0], &imgs[1], &diff});
    const std::string name = cam.name + "_" + tag + ".png";
    scene::writePng(o.outDir + "/" + name, panel, mediumExposure(imgs[0]));
    RelError imgErr;
    std::vector<double> a(imgs[1].rgb.begin(), imgs[1].rgb.end()), b(imgs[0].rgb.begin(), imgs[0].rgb.end());
    imgErr.add(a.data(), b.data(), a.size());
    return {{"camera", cam.name},
            {"path_frame", pathFrame},
            {"png", name},
            {"state", toString(state)},
            {"image_rms_rel_error", imgErr.value()}};
}

/// 7. Cache files and renders from the moving cameras.
WrittenFiles writeCachesAndRenders(DemoSetup& run, const VolumeDemoOptions& o, const VolumeWorld& world,
                                   const VolumeEvaluator& valEval, const ValidationFrames& frames,
                                   std::map<Index, std::vector<double>>& full, ValidationSink& sink) {
    const auto t = DemoClock::now();
    WrittenFiles written;
    const auto cameraCount = volumeCameras(world, 0).size();
    Index rendered = 0;
    for (Index f : frames.renderFrames) {
        const Index pathFrame = f - frames.between;
        const auto rec = std::find_if(sink.records.begin(), sink.records.end(),
                                      [&](const auto& r) { return r.frame == f; });
        const ScatterCache pmCache(world.density, sink.soft[f],
                                   valEval.info(f, std::string(toString(rec->state))));
        const ScatterCache fullCache(world.density, full[f], valEval.info(f, "full"));
        written.cacheBytes = pmCache.memoryBytes();
        const std::string tag = frameTag(pathFrame);
        for (const auto& [name, cache] : {std::pair{"pmsc", &pmCache}, std::pair{"full", &fullCache}}) {
            const std::string path = o.outDir + "/cache_" + name + "_" + tag + ".vdb";
            cache->write(path);
            written.vdbs.push_back(std::filesystem::path(path).filename().string());
        }
        const double camT = o.pathFrames > 1 ? static_cast<double>(pathFrame) / (o.pathFrames - 1) : 0.0;
        for (const scene::Camera& cam : volumeCameras(world, camT)) {
            run.progress("renders", static_cast<double>(rendered++),
                         static_cast<double>(frames.renderFrames.size() * cameraCount));
            written.images.push_back(
                renderPanel(run, o, world, cam, fullCache, pmCache, pathFrame, tag, rec->state));
        }
    }
    run.lap("caches_and_renders", t);
    return written;
}

/// 8. OpenVDB's own renderer on the density, as an independent view of the input: the same
/// extinction and albedo, a distant light from the first rendered frame's light direction.
nlohmann::json runVdbRender(DemoSetup& run, const VolumeDemoOptions& o, const VolumeWorld& world,
                            const ValidationFrames& frames) {
    if (!o.vdbRender) return nullptr;
    const auto t = DemoClock::now();
    run.progress("vdb_render", 0, 1);
    const scene::Camera cam = volumeCameras(world, 0.5)[0];
    const VolumeLight& l =
        frames
            .lights[static_cast<std::size_t>(frames.renderFrames.empty() ? 0 : *frames.renderFrames.begin())];
    const Vec3 dir = scene::normalize(l.position - world.centre);
    const double s = world.medium.sigmaT;
    const Rgb& a = world.medium.albedo;
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
                                  std::to_string(run.threads)};
    const int rc = runProgram(argv);
    nlohmann::json vdbRender = {
        {"png", rc == 0 ? nlohmann::json("vdb_render_density.png") : nlohmann::json(nullptr)},
        {"exit_status", rc},
        {"command", argv}};
    run.lap("vdb_render", t);
    return vdbRender;
}

/// 9. The report's per-frame table.
nlohmann::json frameTable(const std::vector<ValidationSink::FrameRecord>& records,
                          const ValidationFrames& frames) {
    nlohmann::json table = nlohmann::json::array();
    for (const auto& r : records) {
        nlohmann::json fr{{"frame", r.frame},
                          {"kind", r.frame < frames.between ? "between" : "path"},
                          {"state", toString(r.state)},
                          {"weight", r.weight},
                          {"key_rms", r.keyRms},
                          {"kelvin", frames.lights[static_cast<std::size_t>(r.frame)].kelvin}};
        if (r.pmRelError >= 0) {
            fr["pm_rel_error"] = r.pmRelError;
            fr["soft_rel_error"] = r.softRelError;
        }
        table.push_back(fr);
    }
    return table;
}

/// 9. The report: the medium, the model and how it was trained.
void reportMediumAndModel(nlohmann::json& report, const VolumeDemoOptions& o, const VolumeWorld& world,
                          Index n, const Trained& trained, const TrainingFrames& training, Index trainFrames,
                          int threads) {
    const Model& model = trained.model;
    const auto [lo, hi] = world.density.worldBounds();
    report["points"] = n;
    report["active_voxels"] = n;
    report["voxel_size_m"] = world.density.voxelSize();
    report["bounds_m"] = {{lo.x, lo.y, lo.z}, {hi.x, hi.y, hi.z}};
    report["source"] = world.source;
    report["sigma_t_per_m"] = world.medium.sigmaT;
    report["albedo"] = world.medium.albedo;
    report["max_density"] = world.density.maxDensity();
    report["light_samples"] = world.medium.lightSamples;
    report["step_voxels"] = world.medium.stepVoxels;
    report["multiple_scattering_octaves"] = world.medium.octaves;
    report["key_points"] = model.keyCount();
    report["basis"] = model.basisSize();
    report["shared_channels"] = model.sharedChannels;
    report["train_frames"] = trainFrames;
    report["train_full_calculations"] = training.calculations;
    report["grid_key_points"] = trained.options.gridPoints.size();
    report["eps_min"] = model.epsMin;
    report["eps_max"] = model.epsMax;
    report["tolerance"] = trained.options.tolerance;
    report["peak_training_radiance"] = trained.peak;
    report["energy_captured"] = model.energyCaptured();
    report["rig_from_medium"] = o.rigFromMedium;
    report["rig_azimuths"] = o.rig.spiral > 0 ? 0 : o.rig.azimuths;
    report["rig_elevations"] = o.rig.elevations;
    report["rig_cell_interpolation_error"] = o.rig.cellInterpolationError(world);
    report["basis_rule"] = o.basis > 0 ? nlohmann::json("--basis") : nlohmann::json(o.basisEnergy);
    report["keys_per_basis"] = o.keys > 0 ? nlohmann::json("--keys") : nlohmann::json(o.keysPerBasis);
    report["training_warnings"] = trained.report.warnings;
    report["threads"] = threads;
    report["density_tree_bytes"] = world.density.memoryBytes();
    report["quick"] = o.quick;
}

/// 9. The report: speed and errors against the full calculation and the converged reference.
void reportAccuracy(nlohmann::json& report, const FullFrames& full, const engine::RunStats& stats,
                    Index testFrames, const ValidationSink& sink, const ValidationFrames& frames,
                    const Trained& trained, const RelError& valProjection, const ReferenceSubset& reference,
                    const ReferenceErrors& ref) {
    const double pmscSecondsPerFrame = stats.wallSeconds / static_cast<double>(testFrames);
    report["test_frames"] = testFrames;
    report["full_seconds_per_frame"] = full.secondsPerFrame;
    report["pmsc_seconds_per_frame"] = pmscSecondsPerFrame;
    report["speedup"] = full.secondsPerFrame / pmscSecondsPerFrame;
    report["rms_rel_error"] = sink.pmError.value();
    report["soft_rms_rel_error"] = sink.softError.value();
    report["rms_rel_error_between"] = sink.pmScattered.value();
    report["rms_rel_error_path"] = sink.pmPath.value();
    report["error_frames"] = frames.fullFrames.size();
    report["train_projection_rel_error"] = trained.projection.value();
    report["projection_rel_error"] = valProjection.value();
    report["hit_rate"] = static_cast<double>(stats.hits) / static_cast<double>(testFrames);
    report["hits"] = stats.hits;
    report["blends"] = stats.blends;
    report["misses"] = stats.misses;
    report["reference_rms_rel_error_full"] = ref.full.value();
    report["reference_rms_rel_error_pm"] = ref.pm.value();
    report["reference_ratio_pm_to_full"] = ref.full.value() > 0 ? ref.pm.value() / ref.full.value() : 0.0;
    report["reference_points"] = reference.points.size();
    report["reference_self_rel_error"] = ref.self.value();
    report["reference_light_samples"] = ref.medium.lightSamples;
    report["reference_step_voxels"] = ref.medium.stepVoxels;
    report["reference_frames"] = reference.frames;
}

/// 9. The report: how far the validation lights are from the training ones (angles seen from
/// the centre).
void reportLightSpacing(nlohmann::json& report, const VolumeDemoOptions& o, const VolumeWorld& world,
                        const ValidationFrames& frames) {
    const std::vector<Vec3> dirs = o.rig.trainingDirections();
    auto dirOf = [&](const VolumeLight& l) { return scene::normalize(l.position - world.centre); };
    auto nearestDeg = [&](const Vec3& d, const Vec3* skip) {
        double best = 1e9;
        for (const Vec3& t : dirs) {
            if (skip && t.x == skip->x && t.y == skip->y && t.z == skip->z) continue;
            best = std::min(best,
                            std::acos(std::clamp(d.x * t.x + d.y * t.y + d.z * t.z, -1.0, 1.0)) * 180 / M_PI);
        }
        return best;
    };
    std::vector<double> spacing;
    spacing.reserve(dirs.size());
    for (const Vec3& d : dirs) spacing.push_back(nearestDeg(d, &d));
    std::sort(spacing.begin(), spacing.end());
    report["training_spacing_deg_median"] = spacing[spacing.size() / 2];
    report["training_spacing_deg_max"] = spacing.back();
    nlohmann::json gaps = nlohmann::json::array();
    for (Index f = 0; f < frames.between; ++f)
        gaps.push_back(nearestDeg(dirOf(frames.lights[static_cast<std::size_t>(f)]), nullptr));
    report["between_nearest_training_deg"] = gaps;
}

}  // namespace

namespace {

/// The energy of the training matrix along its principal directions (eigenvalues of the Gram
/// matrix of the mean-removed columns, largest first), as pmsc::train forms it: with shared
/// channels the columns are (frame, channel) and the rows voxels, else the columns are frames.
Eigen::VectorXd energySpectrum(const FrameSet& q, bool shared) {
    const Index n = q.points, c = q.channels, f = q.frames;
    const Index cols = shared ? f * c : f, rows = shared ? n : n * c;
    auto at = [&](Index row, Index col) {
        return shared ? q.values[static_cast<std::size_t>(((col / c) * n + row) * c + col % c)]
                      : q.values[static_cast<std::size_t>(col * n * c + row)];
    };
    Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(cols, cols);
    constexpr Index kBlock = 2048;
    Eigen::MatrixXd b;
    for (Index r0 = 0; r0 < rows; r0 += kBlock) {
        const Index r1 = std::min(rows, r0 + kBlock);
        b.resize(r1 - r0, cols);
        for (Index r = r0; r < r1; ++r)
            for (Index k = 0; k < cols; ++k) b(r - r0, k) = at(r, k);
        if (shared) {
            // each (voxel, channel) row's mean over the frames
            for (Index ch = 0; ch < c; ++ch) {
                Eigen::VectorXd mean = Eigen::VectorXd::Zero(r1 - r0);
                for (Index k = ch; k < cols; k += c) mean += b.col(k);
                mean /= static_cast<double>(f);
                for (Index k = ch; k < cols; k += c) b.col(k) -= mean;
            }
        } else {
            b.colwise() -= b.rowwise().mean();
        }
        gram.selfadjointView<Eigen::Lower>().rankUpdate(b.transpose());
    }
    gram = gram.selfadjointView<Eigen::Lower>();
    Eigen::VectorXd e =
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(gram, Eigen::EigenvaluesOnly).eigenvalues();
    return e.reverse().cwiseMax(0.0);
}

}  // namespace

ModelSize chooseModelSize(const VolumeDemoOptions& o, const FrameSet& q) {
    ModelSize s;
    const Eigen::VectorXd e = energySpectrum(q, o.sharedChannels);
    const double total = e.sum();
    const int available = static_cast<int>(std::min<Index>(e.size() - 1, o.maxBasis));
    s.basis = o.basis;
    if (s.basis == 0) {
        double sum = 0;
        while (s.basis < available && sum < o.basisEnergy * total) sum += e(s.basis++);
        s.basis = std::max(s.basis, 1);
    }
    const Index kept = std::min<Index>(s.basis, e.size());
    s.energy = total > 0 ? e.head(kept).sum() / total : 1.0;
    s.discardedEnergy = e.tail(e.size() - kept).sum();
    const int maxKeys = static_cast<int>(std::max<Index>(1, q.points / 10));
    s.keys = o.keys > 0 ? o.keys : std::min(maxKeys, static_cast<int>(std::lround(o.keysPerBasis * s.basis)));
    s.gridKeys = std::min(s.keys, o.gridKeys >= 0 ? o.gridKeys : s.keys / 5);
    return s;
}

nlohmann::json runVolumeDemo(const VolumeDemoOptions& options) {
    const auto start = DemoClock::now();
    checkOptions(options);
    createOutputFolder(options.outDir, FolderErrorWording::CannotCreate);
    DemoSetup run(options.threads > 0 ? options.threads : tbb::info::default_concurrency(), options.progress,
                  "demo volume: interrupted", start);

    const std::shared_ptr<const VolumeWorld> world = makeMedium(run, options);
    const VolumeDemoOptions o = withRigForMedium(run, options, *world);
    const Index n = static_cast<Index>(world->density.voxelCount());
    const VolumeEvaluator trainEval(world, o.rig.training(*world), "volume-train");
    const Index trainFrames = trainEval.frameCount();
    TrainingFrames training = makeTrainingFrames(run, trainEval, n);
    const Trained trained = trainModel(run, o, *world, std::move(training.q), n);

    const ValidationFrames frames = chooseValidationFrames(o, *world);
    const VolumeEvaluator valEval(world, frames.lights, "volume");
    const Index testFrames = valEval.frameCount();
    FullFrames full = calculateFullFrames(run, valEval, frames.fullFrames, n);
    const ReferenceSubset reference =
        chooseReferenceSubset(n, o.referencePoints, frames.between, o.referenceFrames, /*seed=*/20130711);

    ValidationSink sink("volume", full.values, frames.renderFrames, reference.points, reference.frameSet);
    sink.scatteredCount = frames.between;
    const engine::RunStats stats = runThroughEngine(run, trained.model, valEval, sink);
    // The validation frames' distance from the basis: what M and the training lights allow.
    RelError valProjection;
    for (const auto& [f, v] : full.values) addProjectionError(trained.model, v.data(), valProjection);
    const ReferenceErrors refErrors = measureAgainstReference(run, o, *world, reference, full.values, sink);
    const WrittenFiles written = writeCachesAndRenders(run, o, *world, valEval, frames, full.values, sink);
    const nlohmann::json vdbRender = runVdbRender(run, o, *world, frames);

    nlohmann::json report;
    reportMediumAndModel(report, o, *world, n, trained, training, trainFrames, run.threads);
    reportAccuracy(report, full, stats, testFrames, sink, frames, trained, valProjection, reference,
                   refErrors);
    reportLightSpacing(report, o, *world, frames);
    report["cache_tree_bytes"] = written.cacheBytes;
    report["engine"] = nlohmann::json::parse(stats.toJson());
    report["frames"] = frameTable(sink.records, frames);
    report["images"] = written.images;
    report["vdb_files"] = written.vdbs;
    report["vdb_render"] = vdbRender;
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    report["peak_rss_mb"] = static_cast<double>(usage.ru_maxrss) / 1024.0;
    report["seconds"] = run.finish();
    // The model and the scene spec that rebuilds this medium: what `pmsc view` and `pmsc run` take.
    writeModel(o.outDir + "/model.pmsc", trained.model);
    writeFileAtomically(o.outDir + "/scene.txt", "volume:" + o.outDir + "/density.vdb:samples=" +
                                                     std::to_string(o.medium.lightSamples) + "\n");
    writeFileAtomically(o.outDir + "/report.json", report.dump(2) + "\n");
    run.progress("done", 1, 1);
    return report;
}

}  // namespace pmsc::volume
