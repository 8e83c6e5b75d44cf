#include "cli/EvaluatorRegistry.h"

#include "cli/ReplayEvaluator.h"
#include "examples/cornell/CornellEvaluator.h"
#include "examples/face/FaceEvaluator.h"
#include "examples/skin/SkinEvaluator.h"
#include "examples/volume/VolumeEvaluator.h"

#include <stdexcept>

namespace pmsc::cli {

namespace {

/// Fails for a kind that needs ARGS when none were given.
std::string requireArgs(const std::string& name, const std::string& what, const std::string& args) {
    if (args.empty())
        throw std::invalid_argument("evaluator '" + name + "' needs " + what + ": '" + name + ":" + what +
                                    "'");
    return args;
}

}  // namespace

const std::vector<EvaluatorKind>& evaluatorKinds() {
    // One row per evaluator kind, one line each; other layers register theirs here.
    // clang-format off
    static const std::vector<EvaluatorKind> kinds = {
        {"replay", "FILE.npy", "recorded frames (F, N, C) stand in for the calculation", [](const std::string& a) { return std::make_unique<ReplayEvaluator>(requireArgs("replay", "FILE.npy", a)); }},
        {"cornell", "[points=N,samples=S,lights=all|training|scattered|path]", "section 8: indirect light in the Cornell box at the voxels of an OpenVDB lighting cache (writes .vdb)", [](const std::string& a) -> std::unique_ptr<PointEvaluator> { return cornell::makeCornellEvaluator(a); }},
        {"skin", "ASSET[:fps=F][:animation=A]", "an animated, skinned asset (glTF 2, FBX, Collada, X, BVH, ...) posed by linear blend skinning", [](const std::string& a) -> std::unique_ptr<PointEvaluator> { return skin::makeSkinEvaluator(requireArgs("skin", "ASSET", a)); }},
        {"face", "DIR", "section 7: the ICT face rig (DIR = ICT-FaceKit FaceXModel folder) posing its 44-sequence animation (writes .obj)", [](const std::string& a) -> std::unique_ptr<PointEvaluator> { return face::makeFaceEvaluator(requireArgs("face", "DIR", a)); }},
        {"volume", "FILE.vdb[:grid=NAME][:samples=S][:lights=all|training|between|path]", "issue 11: light scattered at the active voxels of a density grid (writes .vdb)", [](const std::string& a) -> std::unique_ptr<PointEvaluator> { return volume::makeVolumeEvaluator(requireArgs("volume", "FILE.vdb", a)); }},
    };
    // clang-format on
    return kinds;
}

std::unique_ptr<PointEvaluator> makeEvaluator(const std::string& spec) {
    const auto colon = spec.find(':');
    const std::string name = spec.substr(0, colon);
    const std::string args = colon == std::string::npos ? std::string() : spec.substr(colon + 1);
    std::string known;
    for (const auto& kind : evaluatorKinds()) {
        if (kind.name == name) return kind.make(args);
        known += (known.empty() ? "" : ", ") + kind.name;
    }
    throw std::invalid_argument("unknown evaluator '" + name + "' (known: " + known + ")");
}

}  // namespace pmsc::cli
