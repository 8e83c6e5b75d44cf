#include "pmsc/ModelSections.h"

#include "pmsc/Cross.h"
#include "pmsc/KeyNeighbours.h"
#include "pmsc/LearningSections.h"
#include "pmsc/Model.h"
#include "pmsc/Regions.h"
#include "pmsc/Sentinels.h"

#include <cstdio>

namespace pmsc {

namespace {

// KEYERROR: the key error norm eps applies to (Model::keyErrorNorm), one u32; for 3 (predicted)
// then f64 eps_rms, f64 eps_loo (Model::partEps). Absent = Rms, the measure of every model written
// without it.
ModelSectionCodec keyErrorSectionCodec() {
    return {{'K', 'E', 'Y', 'E', 'R', 'R', 'O', 'R'},
            [](const Model& m) { return m.keyErrorNorm != KeyErrorNorm::Rms; },
            [](const Model& m, ByteWriter& out) {
                out.u32(static_cast<std::uint32_t>(m.keyErrorNorm));
                if (m.keyErrorNorm == KeyErrorNorm::Predicted) {
                    out.f64(m.partEps.rms);
                    out.f64(m.partEps.loo);
                }
            },
            [](ByteReader& in, Model& m) {
                const std::uint32_t v = in.u32("key error norm");
                if (v > 3)
                    in.fail("key error norm " + std::to_string(v) +
                            " is not 0 (rms), 1 (largest), 2 (loo) or 3 (predicted)");
                m.keyErrorNorm = static_cast<KeyErrorNorm>(v);
                if (m.keyErrorNorm == KeyErrorNorm::Predicted) {
                    m.partEps.rms = in.finite("key RMS part threshold");
                    m.partEps.loo = in.finite("leave-one-out part threshold");
                }
            }};
}

// NONNEG: the model's output is clamped at 0 (Model::nonNegative), one u32 that is 1. Absent =
// no clamp, the reconstruction of every model written without it.
ModelSectionCodec nonNegativeSectionCodec() {
    return {{'N', 'O', 'N', 'N', 'E', 'G', '\0', '\0'},
            [](const Model& m) { return m.nonNegative; },
            [](const Model&, ByteWriter& out) { out.u32(1); },
            [](ByteReader& in, Model& m) {
                const std::uint32_t v = in.u32("non-negative flag");
                if (v != 1) in.fail("non-negative flag " + std::to_string(v) + " is not 1");
                m.nonNegative = true;
            }};
}

}  // namespace

std::span<const ModelSectionCodec> modelSectionCodecs() {
    // One line per feature. The order is the order of the sections in a written file.
    static const ModelSectionCodec codecs[] = {
        regionsSectionCodec(),
        learningSectionCodec(),            // LEARNSVD (`pmsc learn`)
        calibrationSectionCodec(),         // CALIBRAT (`pmsc learn`)
        crossSectionCodec(),               // CROSSPM (cross point multiplication)
        keyErrorSectionCodec(),            // KEYERROR (the largest key as the soft cache's measure)
        keyNeighboursSectionCodec(),       // KEYNEAR (where a hit one part certifies is checked)
        sentinelsSectionCodec(),           // SENTINEL (points computed beside every hit)
        sentinelNeighboursSectionCodec(),  // SENTNBRS (their neighbours: the slope check)
        nonNegativeSectionCodec(),         // NONNEG (the output clamped at 0)
    };
    return codecs;
}

std::string tagText(const char* tag) {
    std::string out;
    for (int i = 0; i < 8 && tag[i] != '\0'; ++i) {
        const auto c = static_cast<unsigned char>(tag[i]);
        if (c >= 0x20 && c < 0x7f) {
            out += static_cast<char>(c);
        } else {
            char hex[8];
            std::snprintf(hex, sizeof hex, "\\x%02x", c);
            out += hex;
        }
    }
    return out;
}

}  // namespace pmsc
