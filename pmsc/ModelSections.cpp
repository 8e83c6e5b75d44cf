#include "pmsc/ModelSections.h"

#include "pmsc/Cross.h"
#include "pmsc/LearningSections.h"
#include "pmsc/Regions.h"

#include <cstdio>

namespace pmsc {

std::span<const ModelSectionCodec> modelSectionCodecs() {
    // One line per feature. The order is the order of the sections in a written file.
    static const ModelSectionCodec codecs[] = {
        regionsSectionCodec(),
        learningSectionCodec(),     // LEARNSVD (`pmsc learn`)
        calibrationSectionCodec(),  // CALIBRAT (`pmsc learn`)
        crossSectionCodec(),        // CROSSPM (cross point multiplication)
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
