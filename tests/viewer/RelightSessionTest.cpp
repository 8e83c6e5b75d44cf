// The relighting session without the network: what each request sends, in which order, and that
// a page applying the updates ends with the engine's answer (a miss: the full calculation's).
#include "engine/Engine.h"
#include "pmsc/Errors.h"
#include "tests/common/MissingData.h"
#include "tests/common/SmallModel.h"
#include "tests/viewer/ViewerFixture.h"
#include "viewer/HalfCache.h"
#include "viewer/RelightSession.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <limits>
#include <mutex>
#include <random>

namespace pmsc::viewer {
namespace {

using pmsc::test::withSentinels;
using test::fullValues;
using test::smallVolume;

/// Collects a session's updates and applies them to a page's copy of the cache.
class Page {
public:
    Page(Index points) : cache(points, 3), reference(points, 3) {}

    RelightSession::Emit emitter() {
        return [this](Update&& u) {
            std::lock_guard<std::mutex> lock(mutex);
            if (u.binaryFollows) {
                HalfCache& target = u.text["target"] == "reference" ? reference : cache;
                std::vector<double> values(u.halfs.begin(), u.halfs.end());
                for (size_t i = 0; i < values.size(); ++i) values[i] = fromHalf(u.halfs[i]);
                target.write(Index(u.first), values);
                if (!u.text["checksum"].get<std::string>().empty()) {
                    EXPECT_EQ(u.text["checksum"], target.checksum()) << u.text.dump();
                }
            }
            updates.push_back(std::move(u));
            changed.notify_all();
        };
    }

    /// Waits for the final update of `seq` (of `target`); fails after a minute.
    nlohmann::json waitFinal(std::uint32_t seq, const std::string& target = "cache") {
        std::unique_lock<std::mutex> lock(mutex);
        nlohmann::json found;
        const bool ok = changed.wait_for(lock, std::chrono::seconds(60), [&] {
            for (const Update& u : updates) {
                if (u.text.value("phase", "") == "final" && u.seq == seq && u.text["target"] == target) {
                    found = u.text;
                    return true;
                }
            }
            return false;
        });
        EXPECT_TRUE(ok) << "no final update for seq " << seq;
        return found;
    }

    std::vector<Update> of(std::uint32_t seq) {
        std::lock_guard<std::mutex> lock(mutex);
        std::vector<Update> out;
        for (const Update& u : updates)
            if (u.binaryFollows && u.seq == seq) out.push_back(u);
        return out;
    }

    std::mutex mutex;
    std::condition_variable changed;
    std::vector<Update> updates;
    HalfCache cache, reference;
};

std::string setMessage(std::uint32_t seq, double azimuth, double elevation, double kelvin = 5000) {
    return nlohmann::json{{"type", "set"},
                          {"seq", seq},
                          {"controls", {{"azimuth", azimuth}, {"elevation", elevation}, {"kelvin", kelvin}}}}
        .dump();
}

std::vector<std::uint16_t> halfsOf(const std::vector<double>& v) {
    std::vector<std::uint16_t> h(v.size());
    for (size_t i = 0; i < v.size(); ++i) h[i] = toHalf(v[i]);
    return h;
}

/// The engine's answer for one light, run the plain way (a one-frame evaluator and a collector).
std::vector<double> engineAnswer(const Model& model, const RelightScene& scene, const Controls& c) {
    struct Collect : engine::FrameSink {
        std::vector<double> values;
        void write(const engine::FrameResult& r) override { values.assign(r.values.begin(), r.values.end()); }
    } sink;
    const auto e = scene.evaluator(scene.resolve(c));
    engine::EngineOptions o;
    o.localFailThrough = false;
    o.basisPrecision = BasisPrecision::Single;  // what the session's engine reads: it sends half floats
    engine::Engine(model, *e, o).run({0, 1, 1}, sink);
    return sink.values;
}

class RelightSessionTest : public ::testing::Test {
protected:
    void SetUp() override {
        if (!smallVolume().scene) PMSC_MISSING_DATA("assimp-testmodels not installed (WusonOBJ.obj)");
    }
    /// The small volume's model with the thresholds set to force one decision.
    static Model withThresholds(double epsMin, double epsMax) {
        Model m = smallVolume().model;
        m.epsMin = epsMin;
        m.epsMax = epsMax;
        return m;
    }
};

TEST_F(RelightSessionTest, AHitSendsItsReconstructionOnceAndBeforeItsCheck) {
    // Without sentinels a hit has nothing to check: one final holding every point. With them the
    // reconstruction goes out as the estimate, before the sentinels are computed, and the final
    // says the check let it stand, without the values again.
    const auto& v = smallVolume();
    ASSERT_FALSE(smallVolume().model.sentinels) << "the small volume's model has no sentinels";
    for (const bool checked : {false, true}) {
        const Model plain = withThresholds(1e9, 2e9);
        const Model model = checked ? withSentinels(plain, 1e300) : plain;  // every check passes
        Page page(v.scene->pointCount());
        RelightSession session(model, *v.scene, 2, page.emitter());
        const auto unixMs = [] {
            return std::chrono::duration<double, std::milli>(
                       std::chrono::system_clock::now().time_since_epoch())
                .count();
        };
        const double before = unixMs();
        session.receive(setMessage(1, 100, 30));
        const nlohmann::json last = page.waitFinal(1);
        const double after = unixMs();
        EXPECT_EQ(last["state"], "hit");
        // Every update says when the server read its request, by the system clock (the page's
        // latency split into the way out and the way back).
        for (const auto& u : page.of(1)) {
            ASSERT_TRUE(u.text.contains("received_unix_ms")) << u.text.dump();
            EXPECT_GE(u.text["received_unix_ms"].get<double>(), before);
            EXPECT_LE(u.text["received_unix_ms"].get<double>(), after);
        }
        EXPECT_TRUE(last["converged"].get<bool>());
        EXPECT_TRUE(last["timing_ms"].contains("keys"));
        const auto updates = page.of(1);
        ASSERT_EQ(updates.size(), checked ? 2u : 1u);
        EXPECT_EQ(updates[0].text["phase"], checked ? "estimate" : "final");
        EXPECT_EQ(updates[0].text["state"], "hit");
        EXPECT_EQ(updates[0].halfs.size(), size_t(v.scene->pointCount() * 3));
        if (checked) {
            EXPECT_TRUE(updates[1].halfs.empty());
            EXPECT_EQ(updates[1].text["checksum"], updates[0].text["checksum"]);
        }
        const auto expected = halfsOf(engineAnswer(model, *v.scene, {{"azimuth", 100}, {"elevation", 30}}));
        EXPECT_TRUE(std::equal(expected.begin(), expected.end(), page.cache.values().begin()));
        EXPECT_EQ(session.counts().hits, 1u);
    }
}

TEST_F(RelightSessionTest, AHitItsCheckRefusesConvergesToTheEnginesBlendAfterItsImage) {
    const auto& v = smallVolume();
    // Every sentinel is off by more than 0.8 T: the check refuses the hit.
    const Model model = withSentinels(withThresholds(1e9, 2e9), 1e-12);
    const Index n = v.scene->pointCount();
    Page page(n);
    RelightSession session(model, *v.scene, 2, page.emitter());
    session.receive(setMessage(2, 100, 30));
    const nlohmann::json last = page.waitFinal(2);
    EXPECT_EQ(last["state"], "blend");
    const auto updates = page.of(2);
    ASSERT_GE(updates.size(), 3u);
    EXPECT_EQ(updates.front().text["phase"], "estimate");
    EXPECT_EQ(updates.front().text["state"], "hit");
    EXPECT_EQ(updates[1].text["phase"], "chunk");
    EXPECT_EQ(updates[1].text["state"], "blend");
    EXPECT_TRUE(updates.back().halfs.empty());
    const auto expected = halfsOf(engineAnswer(model, *v.scene, {{"azimuth", 100}, {"elevation", 30}}));
    EXPECT_TRUE(std::equal(expected.begin(), expected.end(), page.cache.values().begin()));
    EXPECT_EQ(session.counts().blends, 1u);
}

TEST_F(RelightSessionTest, AMissShowsTheEstimateThenConvergesToTheFullCalculation) {
    const auto& v = smallVolume();
    const Model model = withThresholds(0, 0);
    const Index n = v.scene->pointCount();
    Page page(n);
    RelightSession session(model, *v.scene, 2, page.emitter());
    session.receive(setMessage(7, 200, -20));
    const nlohmann::json last = page.waitFinal(7);
    EXPECT_EQ(last["state"], "miss");
    EXPECT_TRUE(last["converged"].get<bool>());
    const auto updates = page.of(7);
    ASSERT_GE(updates.size(), 3u);
    EXPECT_EQ(updates.front().text["phase"], "estimate");
    EXPECT_EQ(updates.front().halfs.size(), size_t(n * 3));
    EXPECT_EQ(updates.back().text["phase"], "final");
    EXPECT_TRUE(updates.back().halfs.empty());
    // The chunks cover every point exactly once.
    std::vector<int> covered(size_t(n), 0);
    for (size_t i = 1; i + 1 < updates.size(); ++i) {
        EXPECT_EQ(updates[i].text["phase"], "chunk");
        for (Index p = 0; p < Index(updates[i].halfs.size()) / 3; ++p)
            ++covered[size_t(updates[i].first + p)];
    }
    EXPECT_TRUE(std::all_of(covered.begin(), covered.end(), [](int c) { return c == 1; }));
    const auto full = halfsOf(fullValues(*v.scene, {{"azimuth", 200}, {"elevation", -20}}));
    EXPECT_TRUE(std::equal(full.begin(), full.end(), page.cache.values().begin()))
        << "a converged miss is the full calculation, bit for bit in half floats";
}

TEST_F(RelightSessionTest, ABlendConvergesToTheEnginesBlend) {
    const auto& v = smallVolume();
    const Model model = withThresholds(0, 1e9);
    Page page(v.scene->pointCount());
    RelightSession session(model, *v.scene, 2, page.emitter());
    session.receive(setMessage(3, 300, 50, 7000));
    const nlohmann::json last = page.waitFinal(3);
    EXPECT_EQ(last["state"], "blend");
    const auto expected =
        halfsOf(engineAnswer(model, *v.scene, {{"azimuth", 300}, {"elevation", 50}, {"kelvin", 7000}}));
    EXPECT_TRUE(std::equal(expected.begin(), expected.end(), page.cache.values().begin()));
}

TEST_F(RelightSessionTest, FullViewAndReferenceAreTheFullCalculation) {
    const auto& v = smallVolume();
    const Model model = withThresholds(1e9, 2e9);  // the cache would hit: the full view must not
    Page page(v.scene->pointCount());
    RelightSession session(model, *v.scene, 2, page.emitter());
    session.receive(setMessage(1, 10, 20));
    page.waitFinal(1);
    session.receive(R"({"type":"reference","seq":2})");
    EXPECT_EQ(page.waitFinal(2, "reference")["state"], "full");
    const auto full = halfsOf(fullValues(*v.scene, {{"azimuth", 10}, {"elevation", 20}}));
    EXPECT_TRUE(std::equal(full.begin(), full.end(), page.reference.values().begin()));
    EXPECT_FALSE(std::equal(full.begin(), full.end(), page.cache.values().begin()));
    session.receive(R"({"type":"mode","view":"full"})");
    session.receive(setMessage(3, 10, 20));
    EXPECT_EQ(page.waitFinal(3)["state"], "full");
    EXPECT_TRUE(std::equal(full.begin(), full.end(), page.cache.values().begin()));
}

TEST_F(RelightSessionTest, TheNewestRequestWinsAndEndsWhereItsOwnAnswerIs) {
    const auto& v = smallVolume();
    const Model model = withThresholds(0, 0);  // every frame a miss: long enough to be cancelled
    Page page(v.scene->pointCount());
    RelightSession session(model, *v.scene, 2, page.emitter());
    for (std::uint32_t s = 1; s <= 5; ++s) session.receive(setMessage(s, 20.0 * s, 30));
    page.waitFinal(5);
    const auto full = halfsOf(fullValues(*v.scene, {{"azimuth", 100}, {"elevation", 30}}));
    EXPECT_TRUE(std::equal(full.begin(), full.end(), page.cache.values().begin()));
    const auto c = session.counts();
    EXPECT_GE(c.misses, 1u);
    EXPECT_LE(c.misses + c.cancelled, 5u);
}

TEST_F(RelightSessionTest, BadMessagesAreOneLineErrorsAndTheSessionGoesOn) {
    const auto& v = smallVolume();
    Page page(v.scene->pointCount());
    RelightSession session(v.model, *v.scene, 2, page.emitter());
    auto messageOf = [&](const std::string& text) {
        try {
            session.receive(text);
        } catch (const InputError& e) {
            const std::string m = e.what();
            EXPECT_EQ(m.find('\n'), std::string::npos) << m;
            return m;
        }
        return std::string("no error");
    };
    EXPECT_NE(messageOf("{not json").find("not JSON"), std::string::npos);
    EXPECT_NE(messageOf("[1,2]").find("\"type\""), std::string::npos);
    EXPECT_NE(messageOf(R"({"type":"jump"})").find("unknown message type 'jump'"), std::string::npos);
    EXPECT_NE(messageOf(R"({"type":"set","controls":{}})").find("\"seq\""), std::string::npos);
    EXPECT_NE(messageOf(R"({"type":"set","seq":-1,"controls":{}})").find("\"seq\""), std::string::npos);
    EXPECT_NE(messageOf(R"({"type":"set","seq":1})").find("\"controls\""), std::string::npos);
    EXPECT_NE(messageOf(R"({"type":"set","seq":1,"controls":{"hue":3}})").find("unknown control 'hue'"),
              std::string::npos);
    EXPECT_NE(messageOf(R"({"type":"set","seq":1,"controls":{"elevation":"up"}})").find("not a number"),
              std::string::npos);
    EXPECT_NE(messageOf(setMessage(1, 400, 10)).find("'azimuth' = 400 is outside [0, 360]"),
              std::string::npos);
    EXPECT_NE(messageOf(R"({"type":"mode","view":"x"})").find("cache or full"), std::string::npos);
    session.receive(setMessage(9, 45, 40));
    EXPECT_TRUE(page.waitFinal(9)["converged"].get<bool>());
}

TEST_F(RelightSessionTest, AModelOfOtherPointsIsRefusedWithTheWayToMakeOne) {
    const auto& v = smallVolume();
    Model other = v.model;
    other.points += 1;
    Page page(v.scene->pointCount());
    try {
        RelightSession session(other, *v.scene, 1, page.emitter());
        FAIL() << "a model of other points was taken";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("pmsc demo volume --out DIR writes DIR/model.pmsc"),
                  std::string::npos)
            << e.what();
    }
}

TEST(RelightScene, BadSpecsAreOneLineErrors) {
    auto messageOf = [](const std::string& spec) {
        try {
            makeRelightScene(spec);
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    EXPECT_NE(messageOf("sphere:1").find("neither volume"), std::string::npos);
    EXPECT_NE(messageOf("volume:/nonexistent/x.vdb").find("/nonexistent/x.vdb"), std::string::npos);
    EXPECT_NE(messageOf("volume:x.vdb:lights=path").find("lights= is not an option of the viewer"),
              std::string::npos);
    EXPECT_NE(messageOf("cornell:points=5").find("points"), std::string::npos);
    EXPECT_NE(messageOf("cornell:lights=all").find("lights= is not an option of the viewer"),
              std::string::npos);
}

TEST(HalfCache, HalfFloatsRoundToNearestAndNeverOverflow) {
    EXPECT_EQ(toHalf(1.0), 0x3c00);
    EXPECT_EQ(toHalf(-2.0), 0xc000);
    EXPECT_EQ(toHalf(1e9), 0x7bff);  // 65504, not infinity
    EXPECT_EQ(fromHalf(toHalf(0.1)), fromHalf(0x2e66));
    HalfCache c(2, 3);
    EXPECT_EQ(c.checksum(), "d94d12186c0f2fb7") << "FNV-1a 64 stepped over three zero words";
    const std::vector<double> v{1, 2, 3};
    c.write(1, v);
    EXPECT_EQ(fromHalf(c.values()[3]), 1.0f);
    EXPECT_THROW(c.write(2, v), std::out_of_range);
}

TEST(HalfCache, BatchConversionIsTheScalarOneBitForBit) {
    // Every edge: ties at several exponents, the largest half and beyond, subnormals, zeros of
    // both signs, then random values over the halves' range; lengths not a multiple of eight.
    std::vector<double> v{0.0,
                          -0.0,
                          1.0 + std::ldexp(1.0, -11),
                          1.0 + 3 * std::ldexp(1.0, -11),
                          65504.0,
                          65519.0,
                          65520.0,
                          1e300,
                          -1e300,
                          std::ldexp(1.0, -24),
                          std::ldexp(1.0, -25),
                          std::ldexp(3.0, -26),
                          6.1e-5,
                          -0.1,
                          1e-300};
    std::mt19937 random(7);
    std::uniform_real_distribution<double> exponent(-30, 17), unit(-1, 1);
    for (int i = 0; i < 10001; ++i) v.push_back(unit(random) * std::exp2(exponent(random)));
    std::vector<std::uint16_t> batch(v.size());
    toHalves(v, batch.data());
    for (size_t i = 0; i < v.size(); ++i) ASSERT_EQ(batch[i], toHalf(v[i])) << "value " << v[i];
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::vector<double> nans(9, nan);
    std::vector<std::uint16_t> h(nans.size());
    toHalves(nans, h.data());
    for (const std::uint16_t x : h) EXPECT_TRUE(std::isnan(fromHalf(x)));
}

TEST(HalfCache, ChecksumStepsPerWordAndPadsAnOddCount) {
    // Expected values from Python integers; web/viewer/tests/half.test.mjs checks the page's
    // JavaScript against the same ones.
    const std::vector<std::uint16_t> odd{1, 2, 3}, edges{0x3c00, 0xc000, 0x7bff, 0xffff, 0x8000};
    EXPECT_EQ(wordChecksum(odd), 0x3c2f2501ee9691ddull);
    EXPECT_EQ(wordChecksum(edges), 0x5bda643e5916f520ull);
    EXPECT_EQ(wordChecksum({}), 0xcbf29ce484222325ull);
}

}  // namespace
}  // namespace pmsc::viewer
