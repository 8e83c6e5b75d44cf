// pmsc_scaleout_frames: writes a synthetic training shot (examples/synthetic's deforming sheet) as
// a .npy frames file, frame by frame, so tests and benchmarks can make training sets larger than
// the memory they give `pmsc train` without holding them in memory either.
//
//   pmsc_scaleout_frames OUT.npy GRID FRAMES [SEED] [float32|float64] [nan=FRAME:POINT]
#include "evaluators/synthetic/SyntheticSurface.h"
#include "pmsc/NpyIO.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

int main(int argc, char** argv) {
    using namespace pmsc;
    if (argc < 4) {
        std::fprintf(stderr, "usage: %s OUT.npy GRID FRAMES [SEED] [float32|float64] [nan=FRAME:POINT]\n",
                     argv[0]);
        return 2;
    }
    synthetic::SurfaceOptions o;
    o.grid = std::stoll(argv[2]);
    o.frames = std::stoll(argv[3]);
    o.seed = argc > 4 ? static_cast<unsigned>(std::stoul(argv[4])) : 1u;
    const NpyDtype dtype =
        argc > 5 && std::string(argv[5]) == "float32" ? NpyDtype::Float32 : NpyDtype::Float64;
    Index nanFrame = -1, nanPoint = -1;
    if (argc > 6 && std::string(argv[6]).rfind("nan=", 0) == 0) {
        const std::string spec = std::string(argv[6]).substr(4);
        nanFrame = std::stoll(spec.substr(0, spec.find(':')));
        nanPoint = std::stoll(spec.substr(spec.find(':') + 1));
    }
    const synthetic::SyntheticSurface surface(o);
    const Index n = surface.pointCount();
    std::vector<Index> all(static_cast<std::size_t>(n));
    std::iota(all.begin(), all.end(), Index{0});
    std::vector<double> frame(static_cast<std::size_t>(n * 3));
    NpyFrameWriter writer(argv[1], o.frames, n, 3, dtype);
    for (Index f = 0; f < o.frames; ++f) {
        surface.evaluate(f, all, frame.data());
        if (f == nanFrame)
            frame[static_cast<std::size_t>(nanPoint * 3 + 1)] = std::numeric_limits<double>::quiet_NaN();
        writer.writeFrame(f, frame.data());
    }
    writer.commit();
    return 0;
}
