// pmsc — models and evaluators the engine benchmarks share (bench/EngineBench.cpp).
#pragma once

#include "pmsc/Model.h"
#include "pmsc/PointEvaluator.h"
#include "tests/common/SplitMix.h"

#include <Eigen/QR>

#include <chrono>
#include <cstdint>
#include <ctime>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace pmsc::bench {

using testing::mix;
using testing::unit;

/// A model with an orthonormal random basis (QR), K keys spread over the N points and the
/// least-squares projector. The paper's face (section 7) is N = 2986, M = 85, K = 170.
inline Model makeModel(Index points, Index channels, Index basis, Index keys) {
    Model m;
    m.points = points;
    m.channels = channels;
    m.trainFrames = basis;
    const Index rows = points * channels;
    Eigen::MatrixXd g(rows, basis);
    for (Index j = 0; j < basis; ++j)
        for (Index i = 0; i < rows; ++i) g(i, j) = unit(11, std::uint64_t(j * rows + i));
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(g);
    m.basis = qr.householderQ() * Eigen::MatrixXd::Identity(rows, basis);
    m.mean = Eigen::VectorXd::NullaryExpr(rows, [](Index i) { return unit(12, std::uint64_t(i)); });
    m.singularValues = Eigen::VectorXd::LinSpaced(basis, double(basis), 1.0);
    m.totalEnergy = m.singularValues.squaredNorm();
    for (Index k = 0; k < keys; ++k) m.keyPoints.push_back((k * points) / keys);
    m.projector = makeProjector(m.basis, channels, m.keyPoints);
    m.epsMin = 1e-6;  // recorded frames lie in the subspace: every frame is a hit
    m.epsMax = 1e-5;
    return m;
}

/// Spins for about `iterations` dependent multiply-adds: computed busy work, not a sleep, so
/// it really occupies a core (and two threads need two cores).
inline double spin(std::uint64_t seed, long iterations) {
    double x = double(seed % 1000) * 1e-3 + 0.5;
    for (long i = 0; i < iterations; ++i) x = x * 0.999999 + 0.000001;
    return x;
}

/// This thread's CPU time in microseconds (not wall time: other programs sharing the cores
/// must not make the calibration below think the core is slower than it is).
inline double threadCpuMicroseconds() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) * 1e6 + double(ts.tv_nsec) * 1e-3;
}

/// Busy-work iterations per microsecond of CPU on this machine (measured once).
inline double spinsPerMicrosecond() {
    static const double rate = [] {
        const long n = 20'000'000;
        const double t0 = threadCpuMicroseconds();
        volatile double sink = spin(1, n);
        (void)sink;
        return double(n) / (threadCpuMicroseconds() - t0);
    }();
    return rate;
}

/// Recorded frames in the model's subspace (a hit each), read back like `pmsc replay` does,
/// plus an optional busy-work cost per evaluated point (linear cost) and per call.
class RecordedEvaluator : public PointEvaluator {
public:
    RecordedEvaluator(const Model& model, Index frames, Index recorded = 32)
        : points_(model.points),
          channels_(model.channels),
          frames_(frames),
          recorded_(recorded),
          table_(size_t(recorded * model.points * model.channels)) {
        if (model.sharedChannels)
            throw std::invalid_argument(
                "RecordedEvaluator: a model whose channels share the basis is not supported");
        const Index rows = model.points * model.channels;
        Eigen::VectorXd b(model.basisSize());
        for (Index f = 0; f < recorded; ++f) {
            for (Index j = 0; j < b.size(); ++j) b[j] = unit(13 + std::uint64_t(f), std::uint64_t(j));
            Eigen::Map<Eigen::VectorXd>(table_.data() + f * rows, rows) = model.mean + model.basis * b;
        }
    }
    std::string name() const override { return "recorded"; }
    Index pointCount() const override { return points_; }
    Index channelCount() const override { return channels_; }
    Index frameCount() const override { return frames_; }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        const double* src = table_.data() + (frame % recorded_) * points_ * channels_;
        double acc = 0;
        if (spinsPerPoint_ > 0) acc += spin(std::uint64_t(frame), spinsPerPoint_ * long(points.size()));
        for (size_t i = 0; i < points.size(); ++i) {
            for (Index c = 0; c < channels_; ++c)
                out[Index(i) * channels_ + c] = src[points[i] * channels_ + c];
        }
        // The busy work must not be optimized away; adding 0 * acc keeps the values exact.
        if (spinsPerPoint_ > 0 && acc == -1.0) out[0] += 1.0;
    }
    /// Busy-work cost of each evaluated point, in microseconds.
    void setMicrosecondsPerPoint(double us) { spinsPerPoint_ = long(us * spinsPerMicrosecond()); }

private:
    Index points_, channels_, frames_, recorded_;
    std::vector<double> table_;
    long spinsPerPoint_ = 0;
};

}  // namespace pmsc::bench
