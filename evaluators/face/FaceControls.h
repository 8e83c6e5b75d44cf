// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <array>
#include <span>
#include <string_view>

namespace pmsc::face {

/// The face rig's animation controls (the paper's "animation variables", figure 2).
///
/// Most are named after the ICT/ARKit expression they drive. Five drive real nonlinear
/// deformers instead of a blendshape: the jaw (jawOpen, jawLeft, jawRight, jawForward rotate and
/// slide the jaw about its pivot), the eyelids (eyeBlink_L/R rotate the lids over the eyeballs),
/// the gaze (gazeYaw, gazePitch, gazeDistance place a target the eyes aim at; the eyeLook*
/// shapes follow the eyes), and lipStick (how strongly the lips stick together).
/// Values are in [0, 1] except gazeYaw/gazePitch (degrees) and gazeDistance (model units).
enum Control : int {
    BrowDownL,
    BrowDownR,
    BrowInnerUpL,
    BrowInnerUpR,
    BrowOuterUpL,
    BrowOuterUpR,
    CheekPuffL,
    CheekPuffR,
    CheekRaiserL,
    CheekRaiserR,
    CheekSquintL,
    CheekSquintR,
    EyeSquintL,
    EyeSquintR,
    EyeWideL,
    EyeWideR,
    MouthClose,
    MouthDimpleL,
    MouthDimpleR,
    MouthFrownL,
    MouthFrownR,
    MouthFunnel,
    MouthLeft,
    MouthRight,
    MouthLowerDownL,
    MouthLowerDownR,
    MouthPressL,
    MouthPressR,
    MouthPucker,
    MouthRollLower,
    MouthRollUpper,
    MouthShrugLower,
    MouthShrugUpper,
    MouthSmileL,
    MouthSmileR,
    MouthStretchL,
    MouthStretchR,
    MouthUpperUpL,
    MouthUpperUpR,
    NoseSneerL,
    NoseSneerR,
    PupilDilateL,
    PupilDilateR,
    // --- controls of nonlinear deformers ---
    JawOpen,
    JawLeft,
    JawRight,
    JawForward,
    EyeBlinkL,
    EyeBlinkR,
    GazeYaw,
    GazePitch,
    GazeDistance,
    LipStick,
    kControlCount
};

/// Number of controls that simply weight the ICT expression of the same name.
inline constexpr int kShapeControlCount = JawOpen;

/// A pose: one value per control.
using ControlVector = std::array<double, kControlCount>;

/// Control name ("jawOpen", "gazeYaw", ...): the ICT expression name for shape and jaw/blink
/// controls.
std::string_view controlName(int control);
/// Index of a control by name. @throws std::out_of_range naming it.
int controlIndex(std::string_view name);
/// The rest pose: every control 0 except gazeDistance (a target 60 units ahead).
ControlVector restPose();

}  // namespace pmsc::face
