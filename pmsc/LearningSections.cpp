// The model-file sections of `pmsc learn` (format version 2, ModelSections.h):
//
// "LEARNSVD" (Model::learning, LearningState):
//   u64 maxRank, u64 updates, f64 discardedEnergy,
//   u64 E extra vectors, f64 x E singular values, f64 x (N*C*E) vectors (column-major),
//   u64 maxKeys, u64 block, f64 maxError,
//   u64 count + u64 x count fiducials, u64 count + u64 x count grid points,
//   f64 basisEnergy (optional: a section that ends before it reads as 0, M fixed)
// "CALIBRAT" (Model::calibrationRecord, CalibrationRecord):
//   u32 rule (0 max, 1 conformal, 2 threshold), u32 parts (0, or 1 when leave-one-out scores
//   follow), f64 coverage, u64 slices, u64 n, f64 x n key RMS, f64 x n largest point errors,
//   [f64 x n leave-one-out key errors (KeyErrorNorm::Predicted)]
#include "pmsc/LearningSections.h"

#include "pmsc/Model.h"
#include "pmsc/ModelSections.h"

#include <stdexcept>

namespace pmsc {

namespace {

bool learningPresent(const Model& model) { return model.learning.has_value(); }

void encodeLearning(const Model& model, ByteWriter& out) {
    const LearningState& s = *model.learning;
    out.index(s.maxRank);
    out.index(s.updates);
    out.f64(s.discardedEnergy);
    out.index(s.extraSigma.size());
    out.doubles(s.extraSigma.data(), static_cast<std::size_t>(s.extraSigma.size()));
    out.doubles(s.extraBasis.data(), static_cast<std::size_t>(s.extraBasis.size()));
    out.index(s.maxKeys);
    out.index(s.block);
    out.f64(s.maxError);
    out.index(static_cast<Index>(s.fiducials.size()));
    out.indices(s.fiducials);
    out.index(static_cast<Index>(s.gridPoints.size()));
    out.indices(s.gridPoints);
    out.f64(s.basisEnergy);
}

void decodeLearning(ByteReader& in, Model& model) {
    LearningState s;
    const Index rows = model.points * model.channels;
    const auto bound = static_cast<std::uint64_t>(1) << 40;
    s.maxRank = in.index("rank", bound);
    s.updates = in.index("update count", bound);
    s.discardedEnergy = in.finite("discarded energy");
    // Each extra vector costs 8 bytes of sigma and 8*N*C of basis: checked before allocating.
    const std::uint64_t extra = in.count("extra vector count", 8 * (static_cast<std::uint64_t>(rows) + 1));
    s.extraSigma.resize(static_cast<Index>(extra));
    in.doubles(s.extraSigma.data(), extra, "singular values");
    s.extraBasis.resize(rows, static_cast<Index>(extra));
    in.doubles(s.extraBasis.data(), extra * static_cast<std::uint64_t>(rows), "basis vectors");
    s.maxKeys = in.index("key budget", static_cast<std::uint64_t>(model.points) + 1);
    s.block = in.index("block", bound);
    s.maxError = in.finite("max error");
    const std::uint64_t fiducials = in.count("fiducial count", 8);
    s.fiducials = in.indices(fiducials, static_cast<std::uint64_t>(model.points), "fiducial");
    const std::uint64_t grid = in.count("grid point count", 8);
    s.gridPoints = in.indices(grid, static_cast<std::uint64_t>(model.points), "grid point");
    // Decision: the basis rule is the section's last field and optional, so model files written
    // without it still load (as "M fixed", what an update of them does).
    if (in.remaining() > 0) s.basisEnergy = in.finite("basis energy");
    try {
        s.validate(rows, model.basisSize(), model.points);
    } catch (const std::invalid_argument& e) {
        in.fail(e.what());
    }
    model.learning = std::move(s);
}

bool calibrationPresent(const Model& model) { return model.calibrationRecord.has_value(); }

void encodeCalibration(const Model& model, ByteWriter& out) {
    const CalibrationRecord& r = *model.calibrationRecord;
    out.u32(static_cast<std::uint32_t>(r.rule));
    out.u32(r.keyLoo.empty() ? 0 : 1);
    out.f64(r.coverage);
    out.index(r.slices);
    out.index(static_cast<Index>(r.keyRms.size()));
    out.doubles(r.keyRms.data(), r.keyRms.size());
    out.doubles(r.maxPointError.data(), r.maxPointError.size());
    out.doubles(r.keyLoo.data(), r.keyLoo.size());
}

void decodeCalibration(ByteReader& in, Model& model) {
    CalibrationRecord r;
    const std::uint32_t rule = in.u32("rule");
    if (rule > 2) in.fail("rule " + std::to_string(rule) + " is not 0 (max), 1 (conformal) or 2 (threshold)");
    r.rule = static_cast<CalibrationRule>(rule);
    const std::uint32_t looScores = in.u32("leave-one-out scores");
    if (looScores > 1) in.fail("leave-one-out score flag " + std::to_string(looScores) + " is not 0 or 1");
    r.coverage = in.finite("coverage");
    r.slices = in.index("slices", static_cast<std::uint64_t>(1) << 40);
    const std::uint64_t n = in.count("score count", 16);
    r.keyRms.resize(n);
    in.doubles(r.keyRms.data(), n, "key RMS scores");
    r.maxPointError.resize(n);
    in.doubles(r.maxPointError.data(), n, "point error scores");
    if (looScores == 1) {
        r.keyLoo.resize(n);
        in.doubles(r.keyLoo.data(), n, "leave-one-out scores");
    }
    try {
        r.validate();
    } catch (const std::invalid_argument& e) {
        in.fail(e.what());
    }
    model.calibrationRecord = std::move(r);
}

}  // namespace

ModelSectionCodec learningSectionCodec() {
    return {{'L', 'E', 'A', 'R', 'N', 'S', 'V', 'D'}, &learningPresent, &encodeLearning, &decodeLearning};
}

ModelSectionCodec calibrationSectionCodec() {
    return {{'C', 'A', 'L', 'I', 'B', 'R', 'A', 'T'},
            &calibrationPresent,
            &encodeCalibration,
            &decodeCalibration};
}

}  // namespace pmsc
