// `pmsc replay` on the engine (cli/Replay.cpp): the same output, bit for bit, as the plain
// per-frame replayFrame(), and the same at 1 and 2 threads, on a shot with hits, blends and misses.
#include "app/Replay.h"
#include "evaluators/ReplayEvaluator.h"
#include "pmsc/NpyIO.h"
#include "tests/common/TempDir.h"
#include "tests/engine/Synthetic.h"

#include <gtest/gtest.h>

#include <cstring>

namespace pmsc {
namespace {

TEST(ReplayOnEngine, SameBitsAsThePlainLoopAndAtAnyThreadCount) {
    const Model base = testing::makeModel(700, 3, 6, 24);
    testing::SyntheticEvaluator synthetic(base, 48);
    Model model = base;
    const SoftCachePolicy policy = testing::syntheticPolicy(model, synthetic);
    model.epsMin = policy.epsMin();
    model.epsMax = policy.epsMax();

    FrameFile file;
    file.frames = evaluateFrames(synthetic, 0, 48);
    file.dtype = NpyDtype::Float64;
    const evaluators::ReplayEvaluator recorded(file, "synthetic");

    // The reference: replayFrame() frame by frame, serially.
    const PointMultiplier pm(model);
    app::ReplayScratch scratch(model);
    FrameSet expected(48, model.points, 3);
    std::vector<app::ReplayFrame> expectedRows;
    for (Index f = 0; f < 48; ++f)
        expectedRows.push_back(app::replayFrame(pm, policy, recorded, f, scratch, expected.frame(f)));

    test::TempDir dir;
    int states[3] = {0, 0, 0};
    for (const int threads : {1, 2}) {
        const std::string path = dir.file("out" + std::to_string(threads) + ".npy");
        NpyFrameWriter out(path, 48, model.points, 3, NpyDtype::Float64);
        app::ReplayOptions options;
        options.threads = threads;
        const app::ReplayResult result = app::replay(model, recorded, options, &out);
        out.commit();
        const FrameFile written = readFrames(path);
        ASSERT_EQ(written.frames.values.size(), expected.values.size());
        EXPECT_EQ(std::memcmp(written.frames.values.data(), expected.values.data(),
                              expected.values.size() * sizeof(double)),
                  0)
            << "threads " << threads;
        ASSERT_EQ(result.frames.size(), 48u);
        for (size_t f = 0; f < 48; ++f) {
            const auto& a = result.frames[f];
            const auto& b = expectedRows[f];
            EXPECT_EQ(a.frame, b.frame);
            EXPECT_EQ(a.decision.state, b.decision.state) << f;
            EXPECT_EQ(a.decision.weight, b.decision.weight) << f;
            EXPECT_EQ(a.keyRms, b.keyRms) << f;
            EXPECT_EQ(a.pmMaxPointError, b.pmMaxPointError) << f;
            EXPECT_EQ(a.softMaxPointError, b.softMaxPointError) << f;
            if (threads == 1) ++states[int(a.decision.state)];
        }
    }
    EXPECT_EQ(states[0], 24);  // the synthetic classes: 2 hits, 1 blend, 1 miss in 4 frames
    EXPECT_EQ(states[1], 12);
    EXPECT_EQ(states[2], 12);
}

}  // namespace
}  // namespace pmsc
