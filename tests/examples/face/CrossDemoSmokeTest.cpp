// Smoke test of `pmsc demo cross --quick` on the real ICT face (cross point
// multiplication): the demo runs, exits 0, writes a complete report and a cross model whose keys
// are control points, and its figures are sane (errors finite and under 2% of the head diagonal at
// the median although the quick model sees only 2 short sequences, a bound that holds on most
// validation frames, cross PM faster than the full rig).
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

TEST(CrossDemoSmoke, QuickRunWritesACompleteReport) {
    PMSC_REQUIRE_ICT();
    const test::DemoFolder folder("pmsc-cross-demo");
    const fs::path out = folder.path / "out";
    ASSERT_EQ(test::runPmsc("demo cross --data '" + test::ictFolder() + "' --out '" + out.string() +
                                "' --quick --quiet",
                            folder),
              0)
        << test::slurp(folder.path / "stderr");
    const nlohmann::json r = nlohmann::json::parse(test::slurp(out / "report.json"));
    for (const char* key : {"model", "bound", "validation", "novel", "speed", "frames"})
        EXPECT_TRUE(r.contains(key)) << key;
    const auto& v = r.at("validation");
    EXPECT_GT(v.at("frames").get<long>(), 0);
    const double err = v.at("error_pct_bbox").at("max").get<double>();
    EXPECT_TRUE(std::isfinite(err));
    EXPECT_LT(v.at("error_pct_bbox").at("p50").get<double>(), 2.0);
    EXPECT_GT(v.at("inside_bound_rate").get<double>(), 0.5);
    EXPECT_GT(r.at("speed").at("speedup_cpu").get<double>(), 1.0);
    const Model model = readModel((out / "cross.pmsc").string());
    ASSERT_TRUE(model.cross.has_value());
    for (Index k : model.keyPoints) EXPECT_LT(k, model.cross->controlPoints);
}

}  // namespace
}  // namespace pmsc::face
