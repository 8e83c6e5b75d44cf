// The model-file sections of `pmsc learn`: LEARNSVD and CALIBRAT round trips and bad bytes.
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "tests/common/SmallModel.h"

#include <gtest/gtest.h>

#include <cstring>

namespace {

pmsc::Model learnableModel() {
    pmsc::Model m = pmsc::test::smallModel();
    pmsc::LearningState s;
    s.maxRank = 6;
    s.extraBasis = Eigen::MatrixXd(21, 2);
    for (Eigen::Index i = 0; i < s.extraBasis.size(); ++i) s.extraBasis.data()[i] = std::cos(0.37 * i);
    s.extraSigma = Eigen::Vector2d(0.1, 0.0625);
    s.discardedEnergy = 0.03125;
    s.updates = 2;
    s.maxKeys = 3;
    s.block = 2;
    s.maxError = 0.5;
    s.fiducials = {4};
    s.gridPoints = {6, 1};
    s.basisEnergy = 0.9999;
    m.learning = s;
    pmsc::CalibrationRecord r;
    r.rule = pmsc::CalibrationRule::Conformal;
    r.coverage = 0.9;
    r.slices = 5;
    r.keyRms = {0.1, 0.2, 0.3};
    r.maxPointError = {0.4, 0.5, 0.75};
    m.calibrationRecord = r;
    return m;
}

// Offset of a section's tag in an encoded model.
std::size_t find(const std::string& bytes, const char* tag) {
    const std::size_t at = bytes.find(std::string(tag, 8));
    EXPECT_NE(at, std::string::npos) << tag;
    return at;
}

void refix(std::string& bytes) {
    const std::uint64_t sum = pmsc::fnv1a64(bytes.data(), bytes.size() - 8);
    std::memcpy(bytes.data() + bytes.size() - 8, &sum, 8);
}

}  // namespace

TEST(LearningSections, RoundTripBitExact) {
    const pmsc::Model m = learnableModel();
    const std::string bytes = pmsc::encodeModel(m);
    std::uint32_t version = 0;
    std::memcpy(&version, bytes.data() + 8, 4);
    EXPECT_EQ(version, 2u);
    const pmsc::Model back = pmsc::decodeModel(bytes, "m.pmsc");
    ASSERT_TRUE(back.learning && back.calibrationRecord);
    EXPECT_EQ(back.learning->maxRank, 6);
    EXPECT_EQ(back.learning->extraBasis, m.learning->extraBasis);
    EXPECT_EQ(back.learning->extraSigma, m.learning->extraSigma);
    EXPECT_EQ(back.learning->discardedEnergy, m.learning->discardedEnergy);
    EXPECT_EQ(back.learning->updates, 2);
    EXPECT_EQ(back.learning->maxKeys, 3);
    EXPECT_EQ(back.learning->block, 2);
    EXPECT_EQ(back.learning->maxError, 0.5);
    EXPECT_EQ(back.learning->fiducials, m.learning->fiducials);
    EXPECT_EQ(back.learning->gridPoints, m.learning->gridPoints);
    EXPECT_EQ(back.learning->basisEnergy, 0.9999);
    EXPECT_EQ(back.calibrationRecord->rule, pmsc::CalibrationRule::Conformal);
    EXPECT_EQ(back.calibrationRecord->coverage, 0.9);
    EXPECT_EQ(back.calibrationRecord->slices, 5);
    EXPECT_EQ(back.calibrationRecord->keyRms, m.calibrationRecord->keyRms);
    EXPECT_EQ(back.calibrationRecord->maxPointError, m.calibrationRecord->maxPointError);
    EXPECT_EQ(pmsc::encodeModel(back), bytes);
}

TEST(LearningSections, ASectionWithoutTheBasisRuleLoadsWithMFixed) {
    // A LEARNSVD section that ends after the grid points (the basis rule is its optional last
    // field) loads, with basisEnergy 0: updates keep M.
    std::string bytes = pmsc::encodeModel(learnableModel());
    const std::size_t learn = find(bytes, "LEARNSVD");
    std::uint64_t length = 0;
    std::memcpy(&length, bytes.data() + learn + 8, 8);
    bytes.erase(learn + 16 + length - 8, 8);
    length -= 8;
    std::memcpy(bytes.data() + learn + 8, &length, 8);
    refix(bytes);
    const pmsc::Model back = pmsc::decodeModel(bytes, "m.pmsc");
    ASSERT_TRUE(back.learning);
    EXPECT_EQ(back.learning->basisEnergy, 0.0);
    EXPECT_EQ(back.learning->gridPoints, learnableModel().learning->gridPoints);
}

TEST(LearningSections, APlainModelStaysVersion1) {
    const std::string bytes = pmsc::encodeModel(pmsc::test::smallModel());
    std::uint32_t version = 0;
    std::memcpy(&version, bytes.data() + 8, 4);
    EXPECT_EQ(version, 1u);
}

TEST(LearningSections, BadValuesNameTheSectionAndTheField) {
    const std::string good = pmsc::encodeModel(learnableModel());
    auto expectBad = [&](std::string bytes, const char* fragment) {
        refix(bytes);
        try {
            pmsc::decodeModel(bytes, "m.pmsc");
            ADD_FAILURE() << "accepted, expected " << fragment;
        } catch (const pmsc::InputError& e) {
            EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
        }
    };
    // LEARNSVD payload: u64 rank at +16 from the tag.
    const std::size_t learn = find(good, "LEARNSVD");
    std::string b = good;
    const std::uint64_t tooSmallRank = 2;  // below M = 3
    std::memcpy(b.data() + learn + 16, &tooSmallRank, 8);
    expectBad(b, "LEARNSVD");
    b = good;
    const std::uint64_t hugeCount = 1ull << 40;  // extra vectors: more than the bytes left could hold
    std::memcpy(b.data() + learn + 16 + 24, &hugeCount, 8);
    expectBad(b, "extra vector count");
    b = good;
    const double negative = -1;  // first extra singular value
    std::memcpy(b.data() + learn + 16 + 32, &negative, 8);
    expectBad(b, "singular values");
    b = good;
    std::uint64_t learnLength = 0;
    std::memcpy(&learnLength, good.data() + learn + 8, 8);
    const double badEnergy = 1.5;  // the basis rule, the section's last field
    std::memcpy(b.data() + learn + 16 + learnLength - 8, &badEnergy, 8);
    expectBad(b, "basis energy");
    // CALIBRAT payload: u32 rule at +16.
    const std::size_t calib = find(good, "CALIBRAT");
    b = good;
    const std::uint32_t rule = 7;
    std::memcpy(b.data() + calib + 16, &rule, 4);
    expectBad(b, "rule 7");
    b = good;
    const double badCoverage = 1.5;
    std::memcpy(b.data() + calib + 24, &badCoverage, 8);
    expectBad(b, "coverage");
    // Truncated: the section's declared length runs past the checksum.
    b = good.substr(0, calib + 20) + good.substr(good.size() - 8);
    expectBad(b, "m.pmsc");
}
