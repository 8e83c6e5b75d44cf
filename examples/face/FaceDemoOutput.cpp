#include "examples/face/FaceDemoSteps.h"

#include "evaluators/face/FaceControls.h"
#include "evaluators/face/IctFace.h"
#include "evaluators/face/ObjWriter.h"
#include "examples/face/FaceRenderer.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Metrics.h"
#include "pmsc/ModelIO.h"

#include <algorithm>
#include <cstdio>
#include <sstream>

namespace pmsc::face::demo {

namespace {

nlohmann::json summary(const std::vector<double>& v) {
    return {{"p50", percentile(v, 0.5)},
            {"p99", percentile(v, 0.99)},
            {"p995", percentile(v, 0.995)},
            {"max", v.empty() ? 0.0 : *std::max_element(v.begin(), v.end())}};
}

// The renderer and the two views of the pictures written.
struct FacePictures {
    FaceRenderer renderer;
    OrthoView faceView{400, 480, Eigen::Vector3d(0, 0, 0), 19.0, 0.0};
    OrthoView mouthView{400, 260, Eigen::Vector3d(0, -3.6, 10), 55.0, 0.0};
};

// Per point: the error colour of `pose` against `full`.
std::vector<float> errorColours(const std::vector<double>& pose, const std::vector<double>& full, Index n,
                                double percent) {
    std::vector<float> colours(static_cast<size_t>(3 * n));
    for (Index p = 0; p < n; ++p) {
        const auto a =
            errorColour((Eigen::Vector3d(&pose[3 * p]) - Eigen::Vector3d(&full[3 * p])).norm(), percent);
        for (int c = 0; c < 3; ++c) colours[3 * p + c] = a[c];
    }
    return colours;
}

// Full | PM | soft-cached side by side, the face above the mouth, with a colour bar of 0 .. 1%
// of the head diagonal under the PM and soft-cache columns.
RgbImage comparisonSheet(const FacePictures& pics, const std::vector<double>* poses[3],
                         const std::vector<float>* colours[3]) {
    const OrthoView& faceView = pics.faceView;
    const OrthoView& mouthView = pics.mouthView;
    RgbImage sheet(3 * faceView.width, faceView.height + mouthView.height + 16, {20, 20, 24});
    for (int col = 0; col < 3; ++col) {
        sheet.paste(pics.renderer.render(*poses[col], *colours[col], faceView), col * faceView.width, 0);
        sheet.paste(pics.renderer.render(*poses[col], *colours[col], mouthView), col * mouthView.width,
                    faceView.height);
    }
    for (int x = 0; x < 2 * faceView.width; ++x) {
        const auto c = errorColour(static_cast<double>(x) / (2 * faceView.width - 1), 1.0);
        for (int y = 0; y < 12; ++y) {
            std::uint8_t* px = sheet.at(faceView.width + x, faceView.height + mouthView.height + 2 + y);
            for (int ch = 0; ch < 3; ++ch) px[ch] = static_cast<std::uint8_t>(255 * c[ch]);
        }
    }
    return sheet;
}

// LABEL_{full,pm,soft}.obj and LABEL.png of one shown frame; returns its entry of "shown_frames".
nlohmann::json writeShownFrame(const DemoRun& run, const FaceScene& scene, const Model& model,
                               const PointMultiplier& pm, const FacePictures& pics, const std::string& label,
                               const FrameRecord& record, const std::vector<double>& soft,
                               nlohmann::json& files) {
    const Index n = scene.n;
    const std::string& out = run.out;
    std::vector<double> full(static_cast<size_t>(3 * n)), pmPose(static_cast<size_t>(3 * n));
    std::vector<double> keys(static_cast<size_t>(3 * model.keyCount())),
        coords(static_cast<size_t>(model.coordCount()));
    scene.evaluator.evaluateAll(record.frame, full.data());
    for (Index k = 0; k < model.keyCount(); ++k) {
        for (int c = 0; c < 3; ++c) keys[3 * k + c] = full[3 * model.keyPoints[k] + c];
    }
    pm.project(keys.data(), coords.data());
    pm.reconstruct(coords.data(), pmPose.data());
    const FaceSequence& seq = scene.animation->sequences()[record.sequence];
    const std::string frameName = seq.name + " frame " + std::to_string(record.frame - seq.firstFrame);
    writeObj(out + label + "_full.obj", *scene.mesh, full, "pmsc demo face: " + frameName + ", full pose");
    writeObj(out + label + "_pm.obj", *scene.mesh, pmPose,
             "pmsc demo face: " + frameName + ", point multiplication");
    writeObj(out + label + "_soft.obj", *scene.mesh, soft,
             std::string("pmsc demo face: ") + frameName + ", soft cache (" + stateName(record.state) + ")");
    const std::vector<float> grey(static_cast<size_t>(3 * n), 0.8f);
    const std::vector<float> pmColour = errorColours(pmPose, full, n, scene.percent);
    const std::vector<float> softColour = errorColours(soft, full, n, scene.percent);
    const std::vector<double>* poses[3] = {&full, &pmPose, &soft};
    const std::vector<float>* colours[3] = {&grey, &pmColour, &softColour};
    writePng(out + label + ".png", comparisonSheet(pics, poses, colours));
    for (const char* suffix : {"_full.obj", "_pm.obj", "_soft.obj", ".png"}) files.push_back(label + suffix);
    return {{"label", label},
            {"sequence", seq.name},
            {"frame", record.frame},
            {"state", stateName(record.state)},
            {"weight", record.weight},
            {"key_rms", record.keyRms},
            {"pm_max_error_pct_bbox", record.pmMax / scene.percent},
            {"soft_max_error_pct_bbox", record.softMax / scene.percent},
            {"engine_soft_max_error_pct_bbox", maxPointError(soft.data(), full.data(), n) / scene.percent}};
}

// keys.png: the neutral face with the key points (red) and the fiducials (blue).
void writeKeyPointsImage(const DemoRun& run, const FaceScene& scene, const Model& model,
                         const FacePictures& pics) {
    const std::vector<double>& rest = scene.rig->restPositions();
    std::vector<float> colour(static_cast<size_t>(3 * scene.n), 0.8f);
    RgbImage image = pics.renderer.render(rest, colour, pics.faceView);
    pics.renderer.drawPoints(image, rest, model.keyPoints, pics.faceView, {230, 30, 30}, 2);
    const std::vector<Index> fiducials(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
    pics.renderer.drawPoints(image, rest, fiducials, pics.faceView, {40, 110, 255}, 2);
    writePng(run.out + "keys.png", image);
}

// frames.csv: one line per test frame.
void writeFramesCsv(const DemoRun& run, const FaceScene& scene, const std::vector<FrameRecord>& records) {
    std::ostringstream csv;
    csv << "frame,sequence,set,key_rms,state,weight,pm_max_error_pct_bbox,soft_max_error_pct_bbox,engine_"
           "agrees\n";
    char line[256];
    for (const FrameRecord& r : records) {
        std::snprintf(line, sizeof line, "%ld,%s,%s,%.9g,%s,%.6f,%.6f,%.6f,%d\n", static_cast<long>(r.frame),
                      scene.animation->sequences()[r.sequence].name.c_str(), r.novel ? "novel" : "validation",
                      r.keyRms, stateName(r.state), r.weight, r.pmMax / scene.percent,
                      r.softMax / scene.percent, r.engineAgrees ? 1 : 0);
        csv << line;
    }
    writeFileAtomically(run.out + "frames.csv", csv.str());
}

// Per-frame values of the report's summaries (errors in % of the head diagonal).
struct ErrorSamples {
    std::vector<double> pmVal, softVal, pmNovel, softAll, keyVal, keyNovel;
};

ErrorSamples collectErrors(const std::vector<FrameRecord>& records, double percent) {
    ErrorSamples e;
    for (const FrameRecord& r : records) {
        e.softAll.push_back(r.softMax / percent);
        if (r.novel) {
            e.pmNovel.push_back(r.pmMax / percent);
            e.keyNovel.push_back(r.keyRms);
        } else {
            e.pmVal.push_back(r.pmMax / percent);
            e.softVal.push_back(r.softMax / percent);
            e.keyVal.push_back(r.keyRms);
        }
    }
    return e;
}

}  // namespace

// Files: renders, meshes, the model, the per-frame table.
WrittenFiles writeFiles(const DemoRun& run, const FaceScene& scene, const Model& model,
                        const PointMultiplier& pm, const std::vector<FrameRecord>& records,
                        const TestFrames& sets, const EngineTotals& engine) {
    const DemoClock::time_point t = DemoClock::now();
    run.setup.progress("write", 0, 1);
    const FacePictures pics{FaceRenderer(scene.rig->topology(), FaceRenderer::ictHiddenVertices(scene.n))};
    WrittenFiles written;
    for (const auto& [label, record] : sets.shown) {
        written.shown.push_back(writeShownFrame(run, scene, model, pm, pics, label, *record,
                                                engine.kept.at(record->frame), written.files));
    }
    writeKeyPointsImage(run, scene, model, pics);
    written.files.push_back("keys.png");
    writeModel(run.out + "face.pmsc", model);
    written.files.push_back("face.pmsc");
    writeFramesCsv(run, scene, records);
    written.files.push_back("frames.csv");
    run.setup.lap("write", t);
    return written;
}

// What was run on what: sizes of the face, the model and the sets.
void reportSetUp(nlohmann::json& report, const FaceDemoOptions& options, const FaceScene& scene,
                 const Model& model, const SequenceSplit& split, const TestFrames& sets) {
    report["experiment"] =
        "paper section 7: facial articulation, point multiplication and soft caching of a face rig";
    report["quick"] = options.quick;
    report["full"] = options.localFailThroughReport;
    report["data"] = options.dataDir;
    report["points"] = scene.n;
    report["key_points"] = model.keyCount();
    report["fiducials"] = static_cast<Index>(IctFace::multiPie68().size());
    report["basis"] = model.basisSize();
    report["train_frames"] = static_cast<Index>(split.trainingFrames.size());
    report["test_frames"] = static_cast<Index>(sets.validation.size());
    report["novel_frames"] = static_cast<Index>(sets.novel.size());
    report["sequences"] = {{"training", split.trainingSeqs.size()},
                           {"validation", split.validationSeqs.size()},
                           {"novel", split.novelSeqs.size()}};
}

void reportTiming(nlohmann::json& report, const PoseTimings& pt) {
    const Index timed = pt.timed;
    const double fullSeconds = pt.fullSeconds();
    const double pmscSeconds = pt.pmscSeconds();
    report["full_seconds_per_frame"] = fullSeconds;
    report["pmsc_seconds_per_frame"] = pmscSeconds;
    report["speedup"] = fullSeconds / pmscSeconds;
    report["timing"] = {
        {"clock",
         "thread CPU time, one thread, one frame at a time, full pose and PMSC interleaved "
         "on the same frames"},
        {"frames", timed},
        {"full_pose", fullSeconds},
        {"key_and_sentinel_posing", pt.cpuPosing / static_cast<double>(timed)},
        {"key_posing", pt.cpuKeys / static_cast<double>(timed)},
        {"projection", pt.cpuProject / static_cast<double>(timed)},
        {"hit_check", pt.cpuCheck / static_cast<double>(timed)},
        {"hit_check_points", pt.checkPoints / static_cast<double>(timed)},
        {"reconstruction", pt.cpuReconstruct / static_cast<double>(timed)},
        {"key_cost_fraction", pt.cpuKeys / pt.cpuFull},
        {"speedup_without_check", pt.cpuFull / (pt.cpuKeys + pt.cpuProject + pt.cpuReconstruct)},
        {"wall",
         {{"full_pose", pt.wallFull / static_cast<double>(timed)},
          {"pmsc", pt.pmscWallSeconds()},
          {"speedup", pt.wallFull / (pt.pmscWallSeconds() * static_cast<double>(timed))}}}};
}

// Where the selector put the key points (upstream region table, face split by the mouth box), and
// what posing them costs.
void reportKeyPoints(nlohmann::json& report, const FaceRig& rig, const Model& model) {
    const FaceRig::ClosureSize closure = rig.closureSize(model.keyPoints);
    Index lipKeys = 0;
    for (Index k : model.keyPoints) lipKeys += rig.lipContact().inZone(k) ? 1 : 0;
    nlohmann::json where = nlohmann::json::object();
    for (Index k : model.keyPoints) {
        std::string name = "other";
        for (const char* r : {"face", "head_and_neck", "mouth_socket", "eye_socket_left", "eye_socket_right",
                              "gums_and_tongue", "teeth", "eyeball_left", "eyeball_right", "eyelashes_left",
                              "eyelashes_right", "lacrimal_left", "lacrimal_right", "eye_occlusion_left",
                              "eye_occlusion_right", "eye_blend_left", "eye_blend_right"}) {
            if (IctFace::region(r).contains(k)) {
                name = r;
                break;
            }
        }
        if (name == "face" && rig.lipContact().inMouthBox(k)) name = "face (mouth)";
        where[name] = where.value(name, 0) + 1;
    }
    report["key_points_by_region"] = where;
    report["key_point_indices"] = model.keyPoints;
    report["dependency_closure_of_keys"] = {{"blendshape_stage", closure.blendshapes},
                                            {"relaxed", closure.relax},
                                            {"contact_evaluations", closure.contact},
                                            {"lip_keys", lipKeys}};
}

// Decisions, errors and thresholds: the headline rates and the validation, novel and engine sections.
void reportAccuracy(nlohmann::json& report, const FaceDemoOptions& options, const FaceScene& scene,
                    const TrainedModel& trained, const std::vector<FrameRecord>& records,
                    const TestFrames& sets, const EngineTotals& engine) {
    const Model& model = trained.model;
    const double percent = scene.percent;
    const ErrorSamples e = collectErrors(records, percent);
    const double valFrames = static_cast<double>(engine.frames[0]);
    report["hit_rate"] = static_cast<double>(engine.hits[0]) / valFrames;
    report["blend_rate"] = static_cast<double>(engine.blends[0]) / valFrames;
    report["miss_rate"] = static_cast<double>(engine.misses[0]) / valFrames;
    report["max_error_pct_bbox_p995"] = percentile(e.pmVal, 0.995);
    report["soft_max_error_pct_bbox_max"] =
        e.softAll.empty() ? 0.0 : *std::max_element(e.softAll.begin(), e.softAll.end());
    report["novel_nonhit_rate"] =
        static_cast<double>(engine.blends[1] + engine.misses[1]) / static_cast<double>(engine.frames[1]);
    report["bbox_diagonal"] = scene.diagonal;
    report["tolerance_pct_bbox"] = options.tolerancePercent;
    report["eps_min"] = model.epsMin;
    report["eps_max"] = model.epsMax;
    report["eps_min_pct_bbox"] = model.epsMin / percent;
    report["calibration_ratio"] = trained.report.calibration.ratio;
    report["train_max_point_residual_pct_bbox"] = model.trainMaxPointResidual / percent;
    report["training_warnings"] = trained.report.warnings;
    report["validation"] = {{"frames", sets.validation.size()},
                            {"hits", engine.hits[0]},
                            {"blends", engine.blends[0]},
                            {"misses", engine.misses[0]},
                            {"pm_max_error_pct_bbox", summary(e.pmVal)},
                            {"soft_max_error_pct_bbox", summary(e.softVal)},
                            {"key_rms", summary(e.keyVal)},
                            {"engine_wall_seconds", engine.wall[0]}};
    nlohmann::json controls = nlohmann::json::array();
    for (const int control : scene.animationOptions.novelControls) controls.push_back(controlName(control));
    report["novel"] = {{"frames", sets.novel.size()},
                       {"hits", engine.hits[1]},
                       {"blends", engine.blends[1]},
                       {"misses", engine.misses[1]},
                       {"pm_max_error_pct_bbox", summary(e.pmNovel)},
                       {"key_rms", summary(e.keyNovel)},
                       {"controls", controls},
                       {"engine_wall_seconds", engine.wall[1]}};
    report["engine"] = {{"decisions_equal_direct", engine.disagreements == 0 && engine.unseen == 0},
                        {"disagreements", engine.disagreements},
                        {"frames_not_delivered", engine.unseen},
                        {"threads", options.threads},
                        {"runs_sample", engine.runs}};
}

}  // namespace pmsc::face::demo
