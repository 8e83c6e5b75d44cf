// Channels sharing one basis (Model::sharedChannels, TrainingOptions::sharedChannels).
#include "pmsc/Calibration.h"
#include "pmsc/Communicator.h"
#include "pmsc/Errors.h"
#include "pmsc/Learning.h"
#include "pmsc/Model.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Training.h"

#include "Synthetic.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>
#include <vector>

namespace {

using pmsc::Index;

// Light-like frames: point p, channel c of frame f is colour_c(f) * (g_c(p) . w(f)), where the
// g_c are `rank` spatial fields per channel drawn from one rank-`rank` space (so the channels
// share spatial modes but are not proportional) and colour(f) changes from frame to frame.
struct LightFrames {
    Eigen::MatrixXd modes;  // N x rank: the shared spatial modes
    Eigen::MatrixXd mix;    // rank x (rank*C): each channel's own combination of the modes
    Index n, c, rank;

    LightFrames(Index points, Index channels, Index r) : n(points), c(channels), rank(r) {
        modes = pmsc::test::gaussian(n, rank, 11).cwiseAbs();
        mix = Eigen::MatrixXd::Identity(rank, rank * c) + 0.2 * pmsc::test::gaussian(rank, rank * c, 12);
    }
    // One frame: weights w (rank) and an RGB colour.
    void frame(const Eigen::VectorXd& w, const std::vector<double>& colour, double* out) const {
        for (Index ch = 0; ch < c; ++ch) {
            const Eigen::VectorXd v = modes * (mix.middleCols(ch * rank, rank) * w);
            for (Index p = 0; p < n; ++p) out[p * c + ch] = colour[static_cast<size_t>(ch)] * (1.0 + v[p]);
        }
    }
    pmsc::FrameSet training(Index frames) const {
        pmsc::FrameSet q(frames, n, c);
        const Eigen::MatrixXd w = pmsc::test::gaussian(rank, frames, 13);
        for (Index f = 0; f < frames; ++f) {
            // Two colours only, alternating: a colour between them is outside their plane.
            std::vector<double> colour =
                f % 2 ? std::vector<double>{1.2, 1.0, 0.7} : std::vector<double>{0.8, 1.0, 1.3};
            if (c != 3) {  // other channel counts: the same two ramps over the channels
                colour.assign(static_cast<size_t>(c), 1.0);
                for (Index ch = 0; ch < c; ++ch) {
                    const double t = c > 1 ? static_cast<double>(ch) / static_cast<double>(c - 1) : 0.0;
                    colour[static_cast<size_t>(ch)] = f % 2 ? 1.2 - 0.5 * t : 0.8 + 0.5 * t;
                }
            }
            frame(w.col(f), colour, q.frame(f));
        }
        return q;
    }
};

std::vector<double> keysOf(const pmsc::Model& model, const double* frame) {
    std::vector<double> k;
    for (Index p : model.keyPoints)
        for (Index ch = 0; ch < model.channels; ++ch) k.push_back(frame[p * model.channels + ch]);
    return k;
}

// Relative RMS error of point multiplication from the keys on one frame.
double pmError(const pmsc::Model& model, const double* frame) {
    const pmsc::PointMultiplier pm(model);
    std::vector<double> coords(static_cast<size_t>(model.coordCount())),
        out(static_cast<size_t>(model.points * model.channels));
    const std::vector<double> keys = keysOf(model, frame);
    pm.project(keys.data(), coords.data());
    pm.reconstruct(coords.data(), out.data());
    double e = 0, s = 0;
    for (size_t i = 0; i < out.size(); ++i) {
        e += (out[i] - frame[i]) * (out[i] - frame[i]);
        s += frame[i] * frame[i];
    }
    return std::sqrt(e / s);
}

pmsc::TrainingOptions options(Index m, Index k, bool shared) {
    pmsc::TrainingOptions o;
    o.basis = m;
    o.maxKeys = k;
    o.sharedChannels = shared;
    return o;
}

}  // namespace

TEST(SharedChannels, ALightOfANewColourIsReproducedExactlyWhereAPerChannelBasisIsNot) {
    const LightFrames data(300, 3, 5);
    const pmsc::FrameSet q = data.training(40);
    // Rank 5 around a constant field: 6 shared vectors hold every channel of every frame.
    const pmsc::Model shared = pmsc::train(q, options(6, 20, true));
    const pmsc::Model separate = pmsc::train(q, options(6, 20, false));
    ASSERT_TRUE(shared.sharedChannels);
    EXPECT_EQ(shared.channels, 3);
    EXPECT_EQ(shared.basis.rows(), 300);
    EXPECT_EQ(shared.coordCount(), 18);
    EXPECT_EQ(separate.basis.rows(), 900);
    // A new pose in a colour neither training colour has (and outside their plane).
    std::vector<double> frame(900);
    data.frame(pmsc::test::gaussian(5, 1, 99).col(0), {1.0, 0.6, 0.4}, frame.data());
    EXPECT_LT(pmError(shared, frame.data()), 1e-9);
    EXPECT_GT(pmError(separate, frame.data()), 1e-3);
    // Training residual: Euclidean over channels, zero here.
    EXPECT_LT(shared.trainMaxPointResidual, 1e-8);
}

// The training residual is PM's largest point error (Euclidean over the channels) on the training
// frames, recomputed here frame by frame through PointMultiplier; 9,000 points: two slabs.
TEST(SharedChannels, TheTrainingResidualIsPmsLargestPointErrorOnTheTrainingFrames) {
    const LightFrames data(9000, 3, 6);
    static_assert(pmsc::kSlabPoints < 9000);
    // 180 frames: past the 170 frames of one product at 3 channels, and a spike PM cannot follow,
    // in the second run of frames and near the end of the last slab of points.
    pmsc::FrameSet q = data.training(180);
    q.frame(175)[8990 * 3 + 1] += 100;
    const pmsc::Model model = pmsc::train(q, options(4, 12, true));  // M < rank: residuals
    ASSERT_TRUE(model.sharedChannels);
    const pmsc::PointMultiplier pm(model);
    std::vector<double> coords(static_cast<size_t>(model.coordCount())), out(9000 * 3);
    double worst = 0;
    Index worstPoint = -1;
    for (Index f = 0; f < q.frames; ++f) {
        const std::vector<double> keys = keysOf(model, q.frame(f));
        pm.project(keys.data(), coords.data());
        pm.reconstruct(coords.data(), out.data());
        for (Index p = 0; p < 9000; ++p) {
            double e = 0;
            for (Index ch = 0; ch < 3; ++ch) {
                const double d = out[size_t(p * 3 + ch)] - q.frame(f)[p * 3 + ch];
                e += d * d;
            }
            if (std::sqrt(e) > worst) {
                worst = std::sqrt(e);
                worstPoint = p;
            }
        }
    }
    EXPECT_EQ(worstPoint, 8990);
    EXPECT_NEAR(model.trainMaxPointResidual, worst, 1e-10 * worst);
}

TEST(SharedChannels, ProjectReconstructAndKeyErrorAgreeWithTheFormulas) {
    const LightFrames data(120, 3, 4);
    const pmsc::Model model = pmsc::train(data.training(24), options(3, 10, true));  // M < rank: residuals
    const pmsc::PointMultiplier pm(model);
    std::vector<double> frame(360);
    data.frame(pmsc::test::gaussian(4, 1, 5).col(0), {0.9, 1.0, 1.1}, frame.data());
    const std::vector<double> keys = keysOf(model, frame.data());
    std::vector<double> coords(static_cast<size_t>(model.coordCount()));
    pm.project(keys.data(), coords.data());
    // coords_c = P (k_c - mean_K,c) for every channel.
    const Index m = model.basisSize(), k = model.keyCount();
    for (Index ch = 0; ch < 3; ++ch) {
        Eigen::VectorXd kc(k);
        for (Index i = 0; i < k; ++i)
            kc[i] = keys[static_cast<size_t>(i * 3 + ch)] -
                    model.mean[model.keyPoints[static_cast<size_t>(i)] * 3 + ch];
        const Eigen::VectorXd b = model.projector * kc;
        for (Index j = 0; j < m; ++j) EXPECT_NEAR(coords[static_cast<size_t>(j * 3 + ch)], b[j], 1e-12);
    }
    // Whole, range and subset reconstruction give the same values: mean_c + basis * coords_c.
    std::vector<double> all(360), range(3 * 50), some(3 * 3);
    pm.reconstruct(coords.data(), all.data());
    pm.reconstructRange(coords.data(), 40, 50, range.data());
    const std::vector<Index> points{7, 0, 119};
    pm.reconstructPoints(coords.data(), points, some.data());
    for (Index p = 0; p < 120; ++p)
        for (Index ch = 0; ch < 3; ++ch) {
            double v = model.mean[p * 3 + ch];
            for (Index j = 0; j < m; ++j) v += model.basis(p, j) * coords[static_cast<size_t>(j * 3 + ch)];
            EXPECT_NEAR(all[static_cast<size_t>(p * 3 + ch)], v, 1e-12);
        }
    for (Index i = 0; i < 50 * 3; ++i)
        EXPECT_EQ(range[static_cast<size_t>(i)], all[static_cast<size_t>(40 * 3 + i)]);
    for (size_t i = 0; i < points.size(); ++i)
        for (Index ch = 0; ch < 3; ++ch)
            EXPECT_NEAR(some[i * 3 + static_cast<size_t>(ch)], all[static_cast<size_t>(points[i] * 3 + ch)],
                        1e-12);
    // Key error: RMS over keys of the Euclidean error over channels, as for any model.
    double sum = 0;
    for (Index i = 0; i < k; ++i) {
        const Index p = model.keyPoints[static_cast<size_t>(i)];
        for (Index ch = 0; ch < 3; ++ch) {
            const double r = keys[static_cast<size_t>(i * 3 + ch)] - all[static_cast<size_t>(p * 3 + ch)];
            sum += r * r;
        }
    }
    const double expected = std::sqrt(sum / static_cast<double>(k));
    EXPECT_GT(expected, 1e-6);
    EXPECT_NEAR(pm.keyError(keys.data(), coords.data()), expected, 1e-12 + 1e-9 * expected);
    keysOf(model, frame.data());
    std::vector<double> bad = keys;
    bad[4] = std::nan("");
    EXPECT_TRUE(std::isnan(pm.keyError(bad.data(), coords.data())));
}

TEST(SharedChannels, CalibratedEpsBoundTheEuclideanPointErrorOfTheTrainingFrames) {
    const LightFrames data(200, 3, 6);
    const pmsc::FrameSet q = data.training(60);
    pmsc::TrainingOptions o = options(5, 12, true);  // M < rank + 1: frames have residuals
    o.tolerance = 0.6 * pmsc::train(q, o).trainMaxPointResidual;
    const pmsc::Model model = pmsc::train(q, o);
    ASSERT_GT(model.epsMin, 0);
    // A training frame the soft cache calls a hit has a Euclidean point error within the tolerance.
    const pmsc::PointMultiplier pm(model);
    int hits = 0;
    for (Index f = 0; f < q.frames; ++f) {
        const std::vector<double> keys = keysOf(model, q.frame(f));
        std::vector<double> coords(static_cast<size_t>(model.coordCount())), out(600);
        pm.project(keys.data(), coords.data());
        if (pm.keyError(keys.data(), coords.data()) > model.epsMin) continue;
        ++hits;
        pm.reconstruct(coords.data(), out.data());
        for (Index p = 0; p < 200; ++p) {
            double e = 0;
            for (Index ch = 0; ch < 3; ++ch)
                e += std::pow(out[static_cast<size_t>(p * 3 + ch)] - q.frame(f)[p * 3 + ch], 2);
            EXPECT_LE(std::sqrt(e), o.tolerance * (1 + 1e-9)) << "frame " << f << " point " << p;
        }
    }
    EXPECT_GT(hits, 0);
}

TEST(SharedChannels, UncalibratedEpsAreTheTrainingFramesLargestEuclideanKeyError) {
    // Without a tolerance eps_min is the largest key error of a training frame, measured the way
    // the runtime measures it (Euclidean over the channels), so every training frame is a hit.
    const LightFrames data(150, 3, 6);
    const pmsc::FrameSet q = data.training(30);
    const pmsc::Model model = pmsc::train(q, options(5, 12, true));
    const pmsc::PointMultiplier pm(model);
    double largest = 0;
    for (Index f = 0; f < q.frames; ++f) {
        const std::vector<double> keys = keysOf(model, q.frame(f));
        std::vector<double> coords(static_cast<size_t>(model.coordCount()));
        pm.project(keys.data(), coords.data());
        largest = std::max(largest, pm.keyError(keys.data(), coords.data()));
    }
    EXPECT_GT(largest, 1e-6);
    EXPECT_NEAR(model.epsMin, largest, 1e-12 * largest);
    EXPECT_NEAR(model.epsMax, 1.5 * largest, 1e-12 * largest);
}

TEST(SharedChannels, CombinationsThisVersionDoesNotSupportAreRejectedWithAReason) {
    const LightFrames data(60, 3, 3);
    const pmsc::FrameSet q = data.training(12);
    pmsc::TrainingOptions o = options(3, 8, true);
    o.learnRank = 5;
    try {
        (void)pmsc::train(q, o);
        FAIL() << "learning rank accepted";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("learning rank"), std::string::npos) << e.what();
    }
    o.learnRank = 0;
    o.regions.count = 2;
    EXPECT_THROW((void)pmsc::train(q, o), std::invalid_argument);
    // One channel: nothing to share, a plain model.
    pmsc::FrameSet one(12, 60, 1);
    for (Index f = 0; f < 12; ++f)
        for (Index p = 0; p < 60; ++p) one.frame(f)[p] = std::sin(0.3 * static_cast<double>(f * p + p));
    EXPECT_FALSE(pmsc::train(one, options(3, 8, true)).sharedChannels);
    // pmsc learn updates per-channel bases only.
    const pmsc::Model shared = pmsc::train(q, options(3, 8, true));
    try {
        (void)pmsc::learn(shared, q);
        FAIL() << "learn accepted a shared-channel model";
    } catch (const pmsc::InputError& e) {
        EXPECT_NE(std::string(e.what()).find("share one basis"), std::string::npos) << e.what();
    }
    // A model that says its channels share the basis but carries a per-channel one is invalid.
    pmsc::Model m = pmsc::train(q, options(3, 8, false));
    m.sharedChannels = true;
    EXPECT_THROW(m.validate(), std::invalid_argument);
}

TEST(SharedChannels, ReconstructRangeIsTheWholeFrameForAnyChunkAcrossThePanels) {
    // The engine reconstructs a frame in chunks of points that need not line up with the kernel's
    // panels of 16 rows (PointMultiplier.cpp): every chunking gives the whole frame's values, for
    // 1 to 4 channels and a C the kernel does not special-case (5), and three channels with rows
    // of their own, from the double basis and from the float one alike.
    const std::pair<Index, bool> layouts[] = {{1, true}, {2, true}, {3, true},
                                              {4, true}, {5, true}, {3, false}};
    for (const auto& [c, shared] : layouts) {
        const LightFrames data(700, c, 4);
        const pmsc::FrameSet q = data.training(16);
        const pmsc::Model model = pmsc::train(q, options(4, 12, shared));
        ASSERT_EQ(model.sharedChannels, shared && c > 1);
        std::vector<double> coords(static_cast<size_t>(model.coordCount()));
        for (size_t i = 0; i < coords.size(); ++i) coords[i] = 0.1 * std::sin(static_cast<double>(i) + 0.5);
        std::vector<double> all(static_cast<size_t>(700 * c));
        for (const auto precision : {pmsc::BasisPrecision::Single, pmsc::BasisPrecision::Double}) {
            const pmsc::PointMultiplier pm(model, precision);
            pm.reconstruct(coords.data(), all.data());
            for (Index chunk : {1, 7, 15, 16, 17, 255, 256, 257, 300, 699, 700}) {
                std::vector<double> pieces(all.size(), std::nan(""));
                for (Index first = 0; first < 700; first += chunk) {
                    const Index count = std::min<Index>(chunk, 700 - first);
                    pm.reconstructRange(coords.data(), first, count, pieces.data() + first * c);
                }
                // Bit for bit through the panel kernel: each point's sum runs in the same order in
                // any chunk.
                for (size_t i = 0; i < all.size(); ++i)
                    ASSERT_EQ(pieces[i], all[i]) << "C " << c << " chunk " << chunk << " value " << i;
            }
        }
        // `all` is the double basis's now; the float basis's is within a float's rounding of it.
        const pmsc::PointMultiplier single(model, pmsc::BasisPrecision::Single);
        std::vector<double> fromSingle(all.size());
        single.reconstruct(coords.data(), fromSingle.data());
        double largest = 0, scale = 0;
        for (size_t i = 0; i < all.size(); ++i) {
            largest = std::max(largest, std::abs(fromSingle[i] - all[i]));
            scale = std::max(scale, std::abs(all[i]));
        }
        EXPECT_GT(largest, 0.0) << "C " << c << ": the float basis should round somewhere";
        EXPECT_LT(largest, 1e-6 * scale) << "C " << c;
        // Against the formula, mean_c + basis * coords_c (or the plain model's when C = 1).
        for (Index p : {0, 255, 256, 511, 512, 699})
            for (Index ch = 0; ch < c; ++ch) {
                double v = model.mean[p * c + ch];
                for (Index j = 0; j < model.basisSize(); ++j)
                    v += model.sharedChannels ? model.basis(p, j) * coords[static_cast<size_t>(j * c + ch)]
                                              : model.basis(p * c + ch, j) * coords[static_cast<size_t>(j)];
                EXPECT_NEAR(all[static_cast<size_t>(p * c + ch)], v, 1e-12) << "C " << c << " point " << p;
            }
    }
}

TEST(SharedChannels, CalibrationScoresOneEntryPerFrameInTheRuntimesMeasures) {
    // Grouped calibration (shared channels: a frame's C channel frames are one group) gives one
    // entry per group: e = sqrt(sum e^2) (the frame's Euclidean key error) and E = sqrt(sum E^2)
    // (a bound on its Euclidean point error). With slice boundaries that fall on group boundaries
    // anyway (12 columns, 4 slices, groups of 3) the folds are the same as ungrouped, so the
    // grouped entries are exactly the ungrouped ones combined.
    const Eigen::MatrixXd q = pmsc::test::gaussian(90, 12, 21) * 0.1 +
                              pmsc::test::gaussian(90, 3, 22) * pmsc::test::gaussian(3, 12, 23);
    const std::vector<Index> keys{2, 11, 30, 47, 63, 80};
    pmsc::MatrixBlocks blocks(q, 1, /*centre=*/false);
    pmsc::SingleProcess one;
    const Eigen::MatrixXd keyRows = pmsc::gatherKeyRows(q, 1, keys), gram = pmsc::gramMatrix(q);
    const auto flat = pmsc::calibrate(blocks, one, keyRows, keys, 2, 1.0, 4, gram);
    const auto grouped =
        pmsc::calibrate(blocks, one, keyRows, keys, 2, 1.0, 4, gram, pmsc::CalibrationRule::MaxRatio, 0.9, 3);
    ASSERT_EQ(flat.frames.size(), 12u);
    ASSERT_EQ(grouped.frames.size(), 4u);
    for (size_t g = 0; g < 4; ++g) {
        EXPECT_EQ(grouped.frames[g], static_cast<Index>(g));
        double k2 = 0, e2 = 0;
        for (size_t j = 3 * g; j < 3 * g + 3; ++j) {
            k2 += flat.keyRms[j] * flat.keyRms[j];
            e2 += flat.maxPointError[j] * flat.maxPointError[j];
        }
        EXPECT_NEAR(grouped.keyRms[g], std::sqrt(k2), 1e-12 * std::sqrt(k2));
        EXPECT_NEAR(grouped.maxPointError[g], std::sqrt(e2), 1e-12 * std::sqrt(e2));
    }
    // sqrt(sum E^2) / sqrt(sum e^2) <= max E / e: grouping never asks for a larger ratio.
    EXPECT_LE(grouped.maxRatio, flat.maxRatio * (1 + 1e-12));
    EXPECT_EQ(grouped.usableFrames, 4);
    // Slices count groups; a column count that is not whole groups is refused.
    EXPECT_THROW((void)pmsc::calibrate(blocks, one, keyRows, keys, 2, 1.0, 5, gram,
                                       pmsc::CalibrationRule::MaxRatio, 0.9, 3),
                 std::invalid_argument);
    EXPECT_THROW((void)pmsc::calibrate(blocks, one, keyRows, keys, 2, 1.0, 2, gram,
                                       pmsc::CalibrationRule::MaxRatio, 0.9, 5),
                 std::invalid_argument);
}

TEST(SharedChannels, TrainingReportsOneCalibrationEntryPerFrame) {
    const LightFrames data(200, 3, 6);
    const pmsc::FrameSet q = data.training(30);
    pmsc::TrainingOptions o = options(5, 12, true);
    o.tolerance = 0.05;
    o.calibrationRule = pmsc::CalibrationRule::Conformal;
    o.calibrationCoverage = 0.8;
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(q, o, &report);
    ASSERT_EQ(report.calibration.frames.size(), 30u);
    for (size_t f = 0; f < 30; ++f) EXPECT_EQ(report.calibration.frames[f], static_cast<Index>(f));
    EXPECT_LE(report.calibration.usableFrames, 30);
    EXPECT_GT(model.epsMin, 0);
    EXPECT_EQ(report.calibration.rule, pmsc::CalibrationRule::Conformal);
}
