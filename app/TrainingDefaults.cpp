#include "app/TrainingDefaults.h"

namespace pmsc::app {

TrainingOptions defaultTrainingOptions() {
    TrainingOptions options;
    options.regions.automatic = true;
    // Decision: regions learn from every 3rd frame. On the face's 941 training frames (159
    // regions) that took 23.5 s of CPU against 120 s from every frame, and the novel frames
    // evaluated 50.3% / 47.9% of the points against 52.0% / 51.2% (worst 0.48% of the diagonal
    // against 0.46%); every 4th frame saved 2 s more for a worst of 0.47%
    // (docs/local-fail-through.md, "Regions by default").
    options.regions.frameStride = 3;
    // Decision: every model can learn (TrainingOptions::learnable): a few kilobytes of settings
    // and held-out scores let `pmsc learn` grow M by the training's energy rule and calibrate
    // with the training's evidence.
    options.learnable = true;
    return options;
}

}  // namespace pmsc::app
