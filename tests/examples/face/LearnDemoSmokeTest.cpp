// Smoke test of `pmsc demo learn --quick` on the real ICT face: the nightly loop runs,
// exits 0, writes a complete report, and the learned model is a real update of the day-1 one: its
// frames are the day-1 frames plus the kept ones, its basis is the scratch model's to a fraction of
// a degree, and no soft-cached frame of the max-rule loop exceeds the tolerance.
#include "pmsc/KeptFrames.h"
#include "pmsc/ModelIO.h"
#include "tests/common/FaceTestData.h"
#include "tests/examples/face/DemoRun.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace pmsc::face {
namespace {

namespace fs = std::filesystem;

TEST(LearnDemoSmoke, QuickNightlyLoopWritesACompleteReport) {
    PMSC_REQUIRE_ICT();
    const test::DemoFolder folder("pmsc-learn-demo");
    const fs::path out = folder.path / "out";
    ASSERT_EQ(test::runPmsc("demo learn --data '" + test::ictFolder() + "' --out '" + out.string() +
                                "' --quick --quiet",
                            folder),
              0)
        << test::slurp(folder.path / "stderr");
    const nlohmann::json r = nlohmann::json::parse(test::slurp(out / "report.json"));
    for (const char* key :
         {"frames", "models", "day1", "day2", "validation", "learn_vs_scratch", "calibration"})
        EXPECT_TRUE(r.contains(key)) << key;
    const long kept = r.at("frames").at("day1_kept").get<long>();
    EXPECT_GT(kept, 0);
    EXPECT_EQ(r.at("models").at("day2_learned").at("train_frames").get<long>(),
              r.at("frames").at("training").get<long>() + kept);
    EXPECT_LT(r.at("learn_vs_scratch").at("largest_principal_angle_deg").get<double>(), 1.0);
    EXPECT_EQ(r.at("day1").at("frames_over_tolerance").get<long>(), 0);
    EXPECT_EQ(r.at("day2").at("learned_model").at("frames_over_tolerance").get<long>(), 0);
    EXPECT_EQ(r.at("validation").at("learned_model").at("frames_over_tolerance").get<long>(), 0);
    // The learned model on disk carries what the next night needs.
    const Model day2 = readModel((out / "day2.pmsc").string());
    ASSERT_TRUE(day2.learning.has_value());
    EXPECT_EQ(day2.learning->updates, 1);
    EXPECT_EQ(readKeptFrameNumbers((out / "day1-misses.npy").string()).size(), static_cast<size_t>(kept));
}

}  // namespace
}  // namespace pmsc::face
