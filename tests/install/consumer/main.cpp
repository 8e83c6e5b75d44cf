// Embeds pmsc: trains on frames it makes, saves and reloads the model, and runs the soft cache on
// a frame inside and a frame outside the training subspace, and replays the frames through
// pmsc::evaluators. Prints "pmsc consumer: ok".
#include <evaluators/EvaluatorRegistry.h>
#include <pmsc/ModelIO.h>
#include <pmsc/NpyIO.h>
#include <pmsc/PointMultiplier.h>
#include <pmsc/SoftCache.h>
#include <pmsc/Training.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

int main(int argc, char** argv) {
    if (argc != 2) return 2;
    // 40 frames of 50 points x 3 channels, each a mix of 3 smooth spatial patterns.
    const pmsc::Index frames = 40, points = 50;
    pmsc::FrameSet set(frames, points, 3);
    const auto pattern = [](int k, pmsc::Index p, int c) { return std::sin(0.1 * (k + 1) * p + c + k); };
    for (pmsc::Index f = 0; f < frames; ++f)
        for (pmsc::Index p = 0; p < points; ++p)
            for (int c = 0; c < 3; ++c) {
                double v = 0;
                for (int k = 0; k < 3; ++k) v += std::cos(0.3 * f * (k + 1) + k) * pattern(k, p, c);
                set.frame(f)[p * 3 + c] = v;
            }
    pmsc::TrainingOptions options;
    options.basis = 3;
    options.maxKeys = 6;
    const pmsc::Model trained = pmsc::train(set, options);
    pmsc::writeModel(argv[1], trained);
    const pmsc::Model model = pmsc::readModel(argv[1]);
    const pmsc::PointMultiplier pm(model);
    const pmsc::SoftCachePolicy policy(1e-6, 1e-3);

    std::vector<double> keys(static_cast<std::size_t>(model.keyCount() * 3)), coords(3),
        out(static_cast<std::size_t>(points * 3));
    const auto run = [&](const double* frame) {
        for (std::size_t i = 0; i < model.keyPoints.size(); ++i)
            for (int c = 0; c < 3; ++c) keys[i * 3 + c] = frame[model.keyPoints[i] * 3 + c];
        pm.project(keys.data(), coords.data());
        const double err = pm.keyRmsError(keys.data(), coords.data());
        pm.reconstruct(coords.data(), out.data());
        double worst = 0;
        for (pmsc::Index i = 0; i < points * 3; ++i) worst = std::max(worst, std::abs(out[i] - frame[i]));
        return std::make_pair(policy.decide(err).state, worst);
    };
    const auto inside = run(set.frame(7));
    std::vector<double> novel(set.frame(7), set.frame(7) + points * 3);
    for (pmsc::Index p = 0; p < points; ++p)
        novel[p * 3 + 1] += 0.3 * std::sin(0.77 * p);  // a pattern no training frame has
    const auto outside = run(novel.data());
    std::printf("in-subspace frame: %s, largest error %.3g; novel frame: %s\n",
                std::string(pmsc::toString(inside.first)).c_str(), inside.second,
                std::string(pmsc::toString(outside.first)).c_str());
    if (inside.first != pmsc::CacheState::Hit || inside.second > 1e-8 ||
        outside.first == pmsc::CacheState::Hit) {
        std::printf("pmsc consumer: FAILED\n");
        return 1;
    }
    // pmsc::evaluators: the training frames saved as .npy come back through the registry's
    // "replay" evaluator, value for value.
    const std::string npy = std::string(argv[1]) + ".npy";
    pmsc::writeFrames(npy, set, pmsc::NpyDtype::Float64);
    const auto replay = pmsc::evaluators::EvaluatorRegistry::withBuiltins().make("replay:" + npy);
    std::vector<double> again(static_cast<std::size_t>(points * 3));
    replay->evaluateAll(7, again.data());
    for (pmsc::Index i = 0; i < points * 3; ++i)
        if (again[i] != set.frame(7)[i] || replay->frameCount() != frames) {
            std::printf("pmsc consumer: FAILED (replay evaluator)\n");
            return 1;
        }
    std::printf("pmsc consumer: ok\n");
    return 0;
}
