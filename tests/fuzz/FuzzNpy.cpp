// libFuzzer target: the .npy frames reader (pmsc/NpyIO): header parser, length checks, values
// (readFrames, readFrameRange) and the memory-mapped reader (MappedFrames). The contract under
// test: any file either reads or throws pmsc::InputError; nothing else escapes, nothing crashes,
// and what reads is consistent with its header.
#include "FuzzInput.h"

#include "pmsc/Errors.h"
#include "pmsc/NpyIO.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <vector>

using namespace pmsc;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const fuzz::MemoryFile file(data, size);
    NpyInfo info;
    try {
        info = readNpyInfo(file.path());
    } catch (const InputError&) {
        return 0;
    }
    if (info.frames <= 0 || info.points <= 0 || info.channels <= 0) std::abort();
    bool finite = true;
    try {
        const FrameFile all = readFrames(file.path());
        if (all.frames.frames != info.frames || all.frames.points != info.points ||
            all.frames.channels != info.channels || all.dtype != info.dtype)
            std::abort();
        for (double v : all.frames.values)
            if (!std::isfinite(v)) std::abort();
    } catch (const InputError&) {
        finite = false;  // a NaN or Inf: every reader must refuse the file then
    }
    try {
        const FrameFile last = readFrameRange(file.path(), info.frames - 1, 1);
        if (last.frames.frames != 1) std::abort();
    } catch (const InputError&) {
    }
    try {
        const MappedFrames mapped(file.path());
        if (!finite) std::abort();
        // Room for a whole frame and for two points (a one-point file has less than two points).
        std::vector<double> frame(static_cast<std::size_t>(std::max<Index>(info.points, 2) * info.channels));
        mapped.readFrame(info.frames - 1, frame.data());
        const Index points[] = {0, info.points - 1};
        mapped.read(0, points, frame.data());
    } catch (const InputError&) {
        if (finite) std::abort();
    }
    return 0;
}
