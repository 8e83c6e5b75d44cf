#include "evaluators/face/IctFace.h"

#include "pmsc/Errors.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pmsc::face {

const std::vector<std::string>& IctFace::expressionNames() {
    static const std::vector<std::string> names = {
        "browDown_L",      "browDown_R",      "browInnerUp_L",    "browInnerUp_R",    "browOuterUp_L",
        "browOuterUp_R",   "cheekPuff_L",     "cheekPuff_R",      "cheekRaiser_L",    "cheekRaiser_R",
        "cheekSquint_L",   "cheekSquint_R",   "eyeBlink_L",       "eyeBlink_R",       "eyeLookDown_L",
        "eyeLookDown_R",   "eyeLookIn_L",     "eyeLookIn_R",      "eyeLookOut_L",     "eyeLookOut_R",
        "eyeLookUp_L",     "eyeLookUp_R",     "eyeSquint_L",      "eyeSquint_R",      "eyeWide_L",
        "eyeWide_R",       "jawForward",      "jawLeft",          "jawOpen",          "jawRight",
        "mouthClose",      "mouthDimple_L",   "mouthDimple_R",    "mouthFrown_L",     "mouthFrown_R",
        "mouthFunnel",     "mouthLeft",       "mouthLowerDown_L", "mouthLowerDown_R", "mouthPress_L",
        "mouthPress_R",    "mouthPucker",     "mouthRight",       "mouthRollLower",   "mouthRollUpper",
        "mouthShrugLower", "mouthShrugUpper", "mouthSmile_L",     "mouthSmile_R",     "mouthStretch_L",
        "mouthStretch_R",  "mouthUpperUp_L",  "mouthUpperUp_R",   "noseSneer_L",      "noseSneer_R",
        "PupilDilate_L",   "PupilDilate_R",
    };
    return names;
}

const std::vector<VertexRegion>& IctFace::regions() {
    // Upstream README tables ("Face Model Topology", "Eyeball Details", "Teeth Details").
    // "left" is the character's left, the +x side (eyeBlink_L moves +x vertices).
    static const std::vector<VertexRegion> table = {
        {"face", 0, 9408},
        {"head_and_neck", 9409, 11247},
        {"mouth_socket", 11248, 13293},
        {"eye_socket_left", 13294, 13677},
        {"eye_socket_right", 13678, 14061},
        {"gums_and_tongue", 14062, 17038},
        {"teeth", 17039, 21450},
        {"teeth_upper", 17039, 19246},
        {"teeth_lower", 19247, 21450},
        {"eyeball_left", 21451, 23020},
        {"sclera_left", 21451, 22220},
        {"iris_left", 22221, 23020},
        {"eyeball_right", 23021, 24590},
        {"sclera_right", 23021, 23790},
        {"iris_right", 23791, 24590},
        {"lacrimal_left", 24591, 24794},
        {"lacrimal_right", 24795, 24998},
        {"eye_blend_left", 24999, 25022},
        {"eye_blend_right", 25023, 25046},
        {"eye_occlusion_left", 25047, 25198},
        {"eye_occlusion_right", 25199, 25350},
        {"eyelashes_left", 25351, 26034},
        {"eyelashes_right", 26035, 26718},
    };
    return table;
}

const VertexRegion& IctFace::region(std::string_view name) {
    for (const VertexRegion& r : regions()) {
        if (r.name == name) return r;
    }
    throw std::out_of_range("ICT face: no vertex region '" + std::string(name) + "'");
}

const std::array<Index, 68>& IctFace::multiPie68() {
    static const std::array<Index, 68> landmarks = {
        1225, 1888, 1052, 367,  1719, 1722, 2199, 1447, 966,  3661, 4390, 3927, 3924, 2608, 3272, 4088, 3443,
        268,  493,  1914, 2044, 1401, 3615, 4240, 4114, 2734, 2509, 978,  4527, 4942, 4857, 1140, 2075, 1147,
        4269, 3360, 1507, 1542, 1537, 1528, 1518, 1511, 3742, 3751, 3756, 3721, 3725, 3732, 5708, 5695, 2081,
        0,    4275, 6200, 6213, 6346, 6461, 5518, 5957, 5841, 5702, 5711, 5533, 6216, 6207, 6470, 5517, 5966,
    };
    return landmarks;
}

Index IctFace::expression(std::string_view name) const {
    const auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) throw std::out_of_range("ICT face: no expression '" + std::string(name) + "'");
    return static_cast<Index>(it - names.begin());
}

double IctFace::boundingBoxDiagonal() const {
    double lo[3] = {INFINITY, INFINITY, INFINITY};
    double hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (Index v = 0; v < vertexCount(); ++v) {
        for (int c = 0; c < 3; ++c) {
            lo[c] = std::min(lo[c], neutral.positions[3 * v + c]);
            hi[c] = std::max(hi[c], neutral.positions[3 * v + c]);
        }
    }
    return std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                     (hi[2] - lo[2]) * (hi[2] - lo[2]));
}

IctFace loadIctFace(const std::string& folder) {
    IctFace face;
    face.folder = folder;
    const std::string base = folder.empty() || folder.back() == '/' ? folder : folder + "/";
    const std::vector<std::string>& names = IctFace::expressionNames();

    const std::string neutralPath = base + "generic_neutral_mesh.obj";
    face.neutral = readObj(neutralPath, ObjContent::PositionsAndPolygons);
    const Index n = face.neutral.vertexCount();
    if (n != IctFace::kVertexCount) {
        throw InputError(neutralPath + ": " + std::to_string(n) +
                         " vertices, but the ICT face topology has " + std::to_string(IctFace::kVertexCount));
    }
    const Index polygons = face.neutral.polygonCount();

    face.names = names;
    face.deltas.resize(names.size());
    // Errors are collected per file and the first (in name order) rethrown, so the message does
    // not depend on which thread failed first.
    std::vector<std::string> errors(names.size());
    tbb::parallel_for(size_t{0}, names.size(), [&](size_t s) {
        const std::string path = base + names[s] + ".obj";
        try {
            Index faceLines = 0;
            ObjMesh mesh = readObj(path, ObjContent::Positions, &faceLines);
            if (mesh.vertexCount() != n) {
                throw InputError(path + ": " + std::to_string(mesh.vertexCount()) +
                                 " vertices, but the neutral mesh has " + std::to_string(n) +
                                 " (an expression must be the whole mesh in the same vertex order)");
            }
            if (faceLines != polygons) {
                throw InputError(path + ": " + std::to_string(faceLines) +
                                 " faces, but the neutral mesh has " + std::to_string(polygons) +
                                 " (not the same topology)");
            }
            std::vector<double>& delta = mesh.positions;
            for (size_t i = 0; i < delta.size(); ++i) delta[i] -= face.neutral.positions[i];
            face.deltas[s] = std::move(delta);
        } catch (const InputError& e) {
            errors[s] = e.what();
        }
    });
    for (const std::string& e : errors) {
        if (!e.empty()) throw InputError(e);
    }
    return face;
}

}  // namespace pmsc::face
