#include "evaluators/face/FaceControls.h"

#include <stdexcept>
#include <string>

namespace pmsc::face {
namespace {

constexpr std::array<std::string_view, kControlCount> kNames = {
    "browDown_L",       "browDown_R",      "browInnerUp_L",   "browInnerUp_R",  "browOuterUp_L",
    "browOuterUp_R",    "cheekPuff_L",     "cheekPuff_R",     "cheekRaiser_L",  "cheekRaiser_R",
    "cheekSquint_L",    "cheekSquint_R",   "eyeSquint_L",     "eyeSquint_R",    "eyeWide_L",
    "eyeWide_R",        "mouthClose",      "mouthDimple_L",   "mouthDimple_R",  "mouthFrown_L",
    "mouthFrown_R",     "mouthFunnel",     "mouthLeft",       "mouthRight",     "mouthLowerDown_L",
    "mouthLowerDown_R", "mouthPress_L",    "mouthPress_R",    "mouthPucker",    "mouthRollLower",
    "mouthRollUpper",   "mouthShrugLower", "mouthShrugUpper", "mouthSmile_L",   "mouthSmile_R",
    "mouthStretch_L",   "mouthStretch_R",  "mouthUpperUp_L",  "mouthUpperUp_R", "noseSneer_L",
    "noseSneer_R",      "PupilDilate_L",   "PupilDilate_R",   "jawOpen",        "jawLeft",
    "jawRight",         "jawForward",      "eyeBlink_L",      "eyeBlink_R",     "gazeYaw",
    "gazePitch",        "gazeDistance",    "lipStick",
};

}  // namespace

std::string_view controlName(int control) {
    if (control < 0 || control >= kControlCount)
        throw std::out_of_range("face rig: no control " + std::to_string(control));
    return kNames[static_cast<size_t>(control)];
}

int controlIndex(std::string_view name) {
    for (int c = 0; c < kControlCount; ++c) {
        if (kNames[static_cast<size_t>(c)] == name) return c;
    }
    throw std::out_of_range("face rig: no control '" + std::string(name) + "'");
}

ControlVector restPose() {
    ControlVector pose{};
    pose[GazeDistance] = 60.0;
    return pose;
}

}  // namespace pmsc::face
