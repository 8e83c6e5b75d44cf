// Model file format version 2: tagged sections after the version-1 core (ModelIO.h, ModelSections.h).
#include "pmsc/ByteIO.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"

#include "tests/common/ModelBytes.h"
#include "tests/common/SmallModel.h"
#include "tests/common/TempDir.h"

#include <gtest/gtest.h>

#include <cstring>
#include <string>

namespace {

using pmsc::InputError;
using pmsc::Model;
using pmsc::test::peek;
using pmsc::test::poke;
using pmsc::test::reseal;
using pmsc::test::smallModel;
using pmsc::test::smallModelWithRegions;

// smallModel(): N*C = 21, M = 3, K = 3: the core ends at 104 + 8 * (21 + 63 + 3 + 3 + 27).
constexpr std::size_t kCoreEnd = 1040;
constexpr std::size_t kTagAt = kCoreEnd + 8;
constexpr std::size_t kLengthAt = kTagAt + 8;
constexpr std::size_t kPayloadAt = kLengthAt + 8;

std::string decodeMessage(const std::string& bytes) {
    try {
        pmsc::decodeModel(bytes, "m.pmsc");
    } catch (const InputError& e) {
        return e.what();
    } catch (const std::exception& e) {
        return std::string("WRONG EXCEPTION TYPE: ") + e.what();
    }
    return "NO ERROR";
}
void expectMessage(const std::string& bytes, std::initializer_list<std::string> fragments) {
    const std::string what = decodeMessage(bytes);
    EXPECT_EQ(what.rfind("m.pmsc: ", 0), 0u) << what;
    for (const auto& f : fragments)
        EXPECT_NE(what.find(f), std::string::npos) << "missing '" << f << "' in: " << what;
}

TEST(ModelSections, AModelWithoutSectionsIsStillVersion1) {
    const std::string bytes = pmsc::encodeModel(smallModel());
    EXPECT_EQ(peek<std::uint32_t>(bytes, 8), 1u);
    EXPECT_EQ(bytes.size(), kCoreEnd + 8);  // core + checksum: the version-1 layout exactly
    EXPECT_FALSE(pmsc::decodeModel(bytes, "m.pmsc").regions.has_value());
}

TEST(ModelSections, RegionsRoundTripBitExact) {
    pmsc::test::TempDir dir;
    const auto path = dir.file("m.pmsc");
    const Model m = smallModelWithRegions();
    pmsc::writeModel(path, m);
    const std::string bytes = pmsc::test::readBytes(path);
    EXPECT_EQ(peek<std::uint32_t>(bytes, 8), 2u);
    EXPECT_EQ(peek<std::uint64_t>(bytes, kCoreEnd), 1u);
    EXPECT_EQ(std::string(bytes.data() + kTagAt, 8), std::string("REGIONS\0", 8));
    EXPECT_EQ(peek<std::uint64_t>(bytes, kLengthAt), bytes.size() - 8 - kPayloadAt);
    const Model r = pmsc::readModel(path);
    ASSERT_TRUE(r.regions.has_value());
    EXPECT_EQ(r.basis, m.basis);
    EXPECT_EQ(r.keyPoints, m.keyPoints);
    const auto& a = *m.regions;
    const auto& b = *r.regions;
    EXPECT_EQ(b.featherWidth, a.featherWidth);
    EXPECT_EQ(b.maxLocalFraction, a.maxLocalFraction);
    EXPECT_EQ(b.featherStart, a.featherStart);
    EXPECT_EQ(b.featherRegion, a.featherRegion);
    EXPECT_EQ(b.featherFactor, a.featherFactor);
    ASSERT_EQ(b.regionCount(), 2);
    for (int i = 0; i < 2; ++i) {
        EXPECT_EQ(b.regions[i].points, a.regions[i].points);
        EXPECT_EQ(b.regions[i].keys, a.regions[i].keys);
        EXPECT_EQ(b.regions[i].basis, a.regions[i].basis);
        EXPECT_EQ(b.regions[i].keyBasis, a.regions[i].keyBasis);
        EXPECT_EQ(b.regions[i].projector, a.regions[i].projector);
        EXPECT_EQ(b.regions[i].epsMin, a.regions[i].epsMin);
        EXPECT_EQ(b.regions[i].epsMax, a.regions[i].epsMax);
        EXPECT_EQ(b.regions[i].ratio, a.regions[i].ratio);
    }
    EXPECT_EQ(pmsc::encodeModel(r), bytes);
    EXPECT_EQ(b.failSet(1), (std::vector<pmsc::Index>{4, 5, 6, 3}));
}

TEST(ModelSections, EveryTruncationInsideTheSectionNamesTheSection) {
    const std::string full = pmsc::encodeModel(smallModelWithRegions());
    const std::size_t payload = full.size() - 8 - kPayloadAt;
    for (std::size_t cut = 0; cut < payload; ++cut) {
        // A shorter payload whose length field agrees: only the codec's reader can notice.
        std::string bytes = full.substr(0, kPayloadAt + cut) + std::string(8, '\0');
        poke<std::uint64_t>(bytes, kLengthAt, cut);
        reseal(bytes);
        const std::string what = decodeMessage(bytes);
        EXPECT_EQ(what.rfind("m.pmsc: section 'REGIONS': ", 0), 0u) << "cut " << cut << ": " << what;
    }
    // And a file cut anywhere after the core (the checksum gone with it) is rejected too.
    for (std::size_t length = kCoreEnd; length < full.size(); ++length)
        EXPECT_NE(decodeMessage(full.substr(0, length)), "NO ERROR") << length;
}

TEST(ModelSections, BadLengthIsRejected) {
    std::string bytes = pmsc::encodeModel(smallModelWithRegions());
    const auto length = peek<std::uint64_t>(bytes, kLengthAt);
    poke<std::uint64_t>(bytes, kLengthAt, length + 1);
    reseal(bytes);
    expectMessage(bytes, {"section 'REGIONS' has bad length", "before the checksum"});
    poke<std::uint64_t>(bytes, kLengthAt, ~std::uint64_t{0});
    reseal(bytes);
    expectMessage(bytes, {"section 'REGIONS' has bad length"});
    // Shorter than the payload: the bytes after it are not a section.
    poke<std::uint64_t>(bytes, kLengthAt, length - 8);
    reseal(bytes);
    expectMessage(bytes, {"section 'REGIONS'"});
}

TEST(ModelSections, UnknownTagSaysANewerPmscWroteIt) {
    std::string bytes = pmsc::encodeModel(smallModelWithRegions());
    std::memcpy(bytes.data() + kTagAt, "FUTURE\0\0", 8);
    reseal(bytes);
    expectMessage(bytes, {"unknown section 'FUTURE'", "newer pmsc", "'REGIONS'"});
    std::memcpy(bytes.data() + kTagAt, "\x01\x02XY\0\0\0\0", 8);
    reseal(bytes);
    expectMessage(bytes, {"unknown section '\\x01\\x02XY'"});
}

TEST(ModelSections, DuplicateTagIsRejected) {
    const std::string one = pmsc::encodeModel(smallModelWithRegions());
    const std::string section = one.substr(kTagAt, one.size() - 8 - kTagAt);
    std::string bytes = one.substr(0, one.size() - 8) + section + std::string(8, '\0');
    poke<std::uint64_t>(bytes, kCoreEnd, 2);
    reseal(bytes);
    expectMessage(bytes, {"section 'REGIONS' appears twice"});
}

TEST(ModelSections, CountsThatCannotFitAreRejected) {
    std::string bytes = pmsc::encodeModel(smallModelWithRegions());
    poke<std::uint64_t>(bytes, kCoreEnd, 1u << 30);
    reseal(bytes);
    expectMessage(bytes, {"section count"});
    bytes = pmsc::encodeModel(smallModelWithRegions());
    poke<std::uint64_t>(bytes, kPayloadAt, ~std::uint64_t{0} / 2);  // region count
    reseal(bytes);
    expectMessage(bytes, {"section 'REGIONS'", "region count"});
    bytes = pmsc::encodeModel(smallModelWithRegions());
    poke<std::uint64_t>(bytes, kCoreEnd, 0);  // no sections, but bytes follow
    reseal(bytes);
    expectMessage(bytes, {"unexpected bytes"});
}

TEST(ModelSections, ChecksumCoversTheSections) {
    std::string bytes = pmsc::encodeModel(smallModelWithRegions());
    bytes[bytes.size() - 20] ^= 0x40;
    expectMessage(bytes, {"checksum mismatch"});
}

TEST(ModelSections, InconsistentRegionsNameTheSectionAndTheProblem) {
    const std::string good = pmsc::encodeModel(smallModelWithRegions());
    // Region 0's first point (offset: count, width, fraction, then 6 fields of region 0) -> 5,
    // which region 1 holds too.
    std::string bytes = good;
    const std::size_t firstPoint = kPayloadAt + 24 + 48;
    ASSERT_EQ(peek<std::uint64_t>(bytes, firstPoint), 0u);
    poke<std::uint64_t>(bytes, firstPoint, 5);
    reseal(bytes);
    expectMessage(bytes, {"section 'REGIONS'", "inconsistent", "point"});
    bytes = good;
    poke<std::uint64_t>(bytes, firstPoint, 99);
    reseal(bytes);
    expectMessage(bytes, {"section 'REGIONS'", "region 0 point 99 is outside [0, 7)"});
    // eps_min of region 0 -> NaN
    bytes = good;
    poke<double>(bytes, kPayloadAt + 24 + 24, std::nan(""));
    reseal(bytes);
    expectMessage(bytes, {"section 'REGIONS'", "region 0 eps_min"});
}

TEST(ModelSections, ByteReaderNamesTheFieldAndNeverReadsPastTheEnd) {
    std::string bytes(12, '\0');
    pmsc::ByteReader in(bytes, "f: section 'X'");
    EXPECT_EQ(in.u64("a"), 0u);
    try {
        in.u64("b");
        FAIL() << "read past the end";
    } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()).rfind("f: section 'X': truncated: b", 0), 0u) << e.what();
    }
    EXPECT_EQ(in.u32("c"), 0u);
    EXPECT_NO_THROW(in.expectEnd());
}

}  // namespace

// An empty array's data() may be null, and the codecs must not hand it to memcpy, even with a
// count of 0 (undefined behaviour; UBSan's nonnull check stops the sanitizer build; fuzz_model hits it).
TEST(ModelSections, EmptyArraysWithNullDataAreWrittenAndReadAsNothing) {
    std::string out;
    pmsc::ByteWriter writer(out);
    writer.doubles(nullptr, 0);
    EXPECT_TRUE(out.empty());
    pmsc::ByteReader in(out, "f");
    in.doubles(nullptr, 0, "nothing");
    EXPECT_NO_THROW(in.expectEnd());
}

// The model `pmsc train --regions` wrote for the fuzzer's seed: no feather entries at all.
TEST(ModelSections, RegionsWithoutFeatherEntriesRoundTrip) {
    pmsc::Model m = pmsc::test::smallModelWithRegions();
    m.regions->featherStart.assign(static_cast<std::size_t>(m.points) + 1, 0);
    m.regions->featherRegion.clear();
    m.regions->featherFactor.clear();
    const pmsc::Model r = pmsc::decodeModel(pmsc::encodeModel(m), "m.pmsc");
    ASSERT_TRUE(r.regions.has_value());
    EXPECT_TRUE(r.regions->featherFactor.empty());
    EXPECT_EQ(r.regions->featherStart, m.regions->featherStart);
}

namespace {

/// smallModel() with key neighbours: 2 per key (its 7 points, keys {4, 0, 6}).
Model smallModelWithKeyNeighbours() {
    Model m = smallModel();
    pmsc::KeyNeighbours near;
    near.perKey = 2;
    near.fromMean = false;
    near.points = {3, 5, 1, 2, 5, 3};
    m.keyNeighbours = near;
    return m;
}

TEST(ModelSections, KeyNeighboursRoundTripBitExact) {
    const Model m = smallModelWithKeyNeighbours();
    const std::string bytes = pmsc::encodeModel(m);
    EXPECT_EQ(std::string(bytes.data() + kTagAt, 8), std::string("KEYNEAR\0", 8));
    const Model r = pmsc::decodeModel(bytes, "m.pmsc");
    ASSERT_TRUE(r.keyNeighbours.has_value());
    EXPECT_EQ(r.keyNeighbours->perKey, 2);
    EXPECT_FALSE(r.keyNeighbours->fromMean);
    EXPECT_EQ(r.keyNeighbours->points, m.keyNeighbours->points);
    EXPECT_EQ(pmsc::encodeModel(r), bytes);
}

TEST(ModelSections, BadKeyNeighboursAreRejectedWithTheField) {
    const std::string good = pmsc::encodeModel(smallModelWithKeyNeighbours());
    // Payload: u32 source, u64 per key, u64[K*P] points.
    std::string bytes = good;
    poke<std::uint32_t>(bytes, kPayloadAt, 7);
    reseal(bytes);
    expectMessage(bytes, {"key neighbours' source 7"});
    bytes = good;
    poke<std::uint64_t>(bytes, kPayloadAt + 4, 0);
    reseal(bytes);
    expectMessage(bytes, {"key neighbours per key 0"});
    bytes = good;
    poke<std::uint64_t>(bytes, kPayloadAt + 4, 5);  // N - K = 4
    reseal(bytes);
    expectMessage(bytes, {"key neighbours per key 5"});
    bytes = good;
    poke<std::uint64_t>(bytes, kPayloadAt + 12, 7);  // a point outside [0, N)
    reseal(bytes);
    expectMessage(bytes, {"key neighbour point"});
}

TEST(ModelSections, SentinelsRoundTripBitExactAndBadOnesAreRejectedWithTheField) {
    Model m = smallModel();  // 7 points, keys {4, 0, 6}
    pmsc::Sentinels s;
    s.points = {2, 5};
    s.coveringRadius = 1.5;
    s.source = pmsc::SentinelSource::Given;
    m.sentinels = s;
    const std::string good = pmsc::encodeModel(m);
    EXPECT_EQ(std::string(good.data() + kTagAt, 8), std::string("SENTINEL", 8));
    const Model r = pmsc::decodeModel(good, "m.pmsc");
    ASSERT_TRUE(r.sentinels.has_value());
    EXPECT_EQ(r.sentinels->points, s.points);
    EXPECT_EQ(r.sentinels->coveringRadius, 1.5);
    EXPECT_EQ(r.sentinels->source, pmsc::SentinelSource::Given);
    EXPECT_EQ(pmsc::encodeModel(r), good);
    // Payload: u32 source, f64 covering radius, u64 count, u64[count] points.
    std::string bytes = good;
    poke<std::uint32_t>(bytes, kPayloadAt, 3);  // a training frame
    reseal(bytes);
    EXPECT_EQ(pmsc::decodeModel(bytes, "m.pmsc").sentinels->source, pmsc::SentinelSource::Frame);
    poke<std::uint32_t>(bytes, kPayloadAt, 4);
    reseal(bytes);
    expectMessage(bytes, {"sentinels' source 4"});
    bytes = good;
    poke<double>(bytes, kPayloadAt + 4, -1.0);
    reseal(bytes);
    expectMessage(bytes, {"covering radius"});
    bytes = good;
    poke<std::uint64_t>(bytes, kPayloadAt + 12, 8);  // more than N = 7
    reseal(bytes);
    expectMessage(bytes, {"sentinel count 8"});
    bytes = good;
    poke<std::uint64_t>(bytes, kPayloadAt + 20, 7);  // a point outside [0, N)
    reseal(bytes);
    expectMessage(bytes, {"sentinel point"});
}

}  // namespace

TEST(ModelSections, TheClampAtZeroRoundTripsAndABadFlagIsRejected) {
    Model m = smallModel();
    EXPECT_FALSE(pmsc::decodeModel(pmsc::encodeModel(m), "m.pmsc").nonNegative);
    m.nonNegative = true;
    const std::string good = pmsc::encodeModel(m);
    EXPECT_TRUE(pmsc::decodeModel(good, "m.pmsc").nonNegative);
    ASSERT_EQ(std::string(good.data() + kTagAt, 6), "NONNEG");
    std::string bytes = good;
    poke<std::uint32_t>(bytes, kPayloadAt, 2);
    reseal(bytes);
    expectMessage(bytes, {"section 'NONNEG'", "non-negative flag 2 is not 1"});
}
