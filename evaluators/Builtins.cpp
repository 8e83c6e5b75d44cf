// The calculations pmsc ships, one row each: what `pmsc evaluators` lists and what the command
// line and Python accept as NAME[:ARGS].
#include "evaluators/EvaluatorRegistry.h"

#include "evaluators/ReplayEvaluator.h"
#include "evaluators/SkinEvaluator.h"
#include "evaluators/cornell/CornellEvaluator.h"
#include "evaluators/exec/ExecEvaluator.h"
#include "evaluators/face/FaceControlEvaluator.h"
#include "evaluators/face/FaceEvaluator.h"
#include "evaluators/synthetic/SyntheticSurface.h"
#include "evaluators/volume/VolumeEvaluator.h"

namespace pmsc::evaluators {

EvaluatorRegistry EvaluatorRegistry::withBuiltins() {
    using Made = std::unique_ptr<PointEvaluator>;
    EvaluatorRegistry r;
    r.add({"replay", "FILE.npy", "recorded frames (F, N, C) stand in for the calculation",
           [](const std::string& a) -> Made {
               return std::make_unique<ReplayEvaluator>(requireArgs("replay", "FILE.npy", a));
           }});
    r.add({"skin", "ASSET[:fps=F][:animation=A]",
           "an animated, skinned asset (glTF 2, FBX, Collada, X, BVH, ...) posed by linear blend skinning",
           [](const std::string& a) -> Made { return makeSkinEvaluator(requireArgs("skin", "ASSET", a)); }});
    r.add({"synthetic", "[grid=G][:frames=F][:seed=S][:novel=N]",
           "a procedural deforming surface (G x G points, 3 channels); novel=N ramps in motion no other take "
           "has",
           [](const std::string& a) -> Made { return synthetic::makeSyntheticSurface(a); }});
    r.add({"cornell", "[points=N,samples=S,lights=all|training|scattered|path|outside]",
           "indirect light in the measured Cornell box at the voxels of an OpenVDB lighting cache (paper "
           "section 8)",
           [](const std::string& a) -> Made { return cornell::makeCornellEvaluator(a); }});
    r.add({"face", "DIR",
           "the ICT face rig (DIR: an ICT-FaceKit FaceXModel folder) posing its animation (paper section 7)",
           [](const std::string& a) -> Made {
               return face::makeFaceEvaluator(requireArgs("face", "DIR", a));
           }});
    r.add({"face-control", "DIR",
           "the ICT face's control rig (blendshapes, jaw, eyelids, eyes) over face:DIR's animation, for "
           "cross models",
           [](const std::string& a) -> Made {
               return face::makeFaceControlEvaluator(requireArgs("face-control", "DIR", a));
           }});
    r.add({"volume", "FILE.vdb[:grid=NAME][:samples=S][:lights=all|training|between|path|outside]",
           "light scattered at the active voxels of any OpenVDB density grid",
           [](const std::string& a) -> Made {
               return volume::makeVolumeEvaluator(requireArgs("volume", "FILE.vdb", a));
           }});
    r.add({"exec", "[timeout=SECONDS:]COMMAND",
           "your own calculation in a child process that speaks the exec protocol (docs/exec-protocol.md)",
           [](const std::string& a) -> Made {
               return std::make_unique<exec::ExecEvaluator>(
                   exec::parseExecArgs(requireArgs("exec", "COMMAND", a)));
           }});
    return r;
}

const EvaluatorRegistry& builtinRegistry() {
    static const EvaluatorRegistry registry = EvaluatorRegistry::withBuiltins();
    return registry;
}

std::unique_ptr<PointEvaluator> makeEvaluator(const std::string& spec) {
    return builtinRegistry().make(spec);
}

}  // namespace pmsc::evaluators
