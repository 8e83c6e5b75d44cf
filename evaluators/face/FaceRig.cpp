#include "evaluators/face/FaceRig.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pmsc::face {
namespace {

// A blendshape delta smaller than this (model units, ~2e-8 of the head) is scan noise; storing
// it would only cost time.
constexpr double kDeltaThreshold = 1e-6;
// Plans of recently posed subsets. The engine's fail-through splits a frame into about 8 chunks
// per thread and reuses the same chunks every frame, as it reuses the keys: 32 plans (about
// 0.4 MB each, three vertex maps) keep them all on machines of up to 4 threads.
constexpr size_t kPlanCacheSize = 32;

// The combination corrective of two shapes that overlap: where both move a vertex the same way,
// their sum moves it too far (a sculptor's "double transformation"). The corrective pulls the
// sum back towards the longer of the two, in proportion to how aligned they are: at full
// alignment the pair moves the vertex by max(|a|, |b|) instead of |a| + |b|.
void combinationDelta(const double* a, const double* b, double* out) {
    const double la = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    const double lb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
    const double s[3] = {a[0] + b[0], a[1] + b[1], a[2] + b[2]};
    const double ls = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
    out[0] = out[1] = out[2] = 0;
    if (la == 0 || lb == 0 || ls == 0) return;
    const double cosine = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (la * lb);
    if (cosine <= 0) return;
    const double shrink = cosine * (std::max(la, lb) / ls - 1.0);
    for (int c = 0; c < 3; ++c) out[c] = shrink * s[c];
}

}  // namespace

struct FaceRig::Plan {
    std::vector<std::int32_t> setA, set1, set2;  // ascending global indices
    std::vector<std::int32_t> mapA, map1, map2;  // global -> local, -1 if absent
    Index contacts = 0;
};

const std::vector<FaceRig::Combination>& FaceRig::combinations() {
    static const std::vector<Combination> pairs = {
        {MouthSmileL, CheekSquintL},  {MouthSmileR, CheekSquintR},  {CheekSquintL, EyeSquintL},
        {CheekSquintR, EyeSquintR},   {BrowInnerUpL, BrowOuterUpL}, {BrowInnerUpR, BrowOuterUpR},
        {BrowDownL, NoseSneerL},      {BrowDownR, NoseSneerR},      {MouthPucker, MouthFunnel},
        {MouthFrownL, MouthStretchL}, {MouthFrownR, MouthStretchR}, {JawOpen, MouthSmileL},
        {JawOpen, MouthSmileR},       {JawOpen, MouthPucker},       {JawOpen, MouthFunnel},
        {JawOpen, MouthStretchL},     {JawOpen, MouthStretchR},
    };
    return pairs;
}

FaceRig::FaceRig(const IctFace& face)
    : rest_(face.neutral.positions),
      topology_(face.neutral),
      jaw_(face, topology_),
      eyelids_(face),
      eyes_(face, {eyelids_.centre(0), eyelids_.centre(1)}),
      contact_(face, topology_, jaw_.weights()),
      flesh_(face) {
    const Index n = face.vertexCount();

    // --- contact against rigid parts ---
    {
        auto mark = [&](std::initializer_list<const char*> regions) {
            std::vector<char> m(static_cast<size_t>(n), 0);
            for (const char* name : regions) {
                const VertexRegion& r = IctFace::region(name);
                for (Index v = r.first; v <= r.last; ++v) m[v] = 1;
            }
            return m;
        };
        lidContact_ = std::make_unique<ColliderContact>(
            "eyelids/eyeballs", rest_, topology_, mark({"face", "eye_socket_left", "eye_socket_right"}),
            mark({"sclera_left", "sclera_right"}),
            std::vector<Eigen::Vector3d>{eyelids_.centre(0), eyelids_.centre(1)});
    }

    // --- blendshape channels ---
    std::vector<const std::vector<double>*> channels;
    std::vector<std::vector<double>> derived;  // owned storage for combination correctives
    for (int c = 0; c < kShapeControlCount; ++c) {
        channels.push_back(&face.deltas[face.expression(controlName(c))]);
        channelNames_.emplace_back(controlName(c));
    }
    for (int k = 0; k < 4; ++k) {
        channels.push_back(&jaw_.residual(k));
        channelNames_.push_back(std::string(controlName(JawDeformer::kControls[k])) + " residual");
    }
    for (int e = 0; e < 2; ++e) {
        channels.push_back(&eyelids_.residual(e));
        channelNames_.push_back(std::string(controlName(e == 0 ? EyeBlinkL : EyeBlinkR)) + " residual");
    }
    lookChannel_ = static_cast<int>(channels.size());
    for (const char* name : EyeAimDeformer::kLookShapes) {
        channels.push_back(&face.deltas[face.expression(name)]);
        channelNames_.emplace_back(name);
    }
    combinationChannel_ = static_cast<int>(channels.size());
    derived.reserve(combinations().size());
    for (const Combination& pair : combinations()) {
        const std::vector<double>& a = face.deltas[face.expression(controlName(pair.a))];
        const std::vector<double>& b = face.deltas[face.expression(controlName(pair.b))];
        std::vector<double> d(static_cast<size_t>(3 * n));
        for (Index v = 0; v < n; ++v) combinationDelta(&a[3 * v], &b[3 * v], &d[3 * v]);
        derived.push_back(std::move(d));
        channels.push_back(&derived.back());
        channelNames_.push_back(std::string(controlName(pair.a)) + "*" + std::string(controlName(pair.b)));
    }
    // Vertex-major sparse storage: posing a vertex reads one contiguous run.
    entryStart_.assign(static_cast<size_t>(n) + 1, 0);
    for (Index v = 0; v < n; ++v) {
        for (size_t ch = 0; ch < channels.size(); ++ch) {
            const double* d = &(*channels[ch])[3 * v];
            if (std::abs(d[0]) > kDeltaThreshold || std::abs(d[1]) > kDeltaThreshold ||
                std::abs(d[2]) > kDeltaThreshold) {
                entries_.push_back({static_cast<std::int32_t>(ch), {d[0], d[1], d[2]}});
            }
        }
        entryStart_[v + 1] = static_cast<std::int32_t>(entries_.size());
    }

    // --- relax weights: the shear bands between skull and jaw, and between lid and brow ---
    relax_.assign(static_cast<size_t>(n), 0.0);
    std::array<double, 2> maxLidAngle{};
    for (Index v = 0; v < n; ++v) {
        const int e = eyelids_.eyeOf(v);
        if (e >= 0) maxLidAngle[e] = std::max(maxLidAngle[e], std::abs(eyelids_.angle(v)));
    }
    const VertexRegion& skin = IctFace::region("face");
    const VertexRegion& head = IctFace::region("head_and_neck");
    const VertexRegion& socket = IctFace::region("mouth_socket");
    for (Index v = 0; v < n; ++v) {
        if (!skin.contains(v) && !head.contains(v) && !socket.contains(v)) continue;
        if (topology_.neighbours(v).empty()) continue;
        const double w = jaw_.weight(v);
        double band = 4 * w * (1 - w);
        const int e = eyelids_.eyeOf(v);
        if (e >= 0 && maxLidAngle[e] > 0) {
            const double l = std::abs(eyelids_.angle(v)) / maxLidAngle[e];
            band = std::max(band, 4 * l * (1 - l));
        }
        const double lambda = kRelaxStrength * band;
        relax_[v] = lambda > 1e-3 ? lambda : 0.0;
    }

    // --- flesh weights: skin, fading to 0 towards the mouth box (rings counted on the mesh) ---
    fleshWeight_.assign(static_cast<size_t>(n), 0.0);
    {
        std::vector<int> ring(static_cast<size_t>(n), -1);
        std::vector<Index> frontier;
        for (Index v = 0; v < n; ++v) {
            if (contact_.inMouthBox(v)) {
                ring[v] = 0;
                frontier.push_back(v);
            }
        }
        for (int r = 1; r < kFleshFadeRings && !frontier.empty(); ++r) {
            std::vector<Index> next;
            for (Index v : frontier) {
                for (std::int32_t u : topology_.neighbours(v)) {
                    if (ring[u] < 0) {
                        ring[u] = r;
                        next.push_back(u);
                    }
                }
            }
            frontier = std::move(next);
        }
        for (Index v = 0; v < n; ++v) {
            if (!skin.contains(v) && !head.contains(v)) continue;
            fleshWeight_[v] = ring[v] < 0 ? 1.0 : static_cast<double>(ring[v]) / kFleshFadeRings;
        }
    }

    std::vector<Index> all(static_cast<size_t>(n));
    for (Index v = 0; v < n; ++v) all[v] = v;
    fullPlan_ = buildPlan(all);
}

FaceRig::~FaceRig() = default;

FaceRig::Pose FaceRig::prepareControl(const ControlVector& controls) const {
    Pose pose;
    pose.channelWeights.assign(channelNames_.size(), 0.0);
    for (int c = 0; c < kShapeControlCount; ++c) pose.channelWeights[c] = controls[c];
    for (int k = 0; k < 4; ++k)
        pose.channelWeights[kShapeControlCount + k] = controls[JawDeformer::kControls[k]];
    pose.channelWeights[kShapeControlCount + 4] = controls[EyeBlinkL];
    pose.channelWeights[kShapeControlCount + 5] = controls[EyeBlinkR];
    pose.aim = eyes_.aim(controls);
    for (int k = 0; k < 8; ++k) pose.channelWeights[lookChannel_ + k] = pose.aim.lookWeights[k];
    for (size_t k = 0; k < combinations().size(); ++k) {
        const Combination& pair = combinations()[k];
        pose.channelWeights[combinationChannel_ + k] = controls[pair.a] * controls[pair.b];
    }
    pose.jaw = jaw_.transform(controls);
    pose.blink = {controls[EyeBlinkL], controls[EyeBlinkR]};
    return pose;
}

FaceRig::Pose FaceRig::prepare(const ControlVector& controls) const {
    Pose pose = prepareControl(controls);
    pose.lipStick = controls[LipStick];
    pose.flesh = flesh_.prepare(controls, pose.jaw);
    return pose;
}

Eigen::Vector3d FaceRig::stageA(Index v, const Pose& pose) const {
    Eigen::Vector3d q(&rest_[3 * v]);
    const double* weights = pose.channelWeights.data();
    for (std::int32_t i = entryStart_[v]; i < entryStart_[v + 1]; ++i) {
        const Entry& e = entries_[static_cast<size_t>(i)];
        const double w = weights[e.channel];
        q[0] += w * e.delta[0];
        q[1] += w * e.delta[1];
        q[2] += w * e.delta[2];
    }
    q = jaw_.apply(v, q, pose.jaw);
    q = eyelids_.apply(v, q, pose.blink);
    q = eyes_.apply(v, q, pose.aim);
    return q;
}

std::shared_ptr<const FaceRig::Plan> FaceRig::buildPlan(std::span<const Index> points) const {
    const Index n = pointCount();
    std::vector<char> in2(static_cast<size_t>(n), 0), in1, inA;
    auto plan = std::make_shared<Plan>();
    for (Index p : points) {
        if (p < 0 || p >= n)
            throw std::out_of_range("face rig: point " + std::to_string(p) + " outside [0, " +
                                    std::to_string(n) + ")");
        in2[p] = 1;
        if (contact_.inZone(p)) {
            for (std::int32_t u : contact_.inputVertices(p)) in2[u] = 1;
        }
        if (lidContact_->inZone(p)) {
            for (std::int32_t u : lidContact_->inputVertices(p)) in2[u] = 1;
        }
    }
    // One relax sweep needs its input at the vertex and, where it relaxes, at its neighbours.
    auto widen = [&](const std::vector<char>& out) {
        std::vector<char> need = out;
        for (Index v = 0; v < n; ++v) {
            if (out[v] && relax_[v] > 0) {
                for (std::int32_t u : topology_.neighbours(v)) need[u] = 1;
            }
        }
        return need;
    };
    in1 = widen(in2);
    inA = widen(in1);
    auto list = [&](const std::vector<char>& mark, std::vector<std::int32_t>& set,
                    std::vector<std::int32_t>& map) {
        map.assign(static_cast<size_t>(n), -1);
        for (Index v = 0; v < n; ++v) {
            if (mark[v]) {
                map[v] = static_cast<std::int32_t>(set.size());
                set.push_back(static_cast<std::int32_t>(v));
            }
        }
    };
    list(in2, plan->set2, plan->map2);
    list(in1, plan->set1, plan->map1);
    list(inA, plan->setA, plan->mapA);
    for (Index p : points) {
        plan->contacts += (contact_.inZone(p) ? 1 : 0) + (lidContact_->inZone(p) ? 1 : 0);
    }
    return plan;
}

std::shared_ptr<const FaceRig::Plan> FaceRig::planFor(std::span<const Index> points) const {
    if (static_cast<Index>(points.size()) == pointCount()) {
        bool identity = true;
        for (size_t i = 0; i < points.size() && identity; ++i) identity = points[i] == static_cast<Index>(i);
        if (identity) return fullPlan_;
    }
    {
        std::lock_guard<std::mutex> lock(cacheMutex_);
        for (auto it = cache_.begin(); it != cache_.end(); ++it) {
            if (std::equal(it->first.begin(), it->first.end(), points.begin(), points.end())) {
                cache_.splice(cache_.begin(), cache_, it);
                return it->second;
            }
        }
    }
    std::shared_ptr<const Plan> plan = buildPlan(points);
    std::lock_guard<std::mutex> lock(cacheMutex_);
    cache_.emplace_front(std::vector<Index>(points.begin(), points.end()), plan);
    if (cache_.size() > kPlanCacheSize) cache_.pop_back();
    return plan;
}

void FaceRig::run(const Plan& plan, const Pose& pose, std::span<const Index> points, double* out) const {
    std::vector<double> a(3 * plan.setA.size());
    for (size_t i = 0; i < plan.setA.size(); ++i) {
        const Eigen::Vector3d q = stageA(plan.setA[i], pose);
        a[3 * i] = q[0];
        a[3 * i + 1] = q[1];
        a[3 * i + 2] = q[2];
    }
    // Jacobi sweep: each vertex reads only the previous sweep, so the order of vertices (and
    // which vertices are present) cannot change a result.
    auto sweep = [&](const std::vector<std::int32_t>& set, const std::vector<std::int32_t>& inMap,
                     const std::vector<double>& in, std::vector<double>& result) {
        result.resize(3 * set.size());
        for (size_t i = 0; i < set.size(); ++i) {
            const std::int32_t v = set[i];
            const double* x = &in[3 * static_cast<size_t>(inMap[v])];
            const double lambda = relax_[v];
            if (lambda == 0.0) {
                result[3 * i] = x[0];
                result[3 * i + 1] = x[1];
                result[3 * i + 2] = x[2];
                continue;
            }
            const auto nb = topology_.neighbours(v);
            double sum[3] = {0, 0, 0};
            for (std::int32_t u : nb) {
                const double* y = &in[3 * static_cast<size_t>(inMap[u])];
                for (int c = 0; c < 3; ++c) sum[c] += y[c] - rest_[3 * u + c];
            }
            const double inv = 1.0 / static_cast<double>(nb.size());
            for (int c = 0; c < 3; ++c) {
                const double d = x[c] - rest_[3 * v + c];
                result[3 * i + c] = x[c] + lambda * (sum[c] * inv - d);
            }
        }
    };
    std::vector<double> r1, r2;
    static_assert(kRelaxIterations == 2, "the plan holds one set per sweep");
    sweep(plan.set1, plan.mapA, a, r1);
    sweep(plan.set2, plan.map1, r1, r2);

    auto posed = [&](std::int32_t u) {
        const double* y = &r2[3 * static_cast<size_t>(plan.map2[u])];
        return Eigen::Vector3d(y[0], y[1], y[2]);
    };
    for (size_t i = 0; i < points.size(); ++i) {
        const Index p = points[i];
        Eigen::Vector3d x = posed(static_cast<std::int32_t>(p));
        const double flesh = fleshWeight_[static_cast<size_t>(p)];
        if (flesh > 0) x += flesh * flesh_.displacement(x, pose.flesh);
        // The contact's inputs lie in the mouth box, where the flesh weight is 0: their relaxed
        // positions are their final positions before contact.
        x = contact_.apply(p, x, pose.lipStick, posed);
        x = lidContact_->apply(p, x, posed);
        out[3 * i] = x[0];
        out[3 * i + 1] = x[1];
        out[3 * i + 2] = x[2];
    }
}

void FaceRig::evaluate(const ControlVector& controls, std::span<const Index> points, double* out) const {
    if (points.empty()) return;
    const std::shared_ptr<const Plan> plan = planFor(points);
    run(*plan, prepare(controls), points, out);
}

void FaceRig::evaluateAll(const ControlVector& controls, double* out) const {
    std::vector<Index> all(static_cast<size_t>(pointCount()));
    for (Index v = 0; v < pointCount(); ++v) all[v] = v;
    run(*fullPlan_, prepare(controls), all, out);
}

void FaceRig::evaluateControl(const ControlVector& controls, std::span<const Index> points,
                              double* out) const {
    const Pose pose = prepareControl(controls);  // the control does not use the flesh's pose
    const Index n = pointCount();
    for (size_t i = 0; i < points.size(); ++i) {
        const Index p = points[i];
        if (p < 0 || p >= n)
            throw std::out_of_range("face rig: point " + std::to_string(p) + " outside [0, " +
                                    std::to_string(n) + ")");
        const Eigen::Vector3d q = stageA(p, pose);
        out[3 * i] = q[0];
        out[3 * i + 1] = q[1];
        out[3 * i + 2] = q[2];
    }
}

FaceRig::ClosureSize FaceRig::closureSize(std::span<const Index> points) const {
    const std::shared_ptr<const Plan> plan = buildPlan(points);
    return {static_cast<Index>(plan->setA.size()), static_cast<Index>(plan->set2.size()), plan->contacts};
}

}  // namespace pmsc::face
