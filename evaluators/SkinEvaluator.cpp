// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// The only translation unit that includes Assimp: everything the evaluator needs is copied out of
// the aiScene into plain arrays of doubles at load time, so posing never touches Assimp (whose
// scene is not documented as safe to read from many threads) and the header stays light.
#include "evaluators/SkinEvaluator.h"

#include "evaluators/exec/Isolated.h"
#include "pmsc/ByteIO.h"
#include "pmsc/Errors.h"
#include "pmsc/ObjIO.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <assimp/Importer.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <type_traits>
#include <unordered_map>

namespace pmsc::evaluators {

namespace {

using Affine = Eigen::Matrix<double, 3, 4>;  // [R | t], rows of a 4x4 whose last row is 0 0 0 1

Affine toAffine(const aiMatrix4x4& m) {
    Affine a;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) a(r, c) = m[r][c];
    return a;
}

Affine compose(const Affine& a, const Affine& b) {  // a * b as 4x4 matrices
    Affine r;
    r.leftCols<3>() = a.leftCols<3>() * b.leftCols<3>();
    r.col(3) = a.leftCols<3>() * b.col(3) + a.col(3);
    return r;
}

Affine inverseAffine(const Affine& a) {
    Affine inv;
    inv.leftCols<3>() = a.leftCols<3>().inverse();
    inv.col(3) = -inv.leftCols<3>() * a.col(3);
    return inv;
}

Affine identityAffine() {
    Affine a = Affine::Zero();
    a.leftCols<3>().setIdentity();
    return a;
}

// Assimp's messages can span lines; the command line promises one.
std::string oneLine(std::string s) {
    for (char& c : s)
        if (c == '\n' || c == '\r') c = ' ';
    while (!s.empty() && s.back() == ' ') s.pop_back();
    return s;
}

// The segment [k, k+1] of sorted key times holding t, and the fraction within it. Outside the keys
// the nearest key holds (fraction 0 on key 0 or the last key): Assimp's aiAnimBehaviour_DEFAULT
// would fall back to the node's stored transform instead, which makes a character jump to its bind
// pose before the first key; holding the key is what animation packages show.
struct Segment {
    std::size_t key = 0;
    double fraction = 0;
};

Segment findSegment(const std::vector<double>& times, double t) {
    if (times.size() < 2 || t <= times.front()) return {0, 0.0};
    if (t >= times.back()) return {times.size() - 1, 0.0};
    auto it = std::upper_bound(times.begin(), times.end(), t);
    std::size_t k = static_cast<std::size_t>(it - times.begin()) - 1;
    double span = times[k + 1] - times[k];
    return {k, span > 0 ? (t - times[k]) / span : 0.0};
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// The asset, reduced to what posing needs.

struct SkinEvaluator::Data {
    std::string path;
    std::string animationName;
    double fps = 24;
    double ticksPerSecond = 25;
    Index frames = 0;

    // Node hierarchy in depth-first pre-order, so a parent always precedes its children.
    std::vector<int> parent;
    std::vector<Affine> restLocal;
    std::vector<int> channelOfNode;  // -1: no channel, the node keeps restLocal
    // SkinOptions::rootSpace: the root joint (-1: scene space) and its rest global transform.
    int rootNode = -1;
    Affine rootRest = Affine::Zero();

    struct Channel {
        std::vector<double> positionTimes, rotationTimes, scalingTimes;
        std::vector<Eigen::Vector3d> positions, scalings;
        std::vector<Eigen::Quaterniond> rotations;
    };
    std::vector<Channel> channels;

    // Skinning palette: entry i is globalTransform(node) * offset. Rigid meshes and unweighted
    // vertices use an entry with an identity offset on their mesh's node.
    std::vector<int> paletteNode;
    std::vector<Affine> paletteOffset;

    // Per point: its influences (CSR), rest position.
    std::vector<Index> influenceStart;  // N + 1
    std::vector<std::int32_t> influenceSlot;
    std::vector<double> influenceWeight;
    std::vector<double> rest;  // N * 3

    // Morph targets per mesh: deltas (target - base), targets x vertices x 3.
    struct Morph {
        Index targets = 0;
        std::vector<double> deltas;
        std::vector<double> defaultWeights;
        // Animated weights: key times and dense weights (keys x targets); empty = defaults.
        std::vector<double> keyTimes;
        std::vector<double> keyWeights;
    };
    std::vector<Morph> morphs;  // one per mesh
    Index morphTargetCount = 0;
    Index bones = 0;

    std::vector<Index> meshOffsets;
    std::vector<std::int64_t> triangles;
    std::shared_ptr<const ObjMesh> topology;  // the triangles, for the .obj frame writer

    Index points() const { return static_cast<Index>(rest.size() / 3); }

    // Everything frame-dependent, computed the same way by every call.
    struct Pose {
        std::vector<Affine> palette;
        std::vector<std::vector<double>> morphWeights;  // per mesh
    };
    Pose pose(Index frame) const;
    void posePoint(const Pose& pose, Index point, double* out) const;

    struct Loader;  // load(), one named step per part of the scene

    /// Everything above as bytes, and back (the import in a child process).
    std::string pack() const;
    static std::unique_ptr<Data> unpack(std::string_view bytes, const std::string& where);
};

SkinEvaluator::Data::Pose SkinEvaluator::Data::pose(Index frame) const {
    const double ticks = static_cast<double>(frame) / fps * ticksPerSecond;

    std::vector<Affine> global(parent.size());
    for (std::size_t n = 0; n < parent.size(); ++n) {
        Affine local;
        if (channelOfNode[n] < 0) {
            local = restLocal[n];
        } else {
            const Channel& ch = channels[static_cast<std::size_t>(channelOfNode[n])];
            Segment sp = findSegment(ch.positionTimes, ticks);
            Eigen::Vector3d t = ch.positions[sp.key];
            if (sp.fraction > 0) t += sp.fraction * (ch.positions[sp.key + 1] - t);
            Segment sr = findSegment(ch.rotationTimes, ticks);
            Eigen::Quaterniond q = ch.rotations[sr.key];
            if (sr.fraction > 0) q = q.slerp(sr.fraction, ch.rotations[sr.key + 1]);
            q.normalize();
            Segment ss = findSegment(ch.scalingTimes, ticks);
            Eigen::Vector3d s = ch.scalings[ss.key];
            if (ss.fraction > 0) s += ss.fraction * (ch.scalings[ss.key + 1] - s);
            local.leftCols<3>() = q.toRotationMatrix() * s.asDiagonal();
            local.col(3) = t;
        }
        global[n] = parent[n] < 0 ? local : compose(global[static_cast<std::size_t>(parent[n])], local);
    }

    // Root space: every transform taken back by the root joint's motion from its rest place.
    Affine toRoot = identityAffine();
    if (rootNode >= 0) toRoot = compose(rootRest, inverseAffine(global[static_cast<std::size_t>(rootNode)]));
    Pose p;
    p.palette.resize(paletteNode.size());
    for (std::size_t i = 0; i < paletteNode.size(); ++i)
        p.palette[i] = paletteNode[i] < 0
                           ? paletteOffset[i]
                           : compose(toRoot, compose(global[static_cast<std::size_t>(paletteNode[i])],
                                                     paletteOffset[i]));

    p.morphWeights.resize(morphs.size());
    for (std::size_t m = 0; m < morphs.size(); ++m) {
        const Morph& mo = morphs[m];
        if (mo.targets == 0) continue;
        auto& w = p.morphWeights[m];
        if (mo.keyTimes.empty()) {
            w = mo.defaultWeights;
            continue;
        }
        Segment s = findSegment(mo.keyTimes, ticks);
        const std::size_t T = static_cast<std::size_t>(mo.targets);
        w.assign(mo.keyWeights.begin() + static_cast<std::ptrdiff_t>(s.key * T),
                 mo.keyWeights.begin() + static_cast<std::ptrdiff_t>((s.key + 1) * T));
        if (s.fraction > 0)
            for (std::size_t i = 0; i < T; ++i)
                w[i] += s.fraction * (mo.keyWeights[(s.key + 1) * T + i] - w[i]);
    }
    return p;
}

void SkinEvaluator::Data::posePoint(const Pose& pose, Index point, double* out) const {
    // Which mesh: the last offset <= point.
    auto it = std::upper_bound(meshOffsets.begin(), meshOffsets.end(), point);
    const std::size_t mesh = static_cast<std::size_t>(it - meshOffsets.begin()) - 1;

    Eigen::Vector3d v(rest[3 * point], rest[3 * point + 1], rest[3 * point + 2]);
    const Morph& mo = morphs[mesh];
    if (mo.targets > 0) {
        const Index local = point - meshOffsets[mesh];
        const Index vertices = meshOffsets[mesh + 1] - meshOffsets[mesh];
        const auto& w = pose.morphWeights[mesh];
        for (Index i = 0; i < mo.targets; ++i) {
            const double wi = w[static_cast<std::size_t>(i)];
            if (wi == 0) continue;
            const double* d = &mo.deltas[static_cast<std::size_t>(3 * (i * vertices + local))];
            v += wi * Eigen::Vector3d(d[0], d[1], d[2]);
        }
    }

    Eigen::Vector3d r = Eigen::Vector3d::Zero();
    for (Index k = influenceStart[point]; k < influenceStart[point + 1]; ++k) {
        const Affine& m = pose.palette[static_cast<std::size_t>(influenceSlot[k])];
        r += influenceWeight[k] * (m.leftCols<3>() * v + m.col(3));
    }
    out[0] = r.x();
    out[1] = r.y();
    out[2] = r.z();
}

// ------------------------------------------------------------------------------------------------
// Loading.

namespace {

bool isIndex(const std::string& s) {
    return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

}  // namespace

SkinOptions parseSkinArgs(const std::string& args) {
    SkinOptions o;
    std::string rest = args;
    for (;;) {
        auto colon = rest.rfind(':');
        if (colon == std::string::npos) break;
        std::string opt = rest.substr(colon + 1);
        if (opt.rfind("fps=", 0) == 0) {
            std::string v = opt.substr(4);
            double fps = 0;
            auto [p, ec] = std::from_chars(v.data(), v.data() + v.size(), fps);
            if (ec != std::errc() || p != v.data() + v.size() || !(fps > 0) || !std::isfinite(fps))
                throw InputError("skin: fps must be a positive number, got '" + v + "'");
            o.fps = fps;
        } else if (opt.rfind("animation=", 0) == 0) {
            o.animation = opt.substr(10);
            if (o.animation.empty()) throw InputError("skin: animation= needs a name or an index");
        } else if (opt.rfind("body=", 0) == 0) {
            const std::string v = opt.substr(5);
            if (v != "tubes" && v != "asset")
                throw InputError("skin: body must be tubes or asset, got '" + v + "'");
            o.tubes = v == "tubes";
        } else if (opt.rfind("space=", 0) == 0) {
            const std::string v = opt.substr(6);
            if (v != "root" && v != "scene")
                throw InputError("skin: space must be root or scene, got '" + v + "'");
            o.rootSpace = v == "root";
        } else if (opt.rfind("isolate=", 0) == 0) {
            const std::string v = opt.substr(8);
            if (v != "yes" && v != "no") throw InputError("skin: isolate must be yes or no, got '" + v + "'");
            o.isolate = v == "yes";
        } else if (opt.find('=') != std::string::npos && opt.find('/') == std::string::npos) {
            throw InputError(
                "skin: unknown option '" + opt +
                "' (expected fps=F, animation=NAME|INDEX, isolate=yes|no, body=tubes or space=root)");
        } else {
            break;  // part of the path
        }
        rest.resize(colon);
    }
    if (rest.empty())
        throw InputError(
            "skin: no asset given (expected "
            "skin:ASSET[:fps=F][:animation=A][:isolate=yes|no][:body=tubes][:space=root])");
    o.path = rest;
    return o;
}

// Reads an Assimp scene into Data in named steps; the scene is only read here.
struct SkinEvaluator::Data::Loader {
    Loader(const aiScene& s, Data& data, std::string w) : scene(s), d(data), where(std::move(w)) {}

    const aiScene& scene;
    Data& d;
    const std::string where;  // "skin: PATH: ", the start of every message
    const aiAnimation* anim = nullptr;
    // The scene's nodes in depth-first pre-order (Data's node numbers), by name and per mesh.
    std::vector<const aiNode*> nodes;
    std::unordered_map<std::string, int> nodeByName;
    std::vector<int> firstNodeOfMesh;
    std::unordered_map<int, std::int32_t> rigidSlotOfNode;

    void pickAnimation(const std::string& wanted);
    void flattenNodes();
    void readNodeChannels();
    void readMeshes();
    void dressSkeleton();
    void findRootJoint();
    void readInfluences(const aiMesh& mesh, unsigned meshIndex);
    void readFaces(const aiMesh& mesh, Index offset);
    void readMorphTargets(const aiMesh& mesh, unsigned meshIndex);
    void readMorphChannels();
    void checkKeyOrder() const;
    std::int32_t rigidSlot(int node);
};

namespace {

/// Assimp's scene of `path`, triangulated for the .obj faces (it keeps the vertex arrays); nothing
/// that merges, splits or reorders vertices, so points are the vertices as the importer delivers
/// them. @throws InputError with Assimp's message.
const aiScene& importScene(Assimp::Importer& importer, const std::string& path, const std::string& where,
                           bool tubes) {
    const aiScene* scene = importer.ReadFile(path, aiProcess_Triangulate | aiProcess_ValidateDataStructure);
    if (scene && scene->mNumMeshes == 0) {  // Assimp flags such a scene incomplete, without a message
        if (!tubes)
            throw InputError(
                where + "has no vertices (no mesh in the scene; :body=tubes dresses a skeleton in tubes)");
        if (!scene->mRootNode) throw InputError(where + "has neither a mesh nor a skeleton");
        return *scene;
    }
    if (!scene || !scene->mRootNode || (scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE)) {
        std::string why = oneLine(importer.GetErrorString());
        throw InputError(where + "Assimp cannot read it: " + (why.empty() ? "incomplete scene" : why));
    }
    return *scene;
}

}  // namespace

void SkinEvaluator::Data::Loader::pickAnimation(const std::string& wanted) {
    if (scene.mNumAnimations == 0) throw InputError(where + "has no animation to pose");
    if (wanted.empty()) {
        anim = scene.mAnimations[0];
    } else if (isIndex(wanted)) {
        unsigned long i = std::stoul(wanted);
        if (i >= scene.mNumAnimations)
            throw InputError(where + "animation " + wanted + " requested, it has " +
                             std::to_string(scene.mNumAnimations));
        anim = scene.mAnimations[i];
    } else {
        for (unsigned i = 0; i < scene.mNumAnimations; ++i)
            if (wanted == scene.mAnimations[i]->mName.C_Str()) anim = scene.mAnimations[i];
        if (!anim) throw InputError(where + "has no animation named '" + wanted + "'");
    }
    d.animationName = anim->mName.C_Str();
    d.ticksPerSecond = anim->mTicksPerSecond > 0 ? anim->mTicksPerSecond : 25.0;
    const double seconds = std::max(0.0, anim->mDuration) / d.ticksPerSecond;
    d.frames = static_cast<Index>(std::floor(seconds * d.fps + 1e-9)) + 1;
}

void SkinEvaluator::Data::Loader::flattenNodes() {
    firstNodeOfMesh.assign(scene.mNumMeshes, -1);
    std::vector<std::pair<const aiNode*, int>> stack{{scene.mRootNode, -1}};
    while (!stack.empty()) {
        auto [node, par] = stack.back();
        stack.pop_back();
        const int index = static_cast<int>(nodes.size());
        nodes.push_back(node);
        d.parent.push_back(par);
        d.restLocal.push_back(toAffine(node->mTransformation));
        nodeByName.emplace(node->mName.C_Str(), index);  // first of duplicate names wins
        for (unsigned m = 0; m < node->mNumMeshes; ++m)
            if (node->mMeshes[m] < scene.mNumMeshes && firstNodeOfMesh[node->mMeshes[m]] < 0)
                firstNodeOfMesh[node->mMeshes[m]] = index;
        for (unsigned c = node->mNumChildren; c-- > 0;) stack.push_back({node->mChildren[c], index});
    }
}

void SkinEvaluator::Data::Loader::readNodeChannels() {
    d.channelOfNode.assign(nodes.size(), -1);
    for (unsigned c = 0; c < anim->mNumChannels; ++c) {
        const aiNodeAnim* na = anim->mChannels[c];
        auto it = nodeByName.find(na->mNodeName.C_Str());
        if (it == nodeByName.end()) continue;  // animates nothing we pose
        // Components without keys keep the node's stored value.
        aiVector3D restS, restT;
        aiQuaternion restR;
        nodes[static_cast<std::size_t>(it->second)]->mTransformation.Decompose(restS, restR, restT);
        Channel ch;
        for (unsigned k = 0; k < na->mNumPositionKeys; ++k) {
            const auto& key = na->mPositionKeys[k];
            ch.positionTimes.push_back(key.mTime);
            ch.positions.emplace_back(key.mValue.x, key.mValue.y, key.mValue.z);
        }
        for (unsigned k = 0; k < na->mNumRotationKeys; ++k) {
            const auto& key = na->mRotationKeys[k];
            ch.rotationTimes.push_back(key.mTime);
            ch.rotations.emplace_back(key.mValue.w, key.mValue.x, key.mValue.y, key.mValue.z);
            ch.rotations.back().normalize();
        }
        for (unsigned k = 0; k < na->mNumScalingKeys; ++k) {
            const auto& key = na->mScalingKeys[k];
            ch.scalingTimes.push_back(key.mTime);
            ch.scalings.emplace_back(key.mValue.x, key.mValue.y, key.mValue.z);
        }
        if (ch.positions.empty()) {
            ch.positionTimes = {0.0};
            ch.positions = {Eigen::Vector3d(restT.x, restT.y, restT.z)};
        }
        if (ch.rotations.empty()) {
            ch.rotationTimes = {0.0};
            ch.rotations = {Eigen::Quaterniond(restR.w, restR.x, restR.y, restR.z).normalized()};
        }
        if (ch.scalings.empty()) {
            ch.scalingTimes = {0.0};
            ch.scalings = {Eigen::Vector3d(restS.x, restS.y, restS.z)};
        }
        d.channelOfNode[static_cast<std::size_t>(it->second)] = static_cast<int>(d.channels.size());
        d.channels.push_back(std::move(ch));
    }
}

std::int32_t SkinEvaluator::Data::Loader::rigidSlot(int node) {
    auto [it, added] = rigidSlotOfNode.emplace(node, static_cast<std::int32_t>(d.paletteNode.size()));
    if (added) {
        d.paletteNode.push_back(node);
        d.paletteOffset.push_back(identityAffine());
    }
    return it->second;
}

void SkinEvaluator::Data::Loader::readMeshes() {
    Index total = 0;
    for (unsigned m = 0; m < scene.mNumMeshes; ++m) total += scene.mMeshes[m]->mNumVertices;
    if (total == 0) throw InputError(where + "has no vertices");
    d.rest.reserve(static_cast<std::size_t>(3 * total));
    d.influenceStart.reserve(static_cast<std::size_t>(total + 1));
    d.influenceStart.push_back(0);
    d.morphs.resize(scene.mNumMeshes);

    for (unsigned m = 0; m < scene.mNumMeshes; ++m) {
        const aiMesh& mesh = *scene.mMeshes[m];
        const Index offset = static_cast<Index>(d.rest.size() / 3);
        d.meshOffsets.push_back(offset);
        for (unsigned v = 0; v < mesh.mNumVertices; ++v) {
            d.rest.push_back(mesh.mVertices[v].x);
            d.rest.push_back(mesh.mVertices[v].y);
            d.rest.push_back(mesh.mVertices[v].z);
        }
        readInfluences(mesh, m);
        readFaces(mesh, offset);
        readMorphTargets(mesh, m);
    }
    d.meshOffsets.push_back(total);

    // A vertex of a mesh no node references was given slot -1: an identity entry (node -1).
    if (std::find(d.influenceSlot.begin(), d.influenceSlot.end(), -1) != d.influenceSlot.end()) {
        const auto identitySlot = static_cast<std::int32_t>(d.paletteNode.size());
        d.paletteNode.push_back(-1);
        d.paletteOffset.push_back(identityAffine());
        std::replace(d.influenceSlot.begin(), d.influenceSlot.end(), -1, identitySlot);
    }
}

void SkinEvaluator::Data::Loader::findRootJoint() {
    const auto it =
        std::find_if(d.channelOfNode.begin(), d.channelOfNode.end(), [](int c) { return c >= 0; });
    if (it == d.channelOfNode.end()) throw InputError(where + "space=root: no node is animated");
    d.rootNode = static_cast<int>(it - d.channelOfNode.begin());
    std::vector<Affine> global(static_cast<std::size_t>(d.rootNode) + 1);
    for (std::size_t i = 0; i < global.size(); ++i)
        global[i] = d.parent[i] < 0 ? d.restLocal[i]
                                    : compose(global[static_cast<std::size_t>(d.parent[i])], d.restLocal[i]);
    d.rootRest = global.back();
}

// The tube body of SkinOptions::tubes: built in the rest pose of the node
// transforms, every vertex skinned to the joints whose motion moves it.
void SkinEvaluator::Data::Loader::dressSkeleton() {
    constexpr int kRings = 8, kAround = 12;
    constexpr double kRadius = 0.15, kBlend = 0.25;
    const std::size_t n = d.parent.size();
    std::vector<Affine> global(n);
    for (std::size_t i = 0; i < n; ++i)
        global[i] = d.parent[i] < 0 ? d.restLocal[i]
                                    : compose(global[static_cast<std::size_t>(d.parent[i])], d.restLocal[i]);
    Eigen::Vector3d lo = global[0].col(3), hi = lo;
    for (const Affine& g : global) {
        lo = lo.cwiseMin(g.col(3));
        hi = hi.cwiseMax(g.col(3));
    }
    const double minLength = 1e-6 * std::max((hi - lo).norm(), 1e-300);

    std::unordered_map<int, std::int32_t> slotOfNode;
    auto slot = [&](int node) {
        auto [it, added] = slotOfNode.emplace(node, static_cast<std::int32_t>(d.paletteNode.size()));
        if (added) {
            d.paletteNode.push_back(node);
            d.paletteOffset.push_back(inverseAffine(global[static_cast<std::size_t>(node)]));
            ++d.bones;
        }
        return it->second;
    };

    d.influenceStart.assign(1, 0);
    for (std::size_t i = 0; i < n; ++i) {
        const int p = d.parent[i];
        if (p < 0) continue;
        const Eigen::Vector3d a = global[static_cast<std::size_t>(p)].col(3), b = global[i].col(3);
        const Eigen::Vector3d axis = b - a;
        const double length = axis.norm();
        if (!(length > minLength)) continue;
        // Two unit vectors across the bone.
        const Eigen::Vector3d dir = axis / length;
        const Eigen::Vector3d helper =
            std::abs(dir.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
        const Eigen::Vector3d u = dir.cross(helper).normalized(), v = dir.cross(u);
        const int grand = d.parent[static_cast<std::size_t>(p)];
        const auto first = static_cast<Index>(d.rest.size() / 3);
        for (int r = 0; r < kRings; ++r) {
            const double t = static_cast<double>(r) / (kRings - 1);
            // Weights: the bone's own joint, half and half with the neighbour at each end.
            std::vector<std::pair<std::int32_t, double>> w{{slot(p), 1.0}};
            if (t > 1 - kBlend) w.push_back({slot(static_cast<int>(i)), 0.5 * (t - (1 - kBlend)) / kBlend});
            if (t < kBlend && grand >= 0) w.push_back({slot(grand), 0.5 * (kBlend - t) / kBlend});
            double own = 1;
            for (std::size_t k = 1; k < w.size(); ++k) own -= w[k].second;
            w[0].second = own;
            for (int k = 0; k < kAround; ++k) {
                const double phi = 2 * std::numbers::pi * k / kAround;
                const Eigen::Vector3d x =
                    a + t * axis + kRadius * length * (std::cos(phi) * u + std::sin(phi) * v);
                d.rest.insert(d.rest.end(), {x.x(), x.y(), x.z()});
                for (const auto& [s, weight] : w) {
                    if (weight <= 0) continue;
                    d.influenceSlot.push_back(s);
                    d.influenceWeight.push_back(weight);
                }
                d.influenceStart.push_back(static_cast<Index>(d.influenceSlot.size()));
            }
        }
        for (int r = 0; r + 1 < kRings; ++r)
            for (int k = 0; k < kAround; ++k) {
                const Index v00 = first + r * kAround + k, v01 = first + r * kAround + (k + 1) % kAround;
                const Index v10 = v00 + kAround, v11 = v01 + kAround;
                d.triangles.insert(d.triangles.end(), {v00, v10, v11, v00, v11, v01});
            }
    }
    if (d.rest.empty())
        throw InputError(where + "has no bone to dress in tubes (every joint sits on its parent)");
    d.meshOffsets = {0, d.points()};
    d.morphs.resize(1);
}

void SkinEvaluator::Data::Loader::readInfluences(const aiMesh& mesh, unsigned meshIndex) {
    // Influences gathered per vertex, then normalized so weights sum to 1 (exporters round
    // weights; an unnormalized sum would scale the character away from its bones).
    std::vector<std::vector<std::pair<std::int32_t, double>>> inf(mesh.mNumVertices);
    for (unsigned b = 0; b < mesh.mNumBones; ++b) {
        const aiBone* bone = mesh.mBones[b];
        auto it = nodeByName.find(bone->mName.C_Str());
        if (it == nodeByName.end())
            throw InputError(where + "bone '" + bone->mName.C_Str() + "' has no node in the scene");
        const auto slot = static_cast<std::int32_t>(d.paletteNode.size());
        ++d.bones;
        d.paletteNode.push_back(it->second);
        d.paletteOffset.push_back(toAffine(bone->mOffsetMatrix));
        for (unsigned w = 0; w < bone->mNumWeights; ++w) {
            const aiVertexWeight& vw = bone->mWeights[w];
            if (vw.mVertexId >= mesh.mNumVertices)
                throw InputError(where + "bone '" + bone->mName.C_Str() + "' weights vertex " +
                                 std::to_string(vw.mVertexId) + " of a mesh with " +
                                 std::to_string(mesh.mNumVertices));
            if (vw.mWeight > 0) inf[vw.mVertexId].push_back({slot, vw.mWeight});
        }
    }
    const int meshNode = firstNodeOfMesh[meshIndex];
    for (auto& list : inf) {
        double sum = 0;
        for (auto& [slot, w] : list) sum += w;
        if (list.empty() || !(sum > 0)) {
            // Unskinned mesh, or a vertex no bone holds: rigid on the mesh's node (root space
            // when no node references the mesh).
            list.assign(1, {meshNode < 0 ? -1 : rigidSlot(meshNode), 1.0});
            sum = 1;
        }
        for (auto& [slot, w] : list) {
            d.influenceSlot.push_back(slot);
            d.influenceWeight.push_back(w / sum);
        }
        d.influenceStart.push_back(static_cast<Index>(d.influenceSlot.size()));
    }
}

void SkinEvaluator::Data::Loader::readFaces(const aiMesh& mesh, Index offset) {
    for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
        const aiFace& face = mesh.mFaces[f];
        for (unsigned k = 1; k + 1 < face.mNumIndices; ++k) {
            d.triangles.push_back(offset + face.mIndices[0]);
            d.triangles.push_back(offset + face.mIndices[k]);
            d.triangles.push_back(offset + face.mIndices[k + 1]);
        }
    }
}

void SkinEvaluator::Data::Loader::readMorphTargets(const aiMesh& mesh, unsigned meshIndex) {
    auto& mo = d.morphs[meshIndex];
    const Index nv = mesh.mNumVertices;
    mo.targets = mesh.mNumAnimMeshes;
    d.morphTargetCount += mo.targets;
    mo.deltas.assign(static_cast<std::size_t>(mo.targets * nv * 3), 0.0);
    for (unsigned t = 0; t < mesh.mNumAnimMeshes; ++t) {
        const aiAnimMesh* am = mesh.mAnimMeshes[t];
        mo.defaultWeights.push_back(am->mWeight);
        if (!am->mVertices) continue;  // a normals-only target moves no point
        if (am->mNumVertices != mesh.mNumVertices)
            throw InputError(where + "morph target " + std::to_string(t) + " has " +
                             std::to_string(am->mNumVertices) + " vertices, its mesh " +
                             std::to_string(mesh.mNumVertices));
        // Assimp stores targets as absolute positions (the glTF and FBX importers add the
        // displacement to the base); blending their differences from the base is the same
        // formula as glTF's relative targets and Assimp's normalized/vertex-blend methods.
        for (Index v = 0; v < nv; ++v)
            for (int c = 0; c < 3; ++c)
                mo.deltas[static_cast<std::size_t>(3 * (t * nv + v) + c)] =
                    static_cast<double>(am->mVertices[v][c]) - static_cast<double>(mesh.mVertices[v][c]);
    }
}

// Morph channels are named after the node that holds the mesh (glTF) or the mesh itself.
void SkinEvaluator::Data::Loader::readMorphChannels() {
    for (unsigned c = 0; c < anim->mNumMorphMeshChannels; ++c) {
        const aiMeshMorphAnim* ma = anim->mMorphMeshChannels[c];
        std::vector<unsigned> meshes;
        if (auto it = nodeByName.find(ma->mName.C_Str()); it != nodeByName.end()) {
            const aiNode* node = nodes[static_cast<std::size_t>(it->second)];
            meshes.assign(node->mMeshes, node->mMeshes + node->mNumMeshes);
        } else {
            for (unsigned m = 0; m < scene.mNumMeshes; ++m)
                if (ma->mName == scene.mMeshes[m]->mName) meshes.push_back(m);
        }
        for (unsigned m : meshes) {
            auto& mo = d.morphs[m];
            if (mo.targets == 0) continue;
            const auto T = static_cast<std::size_t>(mo.targets);
            mo.keyTimes.clear();
            mo.keyWeights.assign(T * ma->mNumKeys, 0.0);
            for (unsigned k = 0; k < ma->mNumKeys; ++k) {
                const aiMeshMorphKey& key = ma->mKeys[k];
                mo.keyTimes.push_back(key.mTime);
                for (unsigned i = 0; i < key.mNumValuesAndWeights; ++i) {
                    if (key.mValues[i] >= T)
                        throw InputError(where + "morph channel '" + ma->mName.C_Str() + "' names target " +
                                         std::to_string(key.mValues[i]) + " of a mesh with " +
                                         std::to_string(T));
                    mo.keyWeights[k * T + key.mValues[i]] = key.mWeights[i];
                }
            }
            if (!std::is_sorted(mo.keyTimes.begin(), mo.keyTimes.end()))
                throw InputError(where + "morph channel '" + ma->mName.C_Str() +
                                 "' keys are not in time order");
        }
    }
}

void SkinEvaluator::Data::Loader::checkKeyOrder() const {
    for (const auto& ch : d.channels)
        if (!std::is_sorted(ch.positionTimes.begin(), ch.positionTimes.end()) ||
            !std::is_sorted(ch.rotationTimes.begin(), ch.rotationTimes.end()) ||
            !std::is_sorted(ch.scalingTimes.begin(), ch.scalingTimes.end()))
            throw InputError(where + "animation keys are not in time order");
}

std::unique_ptr<SkinEvaluator::Data> SkinEvaluator::loadInProcess(const SkinOptions& options) {
    auto d = std::make_unique<SkinEvaluator::Data>();
    d->path = options.path;
    d->fps = options.fps;
    const std::string where = "skin: " + options.path + ": ";
    Assimp::Importer importer;  // owns the scene until the end of loading
    Data::Loader loader(importScene(importer, options.path, where, options.tubes), *d, where);
    loader.pickAnimation(options.animation);
    loader.flattenNodes();
    loader.readNodeChannels();
    if (options.rootSpace) loader.findRootJoint();
    if (options.tubes)
        loader.dressSkeleton();
    else
        loader.readMeshes();
    loader.readMorphChannels();
    loader.checkKeyOrder();
    d->topology = std::make_shared<const ObjMesh>(triangleMesh(d->triangles));
    return d;
}

// ------------------------------------------------------------------------------------------------
// The posing arrays as bytes, for an import in a child process. Only the child that just made them
// writes them, so the reader checks sizes (a child that died mid-write) and not meaning.

namespace {

class Packer {
public:
    explicit Packer(std::string& out) : w_(out), out_(out) {}
    void text(const std::string& s) {
        w_.u64(s.size());
        out_.append(s);
    }
    template <class T>
    void scalar(T v) {
        static_assert(std::is_trivially_copyable_v<T>);
        out_.append(reinterpret_cast<const char*>(&v), sizeof v);
    }
    /// Plain numbers, or Eigen fixed-size objects as their doubles.
    template <class T>
    void vec(const std::vector<T>& v) {
        w_.u64(v.size());
        for (const T& x : v) {
            if constexpr (std::is_arithmetic_v<T>) {
                scalar(x);
            } else if constexpr (std::is_same_v<T, Eigen::Quaterniond>) {
                w_.doubles(x.coeffs().data(), 4);
            } else {
                w_.doubles(x.data(), static_cast<std::size_t>(T::SizeAtCompileTime));
            }
        }
    }

private:
    ByteWriter w_;
    std::string& out_;
};

class Unpacker {
public:
    Unpacker(std::string_view bytes, const std::string& where) : r_(bytes, where + "the importer's answer") {}
    std::string text() {
        const auto n = r_.count("text", 1);
        return std::string(r_.take(n, "text"));
    }
    template <class T>
    T scalar() {
        T v;
        const auto bytes = r_.take(sizeof(T), "value");
        std::memcpy(&v, bytes.data(), sizeof(T));
        return v;
    }
    template <class T>
    void vec(std::vector<T>& v) {
        std::size_t size = sizeof(T);
        if constexpr (std::is_same_v<T, Eigen::Quaterniond>)
            size = 4 * sizeof(double);
        else if constexpr (!std::is_arithmetic_v<T>)
            size = T::SizeAtCompileTime * sizeof(double);
        v.resize(r_.count("array", size));
        for (T& x : v) {
            if constexpr (std::is_arithmetic_v<T>) {
                x = scalar<T>();
            } else if constexpr (std::is_same_v<T, Eigen::Quaterniond>) {
                r_.doubles(x.coeffs().data(), 4, "quaternion");
            } else {
                r_.doubles(x.data(), static_cast<std::uint64_t>(T::SizeAtCompileTime), "matrix");
            }
        }
    }
    std::uint64_t count(std::string_view what, std::uint64_t elementBytes) {
        return r_.count(what, elementBytes);
    }
    void finish() { r_.expectEnd(); }

private:
    ByteReader r_;
};

}  // namespace

std::string SkinEvaluator::Data::pack() const {
    std::string out;
    Packer p(out);
    p.text(path);
    p.text(animationName);
    p.scalar(fps);
    p.scalar(ticksPerSecond);
    p.scalar(frames);
    p.vec(parent);
    p.vec(restLocal);
    p.vec(channelOfNode);
    p.scalar(rootNode);
    p.vec(std::vector<Affine>{rootRest});
    p.scalar(static_cast<std::uint64_t>(channels.size()));
    for (const Channel& c : channels) {
        p.vec(c.positionTimes);
        p.vec(c.rotationTimes);
        p.vec(c.scalingTimes);
        p.vec(c.positions);
        p.vec(c.scalings);
        p.vec(c.rotations);
    }
    p.vec(paletteNode);
    p.vec(paletteOffset);
    p.vec(influenceStart);
    p.vec(influenceSlot);
    p.vec(influenceWeight);
    p.vec(rest);
    p.scalar(static_cast<std::uint64_t>(morphs.size()));
    for (const Morph& m : morphs) {
        p.scalar(m.targets);
        p.vec(m.deltas);
        p.vec(m.defaultWeights);
        p.vec(m.keyTimes);
        p.vec(m.keyWeights);
    }
    p.scalar(morphTargetCount);
    p.scalar(bones);
    p.vec(meshOffsets);
    p.vec(triangles);
    return out;
}

std::unique_ptr<SkinEvaluator::Data> SkinEvaluator::Data::unpack(std::string_view bytes,
                                                                 const std::string& where) {
    auto d = std::make_unique<Data>();
    Unpacker u(bytes, where);
    d->path = u.text();
    d->animationName = u.text();
    d->fps = u.scalar<double>();
    d->ticksPerSecond = u.scalar<double>();
    d->frames = u.scalar<Index>();
    u.vec(d->parent);
    u.vec(d->restLocal);
    u.vec(d->channelOfNode);
    d->rootNode = u.scalar<int>();
    std::vector<Affine> rootRest;
    u.vec(rootRest);
    if (rootRest.size() != 1 || d->rootNode < -1 || d->rootNode >= static_cast<int>(d->parent.size()))
        throw InputError(where + "the importer's answer has a bad root joint");
    d->rootRest = rootRest[0];
    d->channels.resize(u.count("channels", 6 * sizeof(std::uint64_t)));
    for (Channel& c : d->channels) {
        u.vec(c.positionTimes);
        u.vec(c.rotationTimes);
        u.vec(c.scalingTimes);
        u.vec(c.positions);
        u.vec(c.scalings);
        u.vec(c.rotations);
    }
    u.vec(d->paletteNode);
    u.vec(d->paletteOffset);
    u.vec(d->influenceStart);
    u.vec(d->influenceSlot);
    u.vec(d->influenceWeight);
    u.vec(d->rest);
    d->morphs.resize(u.count("morphs", sizeof(Index) + 4 * sizeof(std::uint64_t)));
    for (Morph& m : d->morphs) {
        m.targets = u.scalar<Index>();
        u.vec(m.deltas);
        u.vec(m.defaultWeights);
        u.vec(m.keyTimes);
        u.vec(m.keyWeights);
    }
    d->morphTargetCount = u.scalar<Index>();
    d->bones = u.scalar<Index>();
    u.vec(d->meshOffsets);
    u.vec(d->triangles);
    u.finish();
    d->topology = std::make_shared<const ObjMesh>(triangleMesh(d->triangles));
    return d;
}

std::unique_ptr<SkinEvaluator::Data> SkinEvaluator::load(const SkinOptions& options) {
    if (!options.isolate) return loadInProcess(options);
    const std::string where = "skin: " + options.path + ": ";
    exec::IsolationLimits limits;
    limits.timeout = std::chrono::milliseconds(static_cast<long long>(options.importTimeoutSeconds * 1000));
    const std::string bytes =
        exec::runIsolated([&] { return loadInProcess(options)->pack(); }, where, limits);
    return Data::unpack(bytes, where);
}

// ------------------------------------------------------------------------------------------------

SkinEvaluator::SkinEvaluator(const SkinOptions& options) : data_(load(options)) {}
SkinEvaluator::~SkinEvaluator() = default;

Index SkinEvaluator::pointCount() const { return data_->points(); }
Index SkinEvaluator::frameCount() const { return data_->frames; }
const std::vector<Index>& SkinEvaluator::meshOffsets() const { return data_->meshOffsets; }
const std::vector<std::int64_t>& SkinEvaluator::triangles() const { return data_->triangles; }
std::string SkinEvaluator::animationName() const { return data_->animationName; }
Index SkinEvaluator::boneCount() const { return data_->bones; }
Index SkinEvaluator::morphTargetCount() const { return data_->morphTargetCount; }
double SkinEvaluator::fps() const { return data_->fps; }

void SkinEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    const Data& d = *data_;
    if (frame < 0 || frame >= d.frames)
        throw std::out_of_range("skin: frame " + std::to_string(frame) + " outside 0.." +
                                std::to_string(d.frames - 1) + " of " + d.path);
    const Index n = d.points();
    for (Index p : points)
        if (p < 0 || p >= n)
            throw std::out_of_range("skin: point " + std::to_string(p) + " outside 0.." +
                                    std::to_string(n - 1));
    // The pose costs O(nodes + bones), independent of how many points are asked for, so a hit frame
    // that evaluates only the key points stays cheap.
    const Data::Pose pose = d.pose(frame);
    for (std::size_t i = 0; i < points.size(); ++i) d.posePoint(pose, points[i], out + 3 * i);
}

std::vector<std::shared_ptr<const FrameWriter>> SkinEvaluator::frameWriters() const {
    return {std::make_shared<ObjFrameWriter>(data_->points(), data_->topology)};
}

std::unique_ptr<SkinEvaluator> makeSkinEvaluator(const std::string& args) {
    return std::make_unique<SkinEvaluator>(parseSkinArgs(args));
}

}  // namespace pmsc::evaluators
