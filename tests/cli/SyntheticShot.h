// The small generated shot the command-line tests share.
#pragma once

#include "evaluators/synthetic/SyntheticSurface.h"
#include "pmsc/NpyIO.h"
#include "tests/common/TempDir.h"

#include <string>

namespace pmsc::test {

/// A 12 x 12 sheet: 240 training frames (seed 1), 60 test frames (seed 2) whose last 20 carry
/// motion training never saw; the test frames also as float32, and in memory.
struct SyntheticShot {
    TempDir inputs;
    std::string train = inputs.file("train.npy"), test = inputs.file("test.npy"),
                test32 = inputs.file("test32.npy");
    FrameSet recorded;  ///< the test frames
    SyntheticShot() {
        synthetic::SurfaceOptions o;
        o.grid = 12;
        o.frames = 240;
        o.seed = 1;
        writeFrames(train, evaluateFrames(synthetic::SyntheticSurface(o), 0, o.frames), NpyDtype::Float64);
        o.frames = 60;
        o.seed = 2;
        o.novelFrames = 20;
        recorded = evaluateFrames(synthetic::SyntheticSurface(o), 0, o.frames);
        writeFrames(test, recorded, NpyDtype::Float64);
        writeFrames(test32, recorded, NpyDtype::Float32);
    }
};

}  // namespace pmsc::test
