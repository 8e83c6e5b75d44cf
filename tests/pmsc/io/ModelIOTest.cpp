#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"

#include "tests/common/ModelBytes.h"
#include "tests/common/SmallModel.h"
#include "tests/common/TempDir.h"

#include <gtest/gtest.h>
#include <Eigen/QR>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>

namespace {

using pmsc::InputError;
using pmsc::Model;
using pmsc::test::poke;
using pmsc::test::reseal;
using pmsc::test::smallModel;
using pmsc::test::TempDir;
using pmsc::test::writeBytes;

std::string inputErrorMessage(const std::string& path) {
    try {
        pmsc::readModel(path);
    } catch (const InputError& e) {
        return e.what();
    } catch (const std::exception& e) {
        return std::string("WRONG EXCEPTION TYPE: ") + e.what();
    }
    return "NO ERROR";
}

void expectRejected(const std::string& path, std::initializer_list<std::string> fragments) {
    const std::string what = inputErrorMessage(path);
    EXPECT_EQ(what.rfind(path + ": ", 0), 0u) << what;
    for (const auto& f : fragments) EXPECT_NE(what.find(f), std::string::npos) << what;
}

/// `m`'s file with a value written over its KEYERROR section at `offset` (0: the norm, 4: the
/// first part threshold of a predicted error), resealed, at `path`.
template <typename T>
void writeWithKeyErrorPoked(const Model& m, std::size_t offset, T value, const std::string& path) {
    std::string bytes = pmsc::encodeModel(m);
    const std::size_t tag = bytes.find("KEYERROR");
    ASSERT_NE(tag, std::string::npos);
    const std::size_t body = tag + 16;  // after the tag and its length
    if (offset == 0) {
        std::uint32_t norm = 0;
        std::memcpy(&norm, bytes.data() + body, sizeof norm);
        ASSERT_EQ(norm, static_cast<std::uint32_t>(m.keyErrorNorm));
    }
    poke<T>(bytes, body + offset, value);
    reseal(bytes);
    writeBytes(path, bytes);
}

TEST(ModelFile, AKeyErrorNormThisVersionDoesNotKnowIsRefused) {
    Model m = smallModel();
    m.keyErrorNorm = pmsc::KeyErrorNorm::LeaveOneOut;
    TempDir dir;
    const auto path = dir.file("norm.pmsc");
    writeWithKeyErrorPoked<std::uint32_t>(m, 0, 4, path);
    expectRejected(path, {"key error norm 4", "3 (predicted)"});
}

TEST(ModelFile, APredictedKeyErrorKeepsItsPartsThresholds) {
    Model m = smallModel();
    m.keyErrorNorm = pmsc::KeyErrorNorm::Predicted;
    m.tolerance = 0.5;
    m.epsMin = 0.5;
    m.epsMax = 0.75;
    m.partEps = {0.125, 0.375};
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    pmsc::writeModel(path, m);
    const Model back = pmsc::readModel(path);
    EXPECT_EQ(back.keyErrorNorm, pmsc::KeyErrorNorm::Predicted);
    EXPECT_EQ(back.partEps.rms, 0.125);
    EXPECT_EQ(back.partEps.loo, 0.375);
    // A part threshold that is not a finite number is refused with the section and the field.
    writeWithKeyErrorPoked<double>(m, 4, std::numeric_limits<double>::infinity(), path);
    expectRejected(path, {"KEYERROR", "key RMS part threshold"});
}

TEST(ModelFile, APredictedKeyErrorWithoutAToleranceIsRefused) {
    Model m = smallModel();
    m.keyErrorNorm = pmsc::KeyErrorNorm::Predicted;
    m.tolerance = 0;
    EXPECT_THROW(m.validate(), std::invalid_argument);
}

TEST(ModelFile, Fnv1a64MatchesPublishedVectors) {
    // Test vectors of the FNV reference (www.isthe.com/chongo/tech/comp/fnv).
    EXPECT_EQ(pmsc::fnv1a64("", 0), 0xcbf29ce484222325ull);
    EXPECT_EQ(pmsc::fnv1a64("a", 1), 0xaf63dc4c8601ec8cull);
    EXPECT_EQ(pmsc::fnv1a64("foobar", 6), 0x85944171f73967e8ull);
}

TEST(ModelFile, RoundTripIsBitExact) {
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    const Model m = smallModel();
    pmsc::writeModel(path, m);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"m.pmsc"});
    const Model r = pmsc::readModel(path);
    EXPECT_EQ(r.points, m.points);
    EXPECT_EQ(r.channels, m.channels);
    EXPECT_EQ(r.trainFrames, m.trainFrames);
    EXPECT_EQ(r.selector, m.selector);
    EXPECT_EQ(r.keyPoints, m.keyPoints);
    EXPECT_EQ(r.mean, m.mean);
    EXPECT_EQ(r.basis, m.basis);
    EXPECT_EQ(r.singularValues, m.singularValues);
    EXPECT_EQ(r.projector, m.projector);
    EXPECT_EQ(r.epsMin, m.epsMin);
    EXPECT_EQ(r.epsMax, m.epsMax);
    EXPECT_EQ(r.tolerance, m.tolerance);
    EXPECT_EQ(r.trainMaxPointResidual, m.trainMaxPointResidual);
    EXPECT_EQ(r.totalEnergy, m.totalEnergy);
    EXPECT_EQ(pmsc::encodeModel(r), pmsc::test::readBytes(path));  // and the bytes again
}

TEST(ModelFile, LayoutMatchesTheDocumentedOffsets) {
    const Model m = smallModel();
    const std::string bytes = pmsc::encodeModel(m);
    const std::size_t nc = 21, mm = 3, k = 3;
    EXPECT_EQ(bytes.size(), pmsc::kModelHeaderBytes + 8 * (nc + nc * mm + mm + k + mm * k * 3) + 8);
    EXPECT_EQ(bytes.substr(0, 8), "PMSCMODL");
    std::uint32_t version;
    std::memcpy(&version, bytes.data() + 8, 4);
    EXPECT_EQ(version, 1u);
    std::uint64_t n, keys0;
    std::memcpy(&n, bytes.data() + 16, 8);
    EXPECT_EQ(n, 7u);
    double epsMax;
    std::memcpy(&epsMax, bytes.data() + 72, 8);
    EXPECT_EQ(epsMax, 0.015);
    std::memcpy(&keys0, bytes.data() + pmsc::kModelHeaderBytes + 8 * (nc + nc * mm + mm), 8);
    EXPECT_EQ(keys0, 4u);
}

std::string decodeMessage(const std::string& bytes, const std::string& name) {
    try {
        pmsc::decodeModel(bytes, name);
    } catch (const InputError& e) {
        return e.what();
    } catch (const std::exception& e) {
        return std::string("WRONG EXCEPTION TYPE: ") + e.what();
    }
    return "NO ERROR";
}

TEST(ModelFile, SharedChannelsRoundTripAsVersion3WithTheFlagAndAThirdOfTheBasis) {
    const Model m = pmsc::test::smallSharedChannelModel();
    const std::string bytes = pmsc::encodeModel(m);
    // Version 3, header flag 1 at offset 60, no sections; basis N x M and projector M x K
    // instead of (N*C) x M, M x K*C.
    std::uint32_t version, flags;
    std::memcpy(&version, bytes.data() + 8, 4);
    std::memcpy(&flags, bytes.data() + 60, 4);
    EXPECT_EQ(version, pmsc::kModelFormatVersionFlags);
    EXPECT_EQ(flags, pmsc::kModelFlagSharedChannels);
    EXPECT_EQ(bytes.size(), pmsc::kModelHeaderBytes + 8 * (21 + 7 * 3 + 3 + 3 + 3 * 3) + 8 + 8);
    const Model r = pmsc::decodeModel(bytes, "shared.pmsc");
    EXPECT_TRUE(r.sharedChannels);
    EXPECT_EQ(r.channels, 3);
    EXPECT_EQ(r.basis, m.basis);
    EXPECT_EQ(r.projector, m.projector);
    EXPECT_EQ(r.mean, m.mean);
    EXPECT_EQ(r.coordCount(), 9);
    EXPECT_EQ(pmsc::encodeModel(r), bytes);
    // A plain model (no flag set) is written as version 1 with 0 there.
    const std::string plain = pmsc::encodeModel(smallModel());
    std::memcpy(&version, plain.data() + 8, 4);
    std::memcpy(&flags, plain.data() + 60, 4);
    EXPECT_EQ(version, 1u);
    EXPECT_EQ(flags, 0u);
}

TEST(ModelFile, FlagsOnlyInVersion3AndOnlyKnownOnesAndOnlyWithoutSectionsTheyExclude) {
    std::string bytes = pmsc::encodeModel(pmsc::test::smallSharedChannelModel());
    poke<std::uint32_t>(bytes, 60, 6);
    reseal(bytes);
    std::string what = decodeMessage(bytes, "m.pmsc");
    EXPECT_NE(what.find("m.pmsc: unknown model flags 6"), std::string::npos) << what;
    // A version-1 file's reserved word must stay 0.
    bytes = pmsc::encodeModel(smallModel());
    poke<std::uint32_t>(bytes, 60, pmsc::kModelFlagSharedChannels);
    reseal(bytes);
    what = decodeMessage(bytes, "m.pmsc");
    EXPECT_NE(what.find("m.pmsc: the header's reserved word (offset 60) is 1, not 0, in a version-1 file"),
              std::string::npos)
        << what;
    // Version 3 without the flag: the reader expects per-channel arrays, which do not fit the file.
    bytes = pmsc::encodeModel(pmsc::test::smallSharedChannelModel());
    poke<std::uint32_t>(bytes, 60, 0);
    reseal(bytes);
    what = decodeMessage(bytes, "m.pmsc");
    EXPECT_NE(what.find("m.pmsc: truncated model file or corrupted header"), std::string::npos) << what;
    // A shared-channel model with a section it cannot have (here the regions of a region model,
    // spliced in): one InputError naming the file, not a model validate() would refuse later.
    const std::string shared = pmsc::encodeModel(pmsc::test::smallSharedChannelModel());
    const std::string regions = pmsc::encodeModel(pmsc::test::smallModelWithRegions());
    const std::size_t regionsCore = pmsc::kModelHeaderBytes + 8 * (21 + 21 * 3 + 3 + 3 + 3 * 9);
    const std::size_t sharedCore = pmsc::kModelHeaderBytes + 8 * (21 + 7 * 3 + 3 + 3 + 3 * 3);
    bytes = shared.substr(0, sharedCore) + regions.substr(regionsCore, regions.size() - 8 - regionsCore) +
            "12345678";
    reseal(bytes);
    what = decodeMessage(bytes, "m.pmsc");
    EXPECT_EQ(what.rfind("m.pmsc: ", 0), 0u) << what;
    EXPECT_NE(what.find("share the basis has no regions"), std::string::npos) << what;
}

// Every length is decoded from memory (the file system makes 700 file round trips slow); a
// sample goes through real files to cover readModel's own path.
TEST(ModelFile, EveryTruncationIsRejected) {
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    const std::string bytes = pmsc::encodeModel(smallModel());
    for (std::size_t length = 0; length < bytes.size(); ++length) {
        const std::string what = decodeMessage(bytes.substr(0, length), path);
        EXPECT_EQ(what.rfind(path + ": ", 0), 0u) << "length " << length << ": " << what;
        if (length >= 8) {
            EXPECT_NE(what.find("truncated"), std::string::npos) << length << ": " << what;
        }
        if (length % 61 == 0 || length + 1 == bytes.size()) {
            writeBytes(path, bytes.substr(0, length));
            EXPECT_EQ(inputErrorMessage(path), what);
        }
    }
}

TEST(ModelFile, EveryFlippedByteIsRejected) {
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    const std::string good = pmsc::encodeModel(smallModel());
    for (std::size_t i = 0; i < good.size(); ++i) {
        for (unsigned char mask : {0x01, 0x80, 0xff}) {
            std::string bytes = good;
            bytes[i] = static_cast<char>(bytes[i] ^ mask);
            const std::string what = decodeMessage(bytes, path);
            EXPECT_EQ(what.rfind(path + ": ", 0), 0u) << "byte " << i << ": " << what;
            // Past the size fields, only the checksum can notice.
            if (i >= 64) {
                EXPECT_NE(what.find("checksum mismatch"), std::string::npos) << i << ": " << what;
            }
            if (i % 53 == 0 && mask == 0x80) {
                writeBytes(path, bytes);
                EXPECT_EQ(inputErrorMessage(path), what);
            }
        }
    }
}

/// A model whose file is past kChecksumThreadBytes (100,000 points, 2 basis vectors: 7.2 MB), made
/// as smallModel() is.
Model largeModel() {
    Model m;
    m.points = 100000;
    m.channels = 3;
    m.trainFrames = 5;
    const Eigen::Index rows = m.points * m.channels;
    Eigen::MatrixXd random(rows, 2);
    for (Eigen::Index i = 0; i < random.size(); ++i) random.data()[i] = std::sin(0.37 * double(i) + 0.1);
    m.basis =
        Eigen::HouseholderQR<Eigen::MatrixXd>(random).householderQ() * Eigen::MatrixXd::Identity(rows, 2);
    m.mean = Eigen::VectorXd::LinSpaced(rows, -1.0, 1.0);
    m.singularValues = Eigen::Vector2d(4.0, 0.5);
    m.totalEnergy = m.singularValues.squaredNorm() + 0.25;
    m.keyPoints = {17, 40000, 99999};
    m.projector = pmsc::makeProjector(m.basis, m.channels, m.keyPoints);
    m.selector = pmsc::Selector::QDeim;
    m.epsMin = 0.01;
    m.epsMax = 0.015;
    m.tolerance = 0.05;
    return m;
}

// A file past kChecksumThreadBytes has its checksum computed beside the decode: the same model, and
// the same verdicts in the same order as with the checksum first (a corrupted file is reported as
// corrupted even where its contents would also be refused).
TEST(ModelFile, ALargeFileDecodesBesideItsChecksumWithTheSameVerdicts) {
    const Model m = largeModel();
    const std::string good = pmsc::encodeModel(m);
    ASSERT_GE(good.size(), pmsc::kChecksumThreadBytes);
    for (const auto where : {pmsc::ChecksumThread::Beside, pmsc::ChecksumThread::First}) {
        const Model r = pmsc::decodeModel(good, "big.pmsc", where);
        EXPECT_EQ(r.keyPoints, m.keyPoints);
        EXPECT_EQ(r.mean, m.mean);
        EXPECT_EQ(r.basis, m.basis);
        EXPECT_EQ(r.projector, m.projector);
    }
    TempDir dir;
    const auto path = dir.file("big.pmsc");
    writeBytes(path, good);
    EXPECT_EQ(pmsc::encodeModel(pmsc::readModel(path)), good);

    const auto message = [](const std::string& bytes, pmsc::ChecksumThread where) {
        try {
            pmsc::decodeModel(bytes, "big.pmsc", where);
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string("NO ERROR");
    };
    const std::size_t keysAt = pmsc::kModelHeaderBytes + 8 * (300000 + 600000 + 2);
    std::string flipped = good;
    flipped[pmsc::kModelHeaderBytes + 8 * 300000 + 5] ^= 0x10;  // a basis value
    std::string badKey = good;
    poke<std::uint64_t>(badKey, keysAt + 8, 100000);  // the second key, one past the points
    for (const auto where : {pmsc::ChecksumThread::Beside, pmsc::ChecksumThread::First}) {
        EXPECT_NE(message(flipped, where).find("big.pmsc: checksum mismatch"), std::string::npos);
        EXPECT_NE(message(badKey, where).find("big.pmsc: checksum mismatch"), std::string::npos)
            << message(badKey, where);
        std::string resealed = badKey;
        reseal(resealed);
        EXPECT_NE(message(resealed, where).find("key point index 100000 is outside [0, 100000)"),
                  std::string::npos)
            << message(resealed, where);
    }
    writeBytes(path, badKey);
    expectRejected(path, {"checksum mismatch"});
}

TEST(ModelFile, WrongMagic) {
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    std::string bytes = pmsc::encodeModel(smallModel());
    bytes.replace(0, 8, "PMSCMODX");
    writeBytes(path, bytes);
    expectRejected(path, {"not a pmsc model file", "bad magic"});
    writeBytes(path, "GARBAGE");  // shorter than the magic itself
    expectRejected(path, {"bad magic"});
    writeBytes(path, std::string(300, 'x'));
    expectRejected(path, {"bad magic"});
}

TEST(ModelFile, WrongVersionSaysFoundAndSupported) {
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    std::string bytes = pmsc::encodeModel(smallModel());
    poke<std::uint32_t>(bytes, 8, 4);
    reseal(bytes);
    writeBytes(path, bytes);
    expectRejected(path, {"unsupported model format version 4", "reads versions 1 to 3"});
    poke<std::uint32_t>(bytes, 8, 0);
    reseal(bytes);
    writeBytes(path, bytes);
    expectRejected(path, {"version 0", "reads versions 1 to 3"});
}

TEST(ModelFile, AbsurdSizesAreRejectedBeforeAllocating) {
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    const std::string good = pmsc::encodeModel(smallModel());
    const struct {
        std::size_t offset;
        std::uint64_t value;
        const char* expected;
    } cases[] = {
        {16, 0, "must be positive"},                   // N = 0
        {24, 0, "must be positive"},                   // C = 0
        {32, 0, "must be positive"},                   // M = 0
        {40, 0, "must be positive"},                   // K = 0
        {16, 1ull << 62, "would not fit"},             // N*C*8 overflows
        {32, 0xffffffffffffffffull, "would not fit"},  // M wraps
        {40, 1ull << 40, "needs"},                     // K large, no overflow: length check
        {16, 1000000, "truncated model file or corrupted header"},
        {16, 6, "the file has"},  // N one smaller: extra bytes
    };
    for (const auto& c : cases) {
        std::string bytes = good;
        poke<std::uint64_t>(bytes, c.offset, c.value);
        reseal(bytes);
        writeBytes(path, bytes);
        expectRejected(path, {c.expected});
    }
}

TEST(ModelFile, SizesThatFitTheLengthButNotEachOther) {
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    // N=1, C=1, M=2: the length can be made consistent, but M > N*C.
    std::string bytes = "PMSCMODL";
    const auto u32 = [&](std::uint32_t v) { bytes.append(reinterpret_cast<const char*>(&v), 4); };
    const auto u64 = [&](std::uint64_t v) { bytes.append(reinterpret_cast<const char*>(&v), 8); };
    const auto f64 = [&](double v) { bytes.append(reinterpret_cast<const char*>(&v), 8); };
    u32(1), u32(0), u64(1), u64(1), u64(2), u64(1), u64(3), u32(0), u32(0);
    for (int i = 0; i < 5; ++i) f64(0.0);
    // mean 1, basis 2, sv 2, keys 1, projector 2
    f64(0), f64(1), f64(0), f64(1), f64(0), u64(0), f64(1), f64(0);
    u64(0);
    reseal(bytes);
    writeBytes(path, bytes);
    expectRejected(path, {"more basis vectors than basis rows"});
}

TEST(ModelFile, KeyIndexOutOfRangeAndDuplicateKeys) {
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    const std::string good = pmsc::encodeModel(smallModel());
    const std::size_t keysAt = pmsc::kModelHeaderBytes + 8 * (21 + 63 + 3);
    std::string bytes = good;
    poke<std::uint64_t>(bytes, keysAt + 8, 7);
    reseal(bytes);
    writeBytes(path, bytes);
    expectRejected(path, {"key point index 7 is outside [0, 7)"});
    bytes = good;
    poke<std::uint64_t>(bytes, keysAt + 8, 4);  // {4, 4, 6}
    reseal(bytes);
    writeBytes(path, bytes);
    expectRejected(path, {"inconsistent model", "repeated"});
}

TEST(ModelFile, InvalidValuesFailValidation) {
    TempDir dir;
    const auto path = dir.file("m.pmsc");
    std::string bytes = pmsc::encodeModel(smallModel());
    poke<double>(bytes, 64, 0.5);  // eps_min 0.5 > eps_max 0.015
    reseal(bytes);
    writeBytes(path, bytes);
    expectRejected(path, {"inconsistent model", "eps_min"});
    bytes = pmsc::encodeModel(smallModel());
    poke<std::uint32_t>(bytes, 56, 9);
    reseal(bytes);
    writeBytes(path, bytes);
    expectRejected(path, {"unknown key-point selector 9"});
}

TEST(ModelFile, MissingFileAndFolder) {
    TempDir dir;
    expectRejected(dir.file("none.pmsc"), {"no such file"});
    expectRejected(dir.path().string(), {"folder"});
}

TEST(ModelFile, WriterRefusesAnInvalidModel) {
    TempDir dir;
    Model m = smallModel();
    m.keyPoints = {4, 4, 6};
    EXPECT_THROW(pmsc::writeModel(dir.file("m.pmsc"), m), std::invalid_argument);
    EXPECT_TRUE(dir.entries().empty());
}

TEST(ModelFile, UnwritableDestinationIsAnIoErrorAndLeavesNoTemporaryFile) {
    TempDir dir;
    EXPECT_THROW(pmsc::writeModel(dir.file("missing/m.pmsc"), smallModel()), pmsc::IoError);
    std::filesystem::create_directories(dir.file("taken/child"));
    EXPECT_THROW(pmsc::writeModel(dir.file("taken"), smallModel()), pmsc::IoError);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"taken"});
}

}  // namespace
