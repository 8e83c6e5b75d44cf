#include "examples/face/FaceAnimation.h"

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
