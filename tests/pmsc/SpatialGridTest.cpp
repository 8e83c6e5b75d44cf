#include "pmsc/SpatialGrid.h"

#include <gtest/gtest.h>

#include <random>
#include <set>

namespace {

Eigen::MatrixXd lattice(int side) {
    Eigen::MatrixXd p(side * side * side, 3);
    int i = 0;
    for (int z = 0; z < side; ++z)
        for (int y = 0; y < side; ++y)
            for (int x = 0; x < side; ++x) p.row(i++) = Eigen::RowVector3d(x, y, z);
    return p;
}

}  // namespace

TEST(SpatialGrid, OnePointPerOccupiedCellNearestItsCentre) {
    // A 9^3 lattice with spacing 1 spans [0, 8]; 3 cells per axis of side 8/3: every cell is
    // occupied, and the point nearest each cell centre ((k + 0.5) * 8/3 = 1.33, 4, 6.67) is at
    // lattice coordinate 1, 4 or 7.
    const Eigen::MatrixXd p = lattice(9);
    const std::vector<pmsc::Index> g = pmsc::sparseGridPoints(p, 3);
    ASSERT_EQ(g.size(), 27u);
    std::set<pmsc::Index> unique(g.begin(), g.end());
    EXPECT_EQ(unique.size(), 27u);
    for (pmsc::Index i : g)
        for (int a = 0; a < 3; ++a) {
            const double v = p(i, a);
            EXPECT_TRUE(v == 1 || v == 4 || v == 7) << "point " << i << " axis " << a << " = " << v;
        }
    // Cell order: x fastest. The first cell's point is (1, 1, 1), the last (7, 7, 7).
    EXPECT_EQ(p.row(g.front()), Eigen::RowVector3d(1, 1, 1));
    EXPECT_EQ(p.row(g.back()), Eigen::RowVector3d(7, 7, 7));
}

TEST(SpatialGrid, EmptyCellsContributeNothingAndResultIsDeterministic) {
    // Two clusters at opposite corners: a 4^3 grid has only two occupied cells.
    Eigen::MatrixXd p(6, 3);
    p << 0, 0, 0, 0.1, 0, 0, 0, 0.2, 0, 10, 10, 10, 9.9, 10, 10, 9.8, 9.9, 10;
    const std::vector<pmsc::Index> g = pmsc::sparseGridPoints(p, 4);
    ASSERT_EQ(g.size(), 2u);
    EXPECT_EQ(g, pmsc::sparseGridPoints(p, 4));
    // Cell 0 spans [0, 2.5)^3 with centre (1.25, 1.25, 1.25): squared distances 4.69 (point 0),
    // 4.45 (point 1), 4.23 (point 2) -> point 2.
    EXPECT_EQ(g[0], 2);
    EXPECT_EQ(g[1], 5);  // centre 8.75: (9.8, 9.9, 10) is nearest
}

TEST(SpatialGrid, ByCountStaysWithinTheCountAndCoversSpace) {
    std::mt19937_64 rng(71);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    Eigen::MatrixXd p(5000, 3);
    for (int i = 0; i < 5000; ++i) p.row(i) = Eigen::RowVector3d(u(rng), u(rng), 0.5 * u(rng));
    const std::vector<pmsc::Index> g = pmsc::sparseGridPointsByCount(p, 50);
    EXPECT_LE(g.size(), 50u);
    EXPECT_GE(g.size(), 20u);  // the finest grid under the count is not much coarser than asked
    EXPECT_EQ(std::set<pmsc::Index>(g.begin(), g.end()).size(), g.size());
    // Asking for more points than exist gives every point at most once.
    EXPECT_LE(pmsc::sparseGridPointsByCount(p.topRows(10), 100).size(), 10u);
}

TEST(SpatialGrid, DegenerateAndInvalidInput) {
    Eigen::MatrixXd same(4, 3);
    same.setConstant(2.0);
    EXPECT_EQ(pmsc::sparseGridPoints(same, 5), (std::vector<pmsc::Index>{0}));
    EXPECT_TRUE(pmsc::sparseGridPoints(Eigen::MatrixXd(0, 3), 3).empty());
    EXPECT_THROW(pmsc::sparseGridPoints(same, 0), std::invalid_argument);
    EXPECT_THROW(pmsc::sparseGridPoints(Eigen::MatrixXd(4, 2), 3), std::invalid_argument);
    same(2, 1) = std::nan("");
    EXPECT_THROW(pmsc::sparseGridPoints(same, 3), std::invalid_argument);
    EXPECT_THROW(pmsc::sparseGridPointsByCount(lattice(3), 0), std::invalid_argument);
}
