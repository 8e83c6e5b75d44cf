// The regions `pmsc train` chooses when not told (RegionChoice.h): on a sheet whose motions are
// local bumps it learns regions, on a sheet deformed whole, on light-like values and without a
// tolerance it leaves the model whole.
#include "pmsc/RegionChoice.h"
#include "pmsc/Training.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>

namespace {

using pmsc::Index;

constexpr Index kSide = 48;  // 2,304 points: 13 regions of 167
constexpr Index kFrames = 120;

enum class Motion { LocalBumps, Whole, Light };

/// A kSide x kSide sheet in the unit square moved by six controls: each a Gaussian bump of its own
/// (LocalBumps), each a wave over the whole sheet (Whole), or values that swing by more than the
/// sheet's size (Light: like irradiance, not positions).
pmsc::FrameSet sheet(Motion motion) {
    pmsc::FrameSet frames(kFrames, kSide * kSide, 3);
    for (Index f = 0; f < kFrames; ++f) {
        double* out = frames.frame(f);
        for (Index p = 0; p < kSide * kSide; ++p) {
            const double x = double(p % kSide) / double(kSide - 1), y = double(p / kSide) / double(kSide - 1);
            double z = 0;
            for (int c = 0; c < 6; ++c) {
                const double amp = std::sin(0.05 * (c + 1) * double(f) + 1.3 * c);
                const double cx = 0.2 + 0.3 * (c % 3), cy = c < 3 ? 0.3 : 0.7;
                if (motion == Motion::LocalBumps)
                    z += 0.1 * amp * std::exp(-((x - cx) * (x - cx) + (y - cy) * (y - cy)) / 0.01);
                else
                    z += 0.1 * amp * std::sin(std::numbers::pi * ((c + 1) * x + (c % 2 + 1) * y) + c);
            }
            const double scale = motion == Motion::Light ? 30.0 : 1.0;
            out[3 * p + 0] = x;
            out[3 * p + 1] = y;
            out[3 * p + 2] = scale * z;
        }
    }
    return frames;
}

pmsc::TrainingOptions automatic(double tolerance) {
    pmsc::TrainingOptions o;
    o.maxKeys = 40;
    o.tolerance = tolerance;
    o.regions.automatic = true;
    o.regions.frameStride = 3;
    return o;
}

TEST(RegionChoice, LocalMotionsGetRegionsFromThePointCount) {
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(sheet(Motion::LocalBumps), automatic(1e-3), &report);
    EXPECT_LT(pmsc::basisSupport(model), 0.25);
    ASSERT_TRUE(model.regions.has_value()) << report.regions;
    EXPECT_EQ(report.regions.rfind("13, feather", 0), 0u) << report.regions;
    EXPECT_GE(model.regions->regionCount(), 8);
    EXPECT_LE(model.regions->regionCount(), 13);
    // The feather comes with R: 0.25 / sqrt(13) of the sheet's diagonal.
    EXPECT_NEAR(model.regions->featherWidth, 0.25 / std::sqrt(13.0) * std::sqrt(2.0), 0.02);
}

TEST(RegionChoice, DataThatPoseWholeStayWhole) {
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(sheet(Motion::Whole), automatic(1e-3), &report);
    EXPECT_GT(pmsc::basisSupport(model), 0.25);
    EXPECT_FALSE(model.regions.has_value());
    EXPECT_NE(report.regions.find("none: a motion moves"), std::string::npos) << report.regions;
}

TEST(RegionChoice, LightLikeValuesAreNotPositions) {
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(sheet(Motion::Light), automatic(1e-2), &report);
    EXPECT_FALSE(model.regions.has_value());
    EXPECT_NE(report.regions.find("not point positions"), std::string::npos) << report.regions;
}

TEST(RegionChoice, NoToleranceOrTooFewPointsMeanNoRegions) {
    pmsc::TrainingReport report;
    pmsc::Model model = pmsc::train(sheet(Motion::LocalBumps), automatic(0), &report);
    EXPECT_FALSE(model.regions.has_value());
    EXPECT_NE(report.regions.find("--tolerance"), std::string::npos) << report.regions;

    const pmsc::RegionChoice few = pmsc::chooseRegions(model, {}, 1e-3, 0.0);
    EXPECT_EQ(few.count, 13);  // the same model, asked with a tolerance
    model.points = 1000;       // what the rule reads of N: 1000 / 167 = 5 < 8 regions
    const pmsc::RegionChoice none = pmsc::chooseRegions(model, {}, 1e-3, 0.0);
    EXPECT_EQ(none.count, 0);
    EXPECT_NE(none.reason.find("fewer than 8 regions"), std::string::npos) << none.reason;
}

TEST(RegionChoice, AnExplicitCountOverridesAndTheStrideIsChecked) {
    pmsc::TrainingOptions o = automatic(1e-3);
    o.regions.automatic = false;
    o.regions.count = 4;  // learned although the sheet poses whole
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(sheet(Motion::Whole), o, &report);
    ASSERT_TRUE(model.regions.has_value());
    EXPECT_LE(model.regions->regionCount(), 4);
    EXPECT_TRUE(report.regions.empty());

    o.regions.frameStride = 0;
    EXPECT_THROW(pmsc::train(sheet(Motion::Whole), o), std::invalid_argument);
}

}  // namespace
