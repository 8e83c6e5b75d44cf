// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// app::validate, the one set of rules `pmsc train` and Python's pmsc.train apply to their options:
// each rule refuses what it must, names the option as the front end spells it, and lets the
// defaults and the legal combinations through. The command line's messages are checked end to end
// in tests/cli/CliTest.cpp.
#include "app/Train.h"

#include <gtest/gtest.h>

#include <string>

namespace {

using pmsc::app::OptionError;
using pmsc::app::Spelling;
using pmsc::app::TrainOptions;

TrainOptions request() {
    TrainOptions o;
    o.frames = {"train.npy"};
    o.out = "model.pmsc";
    return o;
}

/// The message validate() throws, "" when it accepts the options.
std::string refusal(TrainOptions o, Spelling spelling = Spelling::CommandLine) {
    try {
        pmsc::app::validate(o, spelling);
    } catch (const OptionError& e) {
        return e.what();
    }
    return "";
}

TEST(TrainOptions, DefaultsAreValidAndChooseRegionsFromTheData) {
    TrainOptions o = request();
    EXPECT_EQ(refusal(o), "");
    pmsc::app::validate(o, Spelling::CommandLine);
    EXPECT_TRUE(o.training.regions.automatic);
    EXPECT_TRUE(o.training.learnable);
}

TEST(TrainOptions, OneBasisSizeRule) {
    TrainOptions o = request();
    o.training.basis = 8;
    o.training.energy = 0.99;
    EXPECT_EQ(refusal(o), "give at most one of --basis, --energy, --basis-error");
    EXPECT_EQ(refusal(o, Spelling::Python), "give at most one of basis, energy, basis_error");
    o.training.energy = 0;
    EXPECT_EQ(refusal(o), "");
}

TEST(TrainOptions, CalibrationChoicesNeedATolerance) {
    TrainOptions o = request();
    o.training.calibrationRule = pmsc::CalibrationRule::Conformal;
    EXPECT_EQ(refusal(o), "--calibration and --coverage need --tolerance");
    o.training.tolerance = 0.01;
    EXPECT_EQ(refusal(o), "");

    TrainOptions c = request();
    c.coverage = 0.8;
    EXPECT_EQ(refusal(c, Spelling::Python), "calibration and coverage need tolerance");
    c.training.tolerance = 0.01;
    c.training.calibrationRule = pmsc::CalibrationRule::MaxRatio;
    EXPECT_EQ(refusal(c), "--coverage needs --calibration threshold or conformal");
    c.coverage = 1.0;
    EXPECT_EQ(refusal(c), "--coverage: must be in (0, 1), got 1");

    TrainOptions k = request();
    k.training.keyErrorNorm = pmsc::KeyErrorNorm::Predicted;
    EXPECT_EQ(refusal(k), "--key-error predicted needs --tolerance (each of its parts is calibrated for it)");
}

TEST(TrainOptions, CoverageGoesIntoTheTrainingOptions) {
    TrainOptions o = request();
    o.training.tolerance = 0.01;
    o.training.calibrationRule = pmsc::CalibrationRule::Conformal;
    o.coverage = 0.8;
    pmsc::app::validate(o, Spelling::CommandLine);
    EXPECT_DOUBLE_EQ(o.training.calibrationCoverage, 0.8);
}

TEST(TrainOptions, SharedChannelsRefuseRegionsLearningAndStreamingAndDropAutomaticRegions) {
    TrainOptions o = request();
    o.training.sharedChannels = true;
    EXPECT_EQ(refusal(o), "");
    pmsc::app::validate(o, Spelling::CommandLine);
    EXPECT_FALSE(o.training.regions.automatic);

    TrainOptions r = request();
    r.training.sharedChannels = true;
    r.training.regions.automatic = false;
    r.training.regions.count = 4;
    EXPECT_NE(refusal(r).find("--regions does not combine with --shared-channels"), std::string::npos);
    r.training.regions.count = 0;  // "--regions 0": none, which shared channels have anyway
    EXPECT_EQ(refusal(r), "");
    r.outOfCore = true;
    EXPECT_NE(refusal(r, Spelling::Python).find("out_of_core does not combine with shared_channels"),
              std::string::npos);

    TrainOptions k = request();
    k.training.sharedChannels = true;
    k.training.tolerance = 0.01;
    k.training.keyErrorNorm = pmsc::KeyErrorNorm::LeaveOneOut;
    EXPECT_EQ(refusal(k), "--key-error loo needs channels of their own (not --shared-channels)");
}

TEST(TrainOptions, CrossModelsTakeOneControlFileAndNoFailThroughOptions) {
    TrainOptions o = request();
    o.targets = "target.npy";
    EXPECT_EQ(refusal(o), "");
    o.frames.push_back("more.npy");
    EXPECT_EQ(refusal(o), "--targets takes exactly one --frames file (the control)");
    o.frames.pop_back();
    o.training.regions.ownKeys = 8;
    EXPECT_NE(refusal(o).find("--region-keys does not apply to a cross model"), std::string::npos);
}

TEST(TrainOptions, NamesAreCheckedWithTheOptionNamed) {
    using pmsc::app::selectorNamed;
    EXPECT_EQ(selectorNamed("qdeim", Spelling::CommandLine), pmsc::Selector::QDeim);
    EXPECT_THROW(selectorNamed("best", Spelling::Python), OptionError);
    try {
        selectorNamed("best", Spelling::Python);
    } catch (const OptionError& e) {
        EXPECT_EQ(std::string(e.what()), "selector: 'best' is not teleconnection or qdeim");
    }
    EXPECT_FALSE(pmsc::app::calibrationNamed("", Spelling::CommandLine).has_value());
    EXPECT_THROW(pmsc::app::calibrationNamed("tight", Spelling::CommandLine), OptionError);
    EXPECT_THROW(pmsc::app::keyErrorNamed("l2", Spelling::CommandLine), OptionError);

    pmsc::RegionOptions regions;
    pmsc::app::setRegions(regions, "auto", Spelling::CommandLine);
    EXPECT_TRUE(regions.automatic);
    pmsc::app::setRegions(regions, "12", Spelling::CommandLine);
    EXPECT_FALSE(regions.automatic);
    EXPECT_EQ(regions.count, 12);
    for (const char* bad : {"", "-1", "many", "1e3", "99999999999"})
        EXPECT_THROW(pmsc::app::setRegions(regions, bad, Spelling::CommandLine), OptionError) << bad;
}

TEST(TrainOptions, RegionRangesAreCheckedOnce) {
    TrainOptions o = request();
    o.training.regions.count = -1;
    EXPECT_EQ(refusal(o, Spelling::Python), "regions: must be >= 0 (0 = none), got -1");
    o = request();
    o.training.regions.featherFraction = 0.6;
    EXPECT_EQ(refusal(o), "--feather: must be in [0, 0.5], got 0.6");
    o = request();
    o.training.regions.frameStride = 0;
    EXPECT_EQ(refusal(o, Spelling::Python), "region_stride: must be >= 1, got 0");
    o = request();
    o.training.regions.ownKeys = -2;
    EXPECT_EQ(refusal(o, Spelling::Python), "region_keys: must be >= 0 (0 = none), got -2");
}

}  // namespace
