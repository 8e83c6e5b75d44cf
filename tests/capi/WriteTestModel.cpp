// Writes a small trained model for the C API's unit test (bad_inputs_c.c), through pmsc's C++ API,
// so the test needs neither the `pmsc` program nor recorded frames:
//   pmsc_capi_test_model MODEL.pmsc
// (its folder is created). 40 frames of 50 points x 3 channels, each a mix of 3 smooth patterns; M = 3, K
// = 6.
#include "pmsc/ModelIO.h"
#include "pmsc/Training.h"

#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: %s MODEL.pmsc\n", argv[0]);
        return 2;
    }
    try {
        const pmsc::Index frames = 40, points = 50, channels = 3;
        pmsc::FrameSet set(frames, points, channels);
        for (pmsc::Index f = 0; f < frames; ++f)
            for (pmsc::Index p = 0; p < points; ++p)
                for (pmsc::Index c = 0; c < channels; ++c) {
                    double v = 0;
                    for (int k = 0; k < 3; ++k)
                        v += std::cos(0.3 * double(f) * (k + 1) + k) *
                             std::sin(0.1 * (k + 1) * double(p) + double(c) + k);
                    set.frame(f)[p * channels + c] = v;
                }
        pmsc::TrainingOptions options;
        options.basis = 3;
        options.maxKeys = 6;
        const std::filesystem::path path(argv[1]);
        if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
        pmsc::writeModel(path.string(), pmsc::train(set, options));
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pmsc_capi_test_model: %s\n", e.what());
        return 1;
    }
    return 0;
}
