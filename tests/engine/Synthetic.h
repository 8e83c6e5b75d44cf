// pmsc — test helpers for the engine: a hand-built model and an instrumented evaluator.
#pragma once

#include "pmsc/Model.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/SoftCache.h"
#include "tests/common/SplitMix.h"

#include <Eigen/QR>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <future>
#include <limits>
#include <mutex>
#include <span>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace pmsc::testing {

/// A model built by hand: orthonormal random basis (QR), random mean, keys spread evenly over
/// the points, projector from makeProjector. No training involved, so engine tests do not
/// depend on the key-point selector.
inline Model makeModel(Index points, Index channels, Index basis, Index keys, unsigned seed = 7) {
    Model m;
    m.points = points;
    m.channels = channels;
    m.trainFrames = 10;
    const Index rows = points * channels;
    Eigen::MatrixXd g(rows, basis);
    for (Index i = 0; i < rows; ++i)
        for (Index j = 0; j < basis; ++j) g(i, j) = unit(seed, std::uint64_t(i * basis + j));
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(g);
    m.basis = qr.householderQ() * Eigen::MatrixXd::Identity(rows, basis);
    m.mean.resize(rows);
    for (Index i = 0; i < rows; ++i) m.mean[i] = 3.0 * unit(seed + 1, std::uint64_t(i));
    m.singularValues = Eigen::VectorXd::LinSpaced(basis, double(basis), 1.0);
    m.totalEnergy = m.singularValues.squaredNorm();
    for (Index k = 0; k < keys; ++k) m.keyPoints.push_back((k * points) / keys + (k % 2));
    m.projector = makeProjector(m.basis, channels, m.keyPoints);
    m.epsMin = 0;
    m.epsMax = 0;
    m.validate();
    return m;
}

/// How a frame of the synthetic evaluator behaves: noise amplitude outside the subspace by
/// frame class (f % 4: 0,3 in the subspace -> hits; 1 small noise -> blend; 2 large -> miss).
inline double noiseAmplitude(Index frame) {
    switch (frame % 4) {
        case 1:
            return 0.01;
        case 2:
            return 1.0;
        default:
            return 0.0;
    }
}

/// value(f, x) = mean[x] + sum_j basis(x, j) * coord_j(f) + amp(f) * u(f, x): deterministic per
/// point, so any subset, chunking or thread count gives the same values. Instrumented: counts
/// key and full calls per frame, frames in flight, optional random delays, failures and NaNs.
class SyntheticEvaluator : public PointEvaluator {
public:
    SyntheticEvaluator(const Model& model, Index frames) : model_(model), frames_(frames) {
        keyCalls_ = std::vector<std::atomic<int>>(size_t(frames));
        fullCalls_ = std::vector<std::atomic<int>>(size_t(frames));
    }

    std::string name() const override { return "synthetic"; }
    Index pointCount() const override { return model_.points; }
    Index channelCount() const override { return model_.channels; }
    Index frameCount() const override { return frames_; }

    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        if (frame < 0 || frame >= frames_)
            throw std::out_of_range("synthetic: frame " + std::to_string(frame));
        if (cancelWatch && cancelWatch->load()) callsAfterCancel_.fetch_add(1);
        const bool keyCall = points.data() == model_.keyPoints.data();
        if (keyCall) {
            keyCalls_[size_t(frame)].fetch_add(1);
            const long now = inFlight_.fetch_add(1) + 1;
            long peak = peakInFlight_.load();
            while (now > peak && !peakInFlight_.compare_exchange_weak(peak, now)) {
            }
        } else {
            fullCalls_[size_t(frame)].fetch_add(1);
            pointsEvaluated_.fetch_add(long(points.size()));
        }
        if (maxDelayMicros > 0) {
            std::this_thread::sleep_for(std::chrono::microseconds(
                mix(std::uint64_t(frame) * 31 + points.size()) % std::uint64_t(maxDelayMicros)));
        }
        if (busyMicros > 0) busyWait(busyMicros);
        if (keyCall && frame == throwInKeysAt) throw std::runtime_error("injected key failure");
        if (!keyCall && frame == throwInFullAt) throw std::runtime_error("injected full failure");
        const Index c = model_.channels;
        for (size_t i = 0; i < points.size(); ++i) {
            for (Index ch = 0; ch < c; ++ch) out[Index(i) * c + ch] = value(frame, points[i], ch);
        }
        if (keyCall && frame == nanInKeysAt) out[0] = std::numeric_limits<double>::quiet_NaN();
        if (!keyCall && frame == nanInFullAt) {
            for (size_t i = 0; i < points.size(); ++i)
                if (points[i] == nanPoint) out[Index(i) * c] = std::numeric_limits<double>::infinity();
        }
    }

    double value(Index frame, Index point, Index channel) const {
        const Index x = point * model_.channels + channel;
        double v = model_.mean[x];
        for (Index j = 0; j < model_.basisSize(); ++j) v += model_.basis(x, j) * coord(frame, j);
        return v + noiseAmplitude(frame) * unit(std::uint64_t(frame) + 1000, std::uint64_t(x));
    }
    static double coord(Index frame, Index j) {
        return 2.0 * unit(std::uint64_t(frame) * 7919 + 17, std::uint64_t(j));
    }

    /// Called by the test sink when a frame arrives (the other end of the in-flight count).
    void frameDelivered() const { inFlight_.fetch_sub(1); }
    long peakInFlight() const { return peakInFlight_.load(); }
    int keyCalls(Index frame) const { return keyCalls_[size_t(frame)].load(); }
    int fullCalls(Index frame) const { return fullCalls_[size_t(frame)].load(); }
    long pointsEvaluated() const { return pointsEvaluated_.load(); }
    /// Evaluator calls that began after *cancelWatch became true.
    int callsAfterCancel() const { return callsAfterCancel_.load(); }

    static void busyWait(int micros) {
        const auto end = std::chrono::steady_clock::now() + std::chrono::microseconds(micros);
        while (std::chrono::steady_clock::now() < end) {
        }
    }

    // Knobs, set before a run.
    int maxDelayMicros = 0;
    int busyMicros = 0;
    Index throwInKeysAt = -1;
    Index throwInFullAt = -1;
    Index nanInKeysAt = -1;
    Index nanInFullAt = -1;
    Index nanPoint = 0;
    const std::atomic<bool>* cancelWatch = nullptr;  ///< counts calls begun after it turned true

private:
    const Model& model_;
    Index frames_;
    mutable std::vector<std::atomic<int>> keyCalls_;
    mutable std::vector<std::atomic<int>> fullCalls_;
    mutable std::atomic<long> inFlight_{0};
    mutable std::atomic<long> peakInFlight_{0};
    mutable std::atomic<long> pointsEvaluated_{0};
    mutable std::atomic<int> callsAfterCancel_{0};
};

/// Thresholds that make the synthetic frame classes hit / blend / miss: measured key errors of
/// frames 1 (blend class) and 2 (miss class) put the zone between them.
inline SoftCachePolicy syntheticPolicy(const Model& model, const SyntheticEvaluator& e) {
    const PointMultiplier pm(model);
    const auto keyError = [&](Index f) {
        std::vector<double> k(size_t(model.keyCount() * model.channels)), b(size_t(model.basisSize()));
        for (Index i = 0; i < model.keyCount(); ++i)
            for (Index c = 0; c < model.channels; ++c)
                k[size_t(i * model.channels + c)] = e.value(f, model.keyPoints[size_t(i)], c);
        pm.project(k.data(), b.data());
        return pm.keyError(k.data(), b.data());
    };
    double blendMax = 0, missMin = std::numeric_limits<double>::max();
    for (Index f = 1; f < std::min<Index>(e.frameCount(), 200); f += 4)
        blendMax = std::max(blendMax, keyError(f));
    for (Index f = 2; f < std::min<Index>(e.frameCount(), 200); f += 4)
        missMin = std::min(missMin, keyError(f));
    if (!(blendMax * 2 < missMin)) throw std::logic_error("synthetic frame classes overlap");
    return SoftCachePolicy(blendMax * 0.05, blendMax * 2);
}

/// The soft-cached value of every point of a frame computed the plain way, serially, straight
/// from the paper's section 5 and 6 (the independent reference the engine is checked against).
inline std::vector<double> referenceFrame(const Model& model, const SyntheticEvaluator& e,
                                          const SoftCachePolicy& policy, Index frame,
                                          CacheDecision* decisionOut = nullptr) {
    const PointMultiplier pm(model);
    const Index c = model.channels;
    std::vector<double> k(size_t(model.keyCount() * c)), b(size_t(model.basisSize()));
    for (Index i = 0; i < model.keyCount(); ++i)
        for (Index ch = 0; ch < c; ++ch)
            k[size_t(i * c + ch)] = e.value(frame, model.keyPoints[size_t(i)], ch);
    pm.project(k.data(), b.data());
    const CacheDecision d = policy.decide(pm.keyError(k.data(), b.data()));
    if (decisionOut) *decisionOut = d;
    std::vector<double> pmv(size_t(model.points * c)), out(size_t(model.points * c));
    pm.reconstruct(b.data(), pmv.data());
    for (Index p = 0; p < model.points; ++p) {
        for (Index ch = 0; ch < c; ++ch) {
            const size_t x = size_t(p * c + ch);
            out[x] = (1 - d.weight) * pmv[x] + d.weight * e.value(frame, p, ch);
        }
    }
    return out;
}

/// Runs `body` on another thread; if it does not finish within `seconds`, the test program
/// exits with a message: a hang fails the test instead of blocking CI.
template <class Body>
void withWatchdog(double seconds, const char* what, Body&& body) {
    auto task = std::async(std::launch::async, std::forward<Body>(body));
    if (task.wait_for(std::chrono::duration<double>(seconds)) != std::future_status::ready) {
        std::fprintf(stderr, "watchdog: '%s' did not finish within %.0f s (deadlock?)\n", what, seconds);
        std::fflush(stderr);
        std::_Exit(3);
    }
    task.get();  // rethrows the body's exception (gtest assertions inside run on that thread)
}

}  // namespace pmsc::testing
