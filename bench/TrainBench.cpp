// pmsc_train_bench — times pmsc::train at the ICT face scale (goal: 600 frames x
// 26,719 points x 3, 170 keys, M around 60-100, under 15 s on the 2-core machine).
//
// The data is synthetic with a face-like spectrum: smooth low-rank blendshape motion (Gaussian
// bumps with decaying amplitudes driven by smooth weight curves), a nonlinear component (a jaw
// region rotated by an angle that varies over time: positions are not linear in the angle), and
// small noise. Prints the time of each training stage (from the progress hook) and the total.
//
// usage: pmsc_train_bench [frames=600] [points=26719] [keys=170] [basis=0 (energy rule)]
//                         [selector=teleconnection|qdeim] [tolerance=0] [energy=0.9999]
#include "pmsc/Training.h"

#include <Eigen/Core>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <random>
#include <string>

namespace {

// CPU seconds of the whole process: on a shared machine the wall clock also counts other users'
// work, the CPU time counts only ours (single-threaded Eigen: CPU ~= wall on an idle machine).
double cpuSeconds() {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

pmsc::FrameSet faceLikeFrames(pmsc::Index frames, pmsc::Index points, unsigned seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    std::normal_distribution<double> normal(0.0, 1.0);
    // Rest positions on an ellipsoid "head" of ~20 units.
    Eigen::MatrixXd rest(points, 3);
    for (pmsc::Index p = 0; p < points; ++p) {
        Eigen::Vector3d d(normal(rng), normal(rng), normal(rng));
        d.normalize();
        rest.row(p) = Eigen::RowVector3d(8 * d.x(), 11 * d.y(), 9 * d.z());
    }
    const int shapes = 96;
    Eigen::MatrixXd centre(shapes, 3), dir(shapes, 3);
    Eigen::VectorXd radius(shapes), amp(shapes), freq(shapes), phase(shapes);
    for (int k = 0; k < shapes; ++k) {
        const pmsc::Index p =
            static_cast<pmsc::Index>(std::abs(uniform(rng)) * static_cast<double>(points - 1));
        centre.row(k) = rest.row(p);
        dir.row(k) = Eigen::RowVector3d(uniform(rng), uniform(rng), uniform(rng)).normalized();
        radius[k] = 1.5 + 3.0 * std::abs(uniform(rng));
        amp[k] = 1.2 * std::pow(0.96, k);
        freq[k] = 0.01 + 0.05 * std::abs(uniform(rng));
        phase[k] = 6.28 * uniform(rng);
    }
    // Blendshape displacement fields, one column per shape (N*3 x shapes).
    Eigen::MatrixXd fields(points * 3, shapes);
    for (int k = 0; k < shapes; ++k)
        for (pmsc::Index p = 0; p < points; ++p) {
            const double g = std::exp(-(rest.row(p) - centre.row(k)).squaredNorm() / (radius[k] * radius[k]));
            for (int c = 0; c < 3; ++c) fields(p * 3 + c, k) = amp[k] * g * dir(k, c);
        }
    Eigen::MatrixXd weights(shapes, frames);
    for (int k = 0; k < shapes; ++k)
        for (pmsc::Index t = 0; t < frames; ++t) {
            const double s = std::sin(freq[k] * static_cast<double>(t) + phase[k]) +
                             0.5 * std::sin(2.7 * freq[k] * static_cast<double>(t) + 2 * phase[k]);
            weights(k, t) = std::max(0.0, s);
        }
    pmsc::FrameSet set(frames, points, 3);
    auto q = set.matrix();
    q.noalias() = fields * weights;
    // Jaw: points below y = -3 rotate about the x axis through (0, -2, -4) by up to 0.35 rad, with a
    // smooth falloff; sin/cos of the angle make this component genuinely nonlinear.
    for (pmsc::Index t = 0; t < frames; ++t) {
        const double angle = 0.35 * std::max(0.0, std::sin(0.021 * static_cast<double>(t)));
        const double cs = std::cos(angle), sn = std::sin(angle);
        double* f = set.frame(t);
        for (pmsc::Index p = 0; p < points; ++p) {
            const double y = rest(p, 1);
            const double w = y < -3 ? 1.0 : (y < 0 ? (-y) / 3.0 : 0.0);
            const double yy = rest(p, 1) + 2, zz = rest(p, 2) + 4;
            const double ry = cs * yy - sn * zz - 2, rz = sn * yy + cs * zz - 4;
            f[p * 3 + 0] += rest(p, 0);
            f[p * 3 + 1] += rest(p, 1) + w * (ry - rest(p, 1));
            f[p * 3 + 2] += rest(p, 2) + w * (rz - rest(p, 2));
            for (int c = 0; c < 3; ++c) f[p * 3 + c] += 1e-4 * normal(rng);
        }
    }
    return set;
}

}  // namespace

int main(int argc, char** argv) {
    auto arg = [&](int i, const char* fallback) { return std::string(argc > i ? argv[i] : fallback); };
    const pmsc::Index frames = std::stol(arg(1, "600"));
    const pmsc::Index points = std::stol(arg(2, "26719"));
    pmsc::TrainingOptions o;
    o.maxKeys = std::stol(arg(3, "170"));
    o.basis = std::stol(arg(4, "0"));
    o.selector = arg(5, "teleconnection") == "qdeim" ? pmsc::Selector::QDeim : pmsc::Selector::Teleconnection;
    o.tolerance = std::stod(arg(6, "0"));
    o.energy = std::stod(arg(7, "0.9999"));

    const auto t0 = std::chrono::steady_clock::now();
    const pmsc::FrameSet set = faceLikeFrames(frames, points, 42);
    const auto t1 = std::chrono::steady_clock::now();
    std::printf("data: %ld frames x %ld points x 3 generated in %.2f s\n", static_cast<long>(frames),
                static_cast<long>(points), std::chrono::duration<double>(t1 - t0).count());

    std::string stage;
    auto stageStart = std::chrono::steady_clock::now();
    double stageCpu = cpuSeconds();
    const double trainCpu = stageCpu;
    o.progress = [&](std::string_view s, double done, double total) {
        const auto now = std::chrono::steady_clock::now();
        if (s != stage) {
            const double cpu = cpuSeconds();
            if (!stage.empty())
                std::printf("  %-12s %6.2f s wall %6.2f s cpu\n", stage.c_str(),
                            std::chrono::duration<double>(now - stageStart).count(), cpu - stageCpu);
            stage = std::string(s);
            stageStart = now;
            stageCpu = cpu;
        }
        (void)done;
        (void)total;
        return true;
    };
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(set, o, &report);
    const auto now = std::chrono::steady_clock::now();
    const double cpu = cpuSeconds();
    std::printf("  %-12s %6.2f s wall %6.2f s cpu\n", stage.c_str(),
                std::chrono::duration<double>(now - stageStart).count(), cpu - stageCpu);
    std::printf(
        "train: %.2f s wall, %.2f s cpu  (M = %ld of %ld requested, K = %ld, rounds = %ld, energy %.6f)\n",
        report.seconds, cpu - trainCpu, static_cast<long>(model.basisSize()),
        static_cast<long>(report.requestedBasis), static_cast<long>(model.keyCount()),
        static_cast<long>(report.iterations), model.energyCaptured());
    std::printf("largest training point residual per round:");
    for (double r : report.residualPerRound) std::printf(" %.4g", r);
    std::printf("\neps = [%.4g, %.4g]", model.epsMin, model.epsMax);
    if (o.tolerance > 0)
        std::printf(" (calibrated for T = %g, r = %.3g)", o.tolerance, report.calibration.ratio);
    std::printf("\n");
    for (const auto& w : report.warnings) std::printf("warning: %s\n", w.c_str());
    return 0;
}
