// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
// Internal to the face demo (not installed): what the steps of runFaceDemo hand each other.
// FaceDemo.cpp runs the steps up to the timing; FaceDemoOutput.cpp writes the files and the report.
#pragma once

#include "evaluators/face/FaceAnimation.h"
#include "evaluators/face/FaceEvaluator.h"
#include "evaluators/face/FaceRig.h"
#include "examples/common/DemoSetup.h"
#include "examples/face/FaceDemo.h"
#include "pmsc/Errors.h"
#include "pmsc/Model.h"
#include "pmsc/ObjIO.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/SoftCache.h"
#include "pmsc/Training.h"

#include <nlohmann/json.hpp>

#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace pmsc::face::demo {

using examples::DemoClock;
using examples::DemoSetup;
using examples::secondsSince;
using examples::threadCpuSeconds;

inline const char* stateName(CacheState s) {
    return s == CacheState::Hit ? "hit" : s == CacheState::Blend ? "blend" : "miss";
}

// What the demo knows about one test frame.
struct FrameRecord {
    Index frame = 0;
    Index sequence = 0;
    bool novel = false;
    double keyRms = 0;
    CacheState state = CacheState::Hit;
    double weight = 0;
    double pmMax = 0;    // largest point error of PM vs the full pose (model units)
    double softMax = 0;  // same for the soft-cached result
    // From the engine run:
    bool engineSeen = false;
    bool engineAgrees = false;
};

// What every step needs: the options, the shared set-up (progress hook, worker arena, timings) and
// the output folder.
struct DemoRun {
    const FaceDemoOptions& options;
    DemoSetup& setup;
    std::string out;  // the output folder with a trailing '/'
};

// The face, the rig, the animation and the rig as an evaluator.
struct FaceScene {
    std::shared_ptr<const FaceRig> rig;
    std::shared_ptr<const ObjMesh> mesh;
    FaceAnimationOptions animationOptions;
    std::shared_ptr<const FaceAnimation> animation;
    FaceEvaluator evaluator;
    Index n = 0;          // points
    double diagonal = 0;  // of the head's bounding box
    double percent = 0;   // model units per % of the head diagonal
};

// Sequences (indices into the animation's) by use; the training sequences' frames.
struct SequenceSplit {
    std::vector<Index> trainingSeqs, validationSeqs, novelSeqs;
    std::vector<Index> trainingFrames;
};

struct TrainedModel {
    Model model;
    TrainingReport report;
};

// The test records by set, and the frames shown: the validation frame with the largest PM error
// (the paper's figure 4), the median validation frame, and the median novel frame.
struct TestFrames {
    std::vector<const FrameRecord*> validation, novel;
    std::vector<std::pair<std::string, const FrameRecord*>> shown;
};

// What the engine did with the test sequences; [0] validation, [1] novel.
struct EngineTotals {
    nlohmann::json runs = nlohmann::json::array();  // a sample of per-run stats
    Index hits[2] = {0, 0}, blends[2] = {0, 0}, misses[2] = {0, 0}, frames[2] = {0, 0};
    double wall[2] = {0, 0};
    Index disagreements = 0, unseen = 0;  // frames whose decision differs from the direct one; not delivered
    std::map<Index, std::vector<double>> kept;  // the output of the shown frames
};

// Seconds summed over the timed frames: thread CPU time and wall time.
struct PoseTimings {
    double cpuFull = 0, cpuPosing = 0, cpuProject = 0, cpuCheck = 0, cpuReconstruct = 0;
    double wallFull = 0, wallPosing = 0, wallProject = 0, wallCheck = 0, wallReconstruct = 0;
    double cpuKeys = 0;      // the keys alone, in a call of their own (a hit without the check)
    double checkPoints = 0;  // points the hits' checks compared, summed over the frames
    Index timed = 0;         // frames

    double fullSeconds() const { return cpuFull / static_cast<double>(timed); }
    /// A hit's cost: its keys and sentinels (one call), projection, the rest of its check
    /// (pmsc::HitCheck) and reconstruction.
    double pmscSeconds() const {
        return (cpuPosing + cpuProject + cpuCheck + cpuReconstruct) / static_cast<double>(timed);
    }
    double pmscWallSeconds() const {
        return (wallPosing + wallProject + wallCheck + wallReconstruct) / static_cast<double>(timed);
    }
};

struct WrittenFiles {
    nlohmann::json files = nlohmann::json::array();  // names, in the order written
    nlohmann::json shown = nlohmann::json::array();  // report.json's "shown_frames"
};

// --- FaceDemoOutput.cpp ---------------------------------------------------------------------------

// Files: renders, meshes, the model, the per-frame table.
WrittenFiles writeFiles(const DemoRun& run, const FaceScene& scene, const Model& model,
                        const PointMultiplier& pm, const std::vector<FrameRecord>& records,
                        const TestFrames& sets, const EngineTotals& engine);

// What was run on what: sizes of the face, the model and the sets.
void reportSetUp(nlohmann::json& report, const FaceDemoOptions& options, const FaceScene& scene,
                 const Model& model, const SequenceSplit& split, const TestFrames& sets);
void reportTiming(nlohmann::json& report, const PoseTimings& pt);
// Where the selector put the key points (upstream region table, face split by the mouth box), and
// what posing them costs.
void reportKeyPoints(nlohmann::json& report, const FaceRig& rig, const Model& model);
// Decisions, errors and thresholds: the headline rates and the validation, novel and engine sections.
void reportAccuracy(nlohmann::json& report, const FaceDemoOptions& options, const FaceScene& scene,
                    const TrainedModel& trained, const std::vector<FrameRecord>& records,
                    const TestFrames& sets, const EngineTotals& engine);

}  // namespace pmsc::face::demo
