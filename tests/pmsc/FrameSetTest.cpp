#include "pmsc/FrameSet.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <stdexcept>

TEST(FrameSet, LayoutMatchesNumpyCOrderAndTrainingMatrix) {
    pmsc::FrameSet set(2, 3, 3);
    // value(f, p, c) = values[(f*N + p)*C + c]
    set.values[(1 * 3 + 2) * 3 + 1] = 7.0;
    EXPECT_EQ(set.matrix()(2 * 3 + 1, 1), 7.0);  // row x = p*C + c, column t = f
    EXPECT_EQ(set.frame(1)[2 * 3 + 1], 7.0);
    EXPECT_EQ(set.rows(), 9);
}

TEST(FrameSet, TheSizedConstructorZeroesAndBothAlignAsEigen) {
    for (const pmsc::Index frames : {pmsc::Index{1}, pmsc::Index{200}}) {  // 14 KiB and 2.7 MiB
        pmsc::FrameSet zeros(frames, 577, 3);
        EXPECT_TRUE(std::all_of(zeros.values.begin(), zeros.values.end(), [](double v) { return v == 0.0; }));
        pmsc::FrameSet filled(frames, 577, 3, pmsc::FrameSet::Uninitialised{});
        ASSERT_EQ(filled.values.size(), zeros.values.size());
        std::fill(filled.values.begin(), filled.values.end(), 2.0);
        filled.values.push_back(3.0);  // grows through the same allocator
        EXPECT_EQ(filled.values.back(), 3.0);
        EXPECT_EQ(filled.values.front(), 2.0);
        for (const auto* set : {&zeros, &filled})
            EXPECT_EQ(reinterpret_cast<std::uintptr_t>(set->values.data()) % EIGEN_MAX_ALIGN_BYTES, 0u);
    }
    // An allocation of 2 MiB or more starts on a huge page's boundary, so the kernel can back it
    // with huge pages from its first byte.
    pmsc::FrameSet large(200, 577, 3, pmsc::FrameSet::Uninitialised{});
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(large.values.data()) % (std::uintptr_t{2} << 20), 0u);
}

TEST(FrameSet, RejectsNonPositiveSizes) {
    EXPECT_THROW(pmsc::FrameSet(2, 0, 3, pmsc::FrameSet::Uninitialised{}), std::invalid_argument);
    EXPECT_THROW(pmsc::FrameSet(0, 3, 3), std::invalid_argument);
    EXPECT_THROW(pmsc::FrameSet(2, -1, 3), std::invalid_argument);
    EXPECT_THROW(pmsc::FrameSet(2, 3, 0), std::invalid_argument);
}
