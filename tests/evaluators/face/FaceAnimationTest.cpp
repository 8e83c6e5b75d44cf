#include "evaluators/face/FaceAnimation.h"

#include <gtest/gtest.h>

#include <algorithm>

namespace pmsc::face {
namespace {

FaceAnimationOptions small() {
    FaceAnimationOptions o;
    o.sequences = 10;
    o.novelSequences = 3;
    o.minFrames = 30;
    o.maxFrames = 50;
    return o;
}

TEST(FaceAnimation, SameSeedSameCurvesOtherSeedOtherCurves) {
    const FaceAnimation a = FaceAnimation::generate(small());
    const FaceAnimation b = FaceAnimation::generate(small());
    ASSERT_EQ(a.frameCount(), b.frameCount());
    for (Index f = 0; f < a.frameCount(); ++f) ASSERT_EQ(a.frame(f), b.frame(f));
    FaceAnimationOptions o = small();
    o.seed = 8;
    const FaceAnimation c = FaceAnimation::generate(o);
    EXPECT_NE(c.frame(5), a.frame(5));
}

TEST(FaceAnimation, ValuesInRangeAndCurvesSmooth) {
    const FaceAnimation a = FaceAnimation::generate(small());
    for (Index f = 0; f < a.frameCount(); ++f) {
        for (int c = 0; c < kControlCount; ++c) {
            if (c == GazeYaw || c == GazePitch || c == GazeDistance) continue;
            ASSERT_GE(a.frame(f)[c], 0.0);
            ASSERT_LE(a.frame(f)[c], 1.0);
        }
    }
    // Smooth: no control jumps by more than a blink's per-frame change within a sequence.
    for (const FaceSequence& s : a.sequences()) {
        for (Index f = s.firstFrame + 1; f < s.firstFrame + s.frameCount; ++f) {
            for (int c = 0; c < kControlCount; ++c) {
                if (c == GazeYaw || c == GazePitch) continue;  // saccades are fast by nature
                ASSERT_LE(std::abs(a.frame(f)[c] - a.frame(f - 1)[c]), 0.6) << controlName(c) << " at " << f;
            }
        }
    }
}

TEST(FaceAnimation, NovelControlsMoveOnlyInNovelSequencesAndThroughout) {
    const FaceAnimationOptions o = small();
    const FaceAnimation a = FaceAnimation::generate(o);
    for (const FaceSequence& s : a.sequences()) {
        for (Index f = s.firstFrame; f < s.firstFrame + s.frameCount; ++f) {
            for (int c : o.novelControls) {
                const bool used =
                    std::find(s.novelControls.begin(), s.novelControls.end(), c) != s.novelControls.end();
                if (!s.novel || !used) {
                    ASSERT_EQ(a.frame(f)[c], 0.0) << s.name << " moves " << controlName(c);
                } else {
                    ASSERT_GE(a.frame(f)[c], FaceAnimation::kNovelMin - 1e-12);
                }
            }
        }
        if (s.novel) {
            EXPECT_FALSE(s.novelControls.empty());
        }
    }
}

/// Mixed sequences: appended without changing a frame before them, never split into
/// training, and moving their novel controls for one window of 1-3 s (plus 6-frame ramps) only.
TEST(FaceAnimation, MixedSequencesMoveNovelControlsForAFewSecondsOnly) {
    FaceAnimationOptions o = small();
    const FaceAnimation plain = FaceAnimation::generate(o);
    o.mixedSequences = 4;
    const FaceAnimation a = FaceAnimation::generate(o);
    ASSERT_EQ(Index(a.sequences().size()), o.sequences + o.novelSequences + 4);
    for (Index f = 0; f < plain.frameCount(); ++f) ASSERT_EQ(a.frame(f), plain.frame(f)) << f;
    std::vector<Index> training, validation;
    a.splitOrdinary(0.5, 3, training, validation);
    for (const Index s : training) EXPECT_FALSE(a.sequences()[size_t(s)].mixed);
    for (const Index s : validation) EXPECT_FALSE(a.sequences()[size_t(s)].mixed);
    for (Index i = o.sequences + o.novelSequences; i < Index(a.sequences().size()); ++i) {
        const FaceSequence& s = a.sequences()[size_t(i)];
        EXPECT_TRUE(s.mixed);
        EXPECT_FALSE(s.novel);
        EXPECT_GE(s.frameCount, o.mixedMinFrames);
        ASSERT_FALSE(s.novelControls.empty()) << s.name;
        Index moving = 0, first = -1, last = -1;
        for (Index f = s.firstFrame; f < s.firstFrame + s.frameCount; ++f) {
            bool any = false;
            for (const int c : s.novelControls) any = any || a.frame(f)[c] > 0;
            if (any) {
                ++moving;
                if (first < 0) first = f;
                last = f;
            }
        }
        EXPECT_GE(moving, 24) << s.name;                 // at least a second
        EXPECT_LE(last - first + 1, 72 + 12) << s.name;  // at most 3 s and the ramps, in one window
        EXPECT_LT(moving, s.frameCount) << s.name;       // ordinary before or after it
    }
}

TEST(FaceAnimation, SplitBySequenceIsAboutAThird) {
    const FaceAnimation a = FaceAnimation::generate(small());
    std::vector<Index> training, validation;
    a.splitOrdinary(0.3, 11, training, validation);
    EXPECT_EQ(training.size(), 3u);
    EXPECT_EQ(validation.size(), 7u);
    for (Index s : training) {
        EXPECT_FALSE(a.sequences()[s].novel);
        EXPECT_EQ(std::find(validation.begin(), validation.end(), s), validation.end());
    }
    EXPECT_EQ(a.framesOf(training).size() + a.framesOf(validation).size(),
              static_cast<size_t>(a.sequences()[10].firstFrame));
}

}  // namespace
}  // namespace pmsc::face
