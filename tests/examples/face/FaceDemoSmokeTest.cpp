// Smoke test of `pmsc demo face --quick` on the real ICT face: the program runs, exits 0, and its
// report has every documented field, within bounds that hold even for the quick run's
// undertrained model (3 training sequences): the soft cache keeps every frame under the 1%
// tolerance by failing through, and catches the novel controls.
#include "evaluators/face/ObjReader.h"
#include "pmsc/Sentinels.h"
#include "tests/common/FaceTestData.h"
#include "tests/examples/face/DemoRun.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace pmsc::face {
namespace {

namespace fs = std::filesystem;

using test::DemoFolder;
using test::slurp;

int run(const std::string& arguments, const DemoFolder& folder) { return test::runPmsc(arguments, folder); }

TEST(FaceDemoSmoke, QuickRunWritesACompleteReport) {
    PMSC_REQUIRE_ICT();
    DemoFolder folder;
    const fs::path out = folder.path / "out";
    ASSERT_EQ(run("demo face --data '" + test::ictFolder() + "' --out '" + out.string() + "' --quick --quiet",
                  folder),
              0)
        << slurp(folder.path / "stderr");
    const nlohmann::json r = nlohmann::json::parse(slurp(out / "report.json"));
    for (const char* field :
         {"points", "key_points", "basis", "train_frames", "test_frames", "full_seconds_per_frame",
          "pmsc_seconds_per_frame", "speedup", "hit_rate", "blend_rate", "miss_rate",
          "max_error_pct_bbox_p995", "soft_max_error_pct_bbox_max", "novel_nonhit_rate"}) {
        ASSERT_TRUE(r.contains(field)) << field;
        ASSERT_TRUE(r.at(field).is_number()) << field;
        ASSERT_TRUE(std::isfinite(r.at(field).get<double>())) << field;
    }
    EXPECT_EQ(r.at("points").get<long>(), 26719);
    EXPECT_GE(r.at("key_points").get<long>(), 68);  // the fiducials are seeded
    EXPECT_LE(r.at("key_points").get<long>(), 170);
    EXPECT_GE(r.at("basis").get<long>(), 1);
    EXPECT_GT(r.at("train_frames").get<long>(), 0);
    EXPECT_GT(r.at("test_frames").get<long>(), 0);
    EXPECT_GT(r.at("full_seconds_per_frame").get<double>(), 0);
    EXPECT_GT(r.at("pmsc_seconds_per_frame").get<double>(), 0);
    // No speed goal here: speed is checked by bench/FaceRigBench.cpp, never by a timed test.
    // The three states partition the test frames (each rate alone in [0, 1] could not fail).
    const double hit = r.at("hit_rate").get<double>(), blend = r.at("blend_rate").get<double>(),
                 miss = r.at("miss_rate").get<double>();
    EXPECT_NEAR(hit + blend + miss, 1.0, 1e-12);
    // Point multiplication alone is not exact on unseen poses, nor far off on the trained kind.
    EXPECT_GT(r.at("max_error_pct_bbox_p995").get<double>(), 0.0);
    EXPECT_LT(r.at("max_error_pct_bbox_p995").get<double>(), 10.0);
    // The soft cache's promise, whatever the model's quality: every frame under the tolerance.
    EXPECT_LT(r.at("soft_max_error_pct_bbox_max").get<double>(), r.at("tolerance_pct_bbox").get<double>());
    EXPECT_GE(r.at("novel_nonhit_rate").get<double>(), 0.9);
    EXPECT_TRUE(r.at("engine").at("decisions_equal_direct").get<bool>());
    // Meshes and pictures a user can open.
    for (const char* label : {"worst", "typical", "novel"}) {
        for (const char* kind : {"_full.obj", "_pm.obj", "_soft.obj"}) {
            Index faces = 0;
            const ObjMesh mesh =
                readObj((out / (std::string(label) + kind)).string(), ObjContent::Positions, &faces);
            EXPECT_EQ(mesh.vertexCount(), 26719) << label << kind;
            EXPECT_EQ(faces, 26384) << label << kind;
        }
        EXPECT_EQ(slurp((out / (std::string(label) + ".png")).string()).substr(0, 8), "\x89PNG\r\n\x1a\n")
            << label;
    }
    EXPECT_TRUE(fs::exists(out / "keys.png"));
    EXPECT_TRUE(fs::exists(out / "frames.csv"));
    // Local fail-through reported both ways on the three sets; the whole-frame way
    // evaluates every point of a non-hit frame, and neither way breaks the tolerance.
    const nlohmann::json& local = r.at("local_fail_through");
    for (const char* set : {"validation", "novel", "mixed"}) {
        ASSERT_TRUE(local.contains(set)) << set;
        const nlohmann::json& s = local.at(set);
        EXPECT_GT(s.at("frames").get<long>(), 0) << set;
        // A hit pays its check's points (pmsc::HitCheck): its sentinels, and when one part of the
        // key error alone certifies it the region keys and at most 64 neighbours (under 3% of the
        // face's points).
        const double hit = s.at("hit_rate").get<double>();
        const double evaluated = s.at("whole_frame").at("points_evaluated_fraction_mean").get<double>();
        const double check = 0.03 + double(pmsc::kDefaultSentinels) / 26719.0;
        EXPECT_GE(evaluated, 1.0 - hit - 1e-12) << set;
        EXPECT_LE(evaluated, 1.0 - hit + check * hit) << set;
        for (const char* way : {"local", "whole_frame"})
            EXPECT_LT(s.at(way).at("soft_max_error_pct_bbox_max").get<double>(),
                      r.at("tolerance_pct_bbox").get<double>())
                << set << " " << way;
        EXPECT_LE(s.at("local").at("points_evaluated_fraction_mean").get<double>(),
                  s.at("whole_frame").at("points_evaluated_fraction_mean").get<double>())
            << set;
    }
}

TEST(FaceDemoSmoke, MissingDataIsOneLineAndExitCode2WithoutOutput) {
    DemoFolder folder;
    const fs::path out = folder.path / "out";
    EXPECT_EQ(run("demo face --data '" + (folder.path / "no-such-folder").string() + "' --out '" +
                      out.string() + "' --quick --quiet",
                  folder),
              2);
    const std::string err = slurp(folder.path / "stderr");
    EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
    EXPECT_NE(err.find("generic_neutral_mesh.obj"), std::string::npos) << err;
    EXPECT_FALSE(fs::exists(out / "report.json"));
}

}  // namespace
}  // namespace pmsc::face
