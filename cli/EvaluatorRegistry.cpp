#include "cli/EvaluatorRegistry.h"

#include "examples/cornell/CornellEvaluator.h"
#include "examples/face/CrossDemo.h"
#include "examples/face/FaceEvaluator.h"
#include "examples/volume/VolumeEvaluator.h"

namespace pmsc::cli {

const evaluators::EvaluatorRegistry& evaluatorRegistry() {
    static const evaluators::EvaluatorRegistry registry = [] {
        using evaluators::requireArgs;
        auto r = evaluators::EvaluatorRegistry::withBuiltins();
        // The paper's demos, one row each; examples register theirs here.
        // clang-format off
        r.add({"cornell", "[points=N,samples=S,lights=all|training|scattered|path]", "section 8: indirect light in the Cornell box at the voxels of an OpenVDB lighting cache (writes .vdb)", [](const std::string& a) -> std::unique_ptr<PointEvaluator> { return cornell::makeCornellEvaluator(a); }});
        r.add({"face", "DIR", "section 7: the ICT face rig (DIR = ICT-FaceKit FaceXModel folder) posing its 44-sequence animation (writes .obj)", [](const std::string& a) -> std::unique_ptr<PointEvaluator> { return face::makeFaceEvaluator(requireArgs("face", "DIR", a)); }});
        r.add({"face-control", "DIR", "issue 10: the ICT face's control rig (blendshapes, jaw, eyelids, eyes; no relax, flesh, contact) over face:DIR's animation, for cross models", [](const std::string& a) -> std::unique_ptr<PointEvaluator> { return face::makeFaceControlEvaluator(requireArgs("face-control", "DIR", a)); }});
        r.add({"volume", "FILE.vdb[:grid=NAME][:samples=S][:lights=all|training|between|path]", "issue 11: light scattered at the active voxels of a density grid (writes .vdb)", [](const std::string& a) -> std::unique_ptr<PointEvaluator> { return volume::makeVolumeEvaluator(requireArgs("volume", "FILE.vdb", a)); }});
        // clang-format on
        return r;
    }();
    return registry;
}

const std::vector<EvaluatorKind>& evaluatorKinds() { return evaluatorRegistry().kinds(); }

std::unique_ptr<PointEvaluator> makeEvaluator(const std::string& spec) {
    return evaluatorRegistry().make(spec);
}

}  // namespace pmsc::cli
