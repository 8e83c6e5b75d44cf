// CrossState (cross point multiplication) as the model file holds it: its checks and the
// "CROSSPM" section codec (format version 2, ModelSections.h):
//   u64 control points, f64 coverage, f64 quantile, f64 scale, u64 slices,
//   u64 n, f64 x n held-out key RMS, f64 x n held-out target errors.
// Apart from Cross.cpp (training, run-time multiplication) so that readers of model files (the
// fuzz targets among them) link without the training code.
#include "pmsc/ByteIO.h"
#include "pmsc/Cross.h"
#include "pmsc/Model.h"
#include "pmsc/ModelSections.h"

#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

namespace pmsc {

void CrossState::validate(Index points, const std::vector<Index>& keys) const {
    if (controlPoints < 1 || controlPoints >= points)
        throw std::invalid_argument("cross: control points " + std::to_string(controlPoints) +
                                    " must be in [1, " + std::to_string(points) +
                                    ") (the joint point count)");
    for (Index k : keys)
        if (k >= controlPoints)
            throw std::invalid_argument("cross: key point " + std::to_string(k) +
                                        " is not a control point (< " + std::to_string(controlPoints) + ")");
    if (!(coverage > 0 && coverage < 1)) throw std::invalid_argument("cross: coverage must be in (0, 1)");
    if (!(quantile >= 0) || !std::isfinite(quantile)) throw std::invalid_argument("cross: bad quantile");
    if (!(scale >= 0) || !std::isfinite(scale)) throw std::invalid_argument("cross: bad scale");
    if (keyRms.size() != targetError.size())
        throw std::invalid_argument("cross: held-out key RMS and target error counts differ");
    for (size_t i = 0; i < keyRms.size(); ++i)
        if (!(keyRms[i] >= 0) || !(targetError[i] >= 0) || !std::isfinite(keyRms[i]) ||
            !std::isfinite(targetError[i]))
            throw std::invalid_argument("cross: held-out score " + std::to_string(i) +
                                        " is not a finite number >= 0");
}

namespace {

bool crossPresent(const Model& model) { return model.cross.has_value(); }

void encodeCross(const Model& model, ByteWriter& out) {
    const CrossState& s = *model.cross;
    out.index(s.controlPoints);
    out.f64(s.coverage);
    out.f64(s.quantile);
    out.f64(s.scale);
    out.index(s.slices);
    out.index(static_cast<Index>(s.keyRms.size()));
    out.doubles(s.keyRms.data(), s.keyRms.size());
    out.doubles(s.targetError.data(), s.targetError.size());
}

void decodeCross(ByteReader& in, Model& model) {
    CrossState s;
    s.controlPoints = in.index("control points", static_cast<std::uint64_t>(model.points));
    s.coverage = in.finite("coverage");
    s.quantile = in.finite("quantile");
    s.scale = in.finite("scale");
    s.slices = in.index("slices", static_cast<std::uint64_t>(1) << 40);
    const std::uint64_t n = in.count("score count", 16);
    s.keyRms.resize(n);
    in.doubles(s.keyRms.data(), n, "key RMS scores");
    s.targetError.resize(n);
    in.doubles(s.targetError.data(), n, "target error scores");
    try {
        s.validate(model.points, model.keyPoints);
    } catch (const std::invalid_argument& e) {
        in.fail(e.what());
    }
    model.cross = std::move(s);
}

}  // namespace

ModelSectionCodec crossSectionCodec() {
    return {{'C', 'R', 'O', 'S', 'S', 'P', 'M', '\0'}, &crossPresent, &encodeCross, &decodeCross};
}

}  // namespace pmsc
