#include "pmsc/FrameSet.h"

#include <gtest/gtest.h>

#include <stdexcept>

TEST(FrameSet, LayoutMatchesNumpyCOrderAndTrainingMatrix) {
    pmsc::FrameSet set(2, 3, 3);
    // value(f, p, c) = values[(f*N + p)*C + c]
    set.values[(1 * 3 + 2) * 3 + 1] = 7.0;
    EXPECT_EQ(set.matrix()(2 * 3 + 1, 1), 7.0);  // row x = p*C + c, column t = f
    EXPECT_EQ(set.frame(1)[2 * 3 + 1], 7.0);
    EXPECT_EQ(set.rows(), 9);
}

TEST(FrameSet, RejectsNonPositiveSizes) {
    EXPECT_THROW(pmsc::FrameSet(0, 3, 3), std::invalid_argument);
    EXPECT_THROW(pmsc::FrameSet(2, -1, 3), std::invalid_argument);
    EXPECT_THROW(pmsc::FrameSet(2, 3, 0), std::invalid_argument);
}
