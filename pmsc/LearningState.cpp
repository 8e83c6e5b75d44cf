#include "pmsc/LearningState.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace pmsc {

namespace {

[[noreturn]] void invalidState(const std::string& what) { throw std::invalid_argument("model: " + what); }

}  // namespace

void LearningState::validate(Index rows, Index basisSize, Index points) const {
    if (maxRank < basisSize) {
        invalidState("learning state rank " + std::to_string(maxRank) + " is below the basis size " +
                     std::to_string(basisSize));
    }
    if (extraBasis.rows() != rows && extraBasis.cols() > 0) {
        invalidState("learning state basis has " + std::to_string(extraBasis.rows()) +
                     " rows, expected N*C = " + std::to_string(rows));
    }
    if (extraBasis.cols() != extraSigma.size())
        invalidState("learning state: basis and singular values differ in count");
    if (basisSize + extraBasis.cols() > maxRank) {
        invalidState("learning state holds " + std::to_string(basisSize + extraBasis.cols()) +
                     " directions, more than its rank " + std::to_string(maxRank));
    }
    for (Index i = 0; i < extraSigma.size(); ++i) {
        if (!(extraSigma[i] > 0) || !std::isfinite(extraSigma[i]) ||
            (i > 0 && extraSigma[i] > extraSigma[i - 1]))
            invalidState("learning state singular values must be positive and descending");
    }
    if (!extraBasis.allFinite()) invalidState("learning state basis contains NaN or Inf");
    if (!(discardedEnergy >= 0) || !std::isfinite(discardedEnergy))
        invalidState("learning state: bad discarded energy");
    if (updates < 0) invalidState("learning state: negative update count");
    if (maxKeys < 1 || maxKeys > points) invalidState("learning state: key budget outside [1, N]");
    if (block < 1) invalidState("learning state: block must be >= 1");
    if (!(maxError >= 0) || !std::isfinite(maxError)) invalidState("learning state: bad max error");
    if (!(basisEnergy >= 0 && basisEnergy <= 1)) invalidState("learning state: basis energy outside [0, 1]");
    for (const auto* list : {&fiducials, &gridPoints})
        for (Index p : *list)
            if (p < 0 || p >= points)
                invalidState("learning state: seeded point " + std::to_string(p) + " outside [0, N)");
}

CalibrationRecord CalibrationRecord::from(const CalibrationStats& s) {
    CalibrationRecord r;
    r.rule = s.rule;
    r.coverage = s.coverage;
    r.slices = s.slices;
    // A predicted error's scores are kept as its raw parts, which `pmsc learn` calibrates anew.
    r.keyRms = s.parts.empty() ? s.keyRms : s.parts[0].keyRms;
    if (s.parts.size() > 1) r.keyLoo = s.parts[1].keyRms;
    r.maxPointError = s.maxPointError;
    return r;
}

CalibrationStats CalibrationRecord::scores() const {
    CalibrationStats s;
    s.keyRms = keyRms;
    s.keyLoo = keyLoo;
    s.maxPointError = maxPointError;
    return s;
}

void CalibrationRecord::append(const CalibrationStats& raw) {
    const auto add = [](std::vector<double>& to, const std::vector<double>& from) {
        to.insert(to.end(), from.begin(), from.end());
    };
    add(keyRms, raw.keyRms);
    add(keyLoo, raw.keyLoo);
    add(maxPointError, raw.maxPointError);
}

void CalibrationRecord::validate() const {
    if (rule != CalibrationRule::MaxRatio && rule != CalibrationRule::Conformal &&
        rule != CalibrationRule::Threshold)
        invalidState("calibration record: unknown rule " + std::to_string(static_cast<int>(rule)));
    if (rule != CalibrationRule::MaxRatio && !(coverage > 0 && coverage < 1))
        invalidState("calibration record: coverage must be in (0, 1)");
    if (slices < 0) invalidState("calibration record: negative slice count");
    if (keyRms.size() != maxPointError.size() || (!keyLoo.empty() && keyLoo.size() != keyRms.size()))
        invalidState("calibration record: score arrays differ in length");
    for (size_t i = 0; i < keyLoo.size(); ++i)
        if (!(keyLoo[i] >= 0) || !std::isfinite(keyLoo[i]))
            invalidState("calibration record: leave-one-out score " + std::to_string(i) +
                         " is not a finite number >= 0");
    for (size_t i = 0; i < keyRms.size(); ++i)
        if (!(keyRms[i] >= 0) || !(maxPointError[i] >= 0) || !std::isfinite(keyRms[i]) ||
            !std::isfinite(maxPointError[i]))
            invalidState("calibration record: score " + std::to_string(i) + " is not a finite number >= 0");
}

}  // namespace pmsc
