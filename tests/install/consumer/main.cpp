// Embeds pmsc: trains on frames it makes, saves and reloads the model, and runs the soft cache on
// a frame inside and a frame outside the training subspace, and replays the frames through
// pmsc::evaluators, and lights a small smoke cube through the registry's "volume" evaluator.
// Prints "pmsc consumer: ok".
#include <evaluators/EvaluatorRegistry.h>
#include <evaluators/volume/DensityVolume.h>
#include <pmsc/ModelIO.h>
#include <pmsc/NpyIO.h>
#include <pmsc/PointMultiplier.h>
#include <pmsc/SoftCache.h>
#include <pmsc/Training.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
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
        const double err = pm.keyError(keys.data(), coords.data());
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
    // pmsc::volume through the registry: a cube mesh made into smoke, then the light scattered
    // at its voxels for the first training light, all points against a subset.
    const std::string obj = std::string(argv[1]) + ".cube.obj", vdb = std::string(argv[1]) + ".cube.vdb";
    {
        std::ofstream cube(obj);
        cube << "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
                "f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\n"
                "f 4 1 5\nf 4 5 8\n";
    }
    pmsc::volume::FogOptions fog;
    fog.targetVoxels = 3000;
    pmsc::volume::DensityVolume::fromMesh(obj, fog).write(vdb);
    const auto volume = pmsc::evaluators::makeEvaluator("volume:" + vdb + ":samples=2:lights=training");
    const pmsc::Index n = volume->pointCount();
    std::vector<double> all(static_cast<std::size_t>(n * 3)), some(6);
    volume->evaluateAll(0, all.data());
    const pmsc::Index chosen[2] = {0, n - 1};
    volume->evaluate(0, chosen, some.data());
    for (int c = 0; c < 3; ++c)
        if (n < 1000 || !(all[c] > 0) || some[c] != all[c] || some[3 + c] != all[(n - 1) * 3 + c]) {
            std::printf("pmsc consumer: FAILED (volume evaluator, %lld voxels)\n", static_cast<long long>(n));
            return 1;
        }
    std::printf("volume evaluator: %lld voxels lit\n", static_cast<long long>(n));
    std::printf("pmsc consumer: ok\n");
    return 0;
}
