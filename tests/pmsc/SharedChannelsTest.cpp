// Channels sharing one basis (Model::sharedChannels, TrainingOptions::sharedChannels; issue 11).
#include "pmsc/Errors.h"
#include "pmsc/Learning.h"
#include "pmsc/Model.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/Training.h"

#include "Synthetic.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
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
            const std::vector<double> colour = f % 2 ? std::vector<double>{1.2, 1.0, 0.7} : std::vector<double>{0.8, 1.0, 1.3};
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
    std::vector<double> coords(static_cast<size_t>(model.coordCount())), out(static_cast<size_t>(model.points * model.channels));
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
            kc[i] = keys[static_cast<size_t>(i * 3 + ch)] - model.mean[model.keyPoints[static_cast<size_t>(i)] * 3 + ch];
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
    for (Index i = 0; i < 50 * 3; ++i) EXPECT_EQ(range[static_cast<size_t>(i)], all[static_cast<size_t>(40 * 3 + i)]);
    for (size_t i = 0; i < points.size(); ++i)
        for (Index ch = 0; ch < 3; ++ch)
            EXPECT_NEAR(some[i * 3 + static_cast<size_t>(ch)], all[static_cast<size_t>(points[i] * 3 + ch)], 1e-12);
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
    EXPECT_NEAR(pm.keyRmsError(keys.data(), coords.data()), expected, 1e-12 + 1e-9 * expected);
    keysOf(model, frame.data());
    std::vector<double> bad = keys;
    bad[4] = std::nan("");
    EXPECT_TRUE(std::isnan(pm.keyRmsError(bad.data(), coords.data())));
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
        if (pm.keyRmsError(keys.data(), coords.data()) > model.epsMin) continue;
        ++hits;
        pm.reconstruct(coords.data(), out.data());
        for (Index p = 0; p < 200; ++p) {
            double e = 0;
            for (Index ch = 0; ch < 3; ++ch) e += std::pow(out[static_cast<size_t>(p * 3 + ch)] - q.frame(f)[p * 3 + ch], 2);
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
        largest = std::max(largest, pm.keyRmsError(keys.data(), coords.data()));
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
