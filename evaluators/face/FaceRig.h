// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/ColliderContact.h"
#include "evaluators/face/EyeAimDeformer.h"
#include "evaluators/face/EyelidDeformer.h"
#include "evaluators/face/FaceControls.h"
#include "evaluators/face/FleshDeformer.h"
#include "evaluators/face/IctFace.h"
#include "evaluators/face/JawDeformer.h"
#include "evaluators/face/LipContact.h"
#include "evaluators/face/MeshTopology.h"

#include <array>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

namespace pmsc::face {

/// The face's posing engine (paper section 7, figure 3: "the standard posing engine"): controls
/// in, posed vertex positions out, through a deformer network with real nonlinearities.
///
/// The network, in evaluation order:
///  1. blendshapes: the ICT expressions weighted by their controls, the residual correctives of
///     the jaw and blink expressions, the eyeLook shapes driven by the eyes' aim, and
///     combination correctives weighted by products of two controls;
///  2. jaw: linear blend skinning to a bone that rotates about its hinge (JawDeformer);
///  3. eyelids: rotation over the eyeballs (EyelidDeformer);
///  4. eyes: rigid rotation towards a gaze target (EyeAimDeformer);
///  5. relax: kRelaxIterations Jacobi sweeps of Laplacian smoothing of the displacement where the
///     skin shears between skull and jaw and between lid and brow; a vertex's result needs its
///     neighbours' previous sweep, so the relax reaches kRelaxIterations rings;
///  6. flesh: the facial muscles' elastic pull and bulge (FleshDeformer), weighted by a flesh
///     weight that is 1 on the skin and fades to 0 over kFleshFadeRings rings towards the mouth
///     box, whose lips are shaped by their scans and their contact;
///  7. contact, last so that nothing pushes a surface back through another: lip contact and
///     sticky lips (LipContact), then the eyelids against the turning eyeballs
///     (ColliderContact). Uneven cost; each reads the posed surface it touches (the opposite
///     lip has flesh weight 0, the eyeballs are rigid and do not relax, so the contacts read
///     relaxed positions and the closure stays small). Decision: no lips-against-teeth contact.
///     The same closest-triangle method would make inner-lip vertices pop
///     between the separate tooth meshes (the nearest triangle jumps across the gaps between
///     teeth, and its normal with it): 2% point errors no smooth subspace can follow. A smooth
///     proxy of the dental arch would be the way to add it.
///
/// Any subset of points is evaluated WITHOUT posing the others: the rig poses the dependency
/// closure of the subset (the contact's input triangles, then kRelaxIterations rings around
/// vertices that relax) and nothing else. A point's value is the same bit for bit whichever
/// other points are evaluated with it: every vertex runs the same code on the same inputs in a
/// fixed order (sorted neighbours, candidates in a fixed order).
///
/// Thread safety: all const methods may be called concurrently. Evaluation plans (closures) of
/// recently used subsets are cached under a mutex; the keys of a model are the same every frame.
class FaceRig {
public:
    static constexpr int kRelaxIterations = 2;
    static constexpr double kRelaxStrength = 0.5;  ///< step of each Jacobi sweep at the band's middle
    static constexpr int kFleshFadeRings = 4;

    /// One combination corrective: weight = controls[a] x controls[b].
    struct Combination {
        int a;
        int b;
    };
    /// The combination correctives of the rig (pairs that fire together in speech and emotion).
    static const std::vector<Combination>& combinations();

    /// Per-pose state computed once per frame from the controls.
    struct Pose {
        std::vector<double> channelWeights;  ///< one per blendshape channel
        RigidTransform jaw;
        std::array<double, 2> blink{};
        EyeAimDeformer::Aim aim;
        double lipStick = 0;
        FleshDeformer::Pose flesh;
    };

    /// Builds the rig from the ICT face (the face is not referenced afterwards).
    explicit FaceRig(const IctFace& face);
    ~FaceRig();
    FaceRig(const FaceRig&) = delete;
    FaceRig& operator=(const FaceRig&) = delete;

    Index pointCount() const { return static_cast<Index>(rest_.size() / 3); }
    Pose prepare(const ControlVector& controls) const;
    /// prepare() up to the stages the control rig uses (channel weights, eye aim, jaw, blink):
    /// no lip stick, no flesh pose.
    Pose prepareControl(const ControlVector& controls) const;

    /// Poses `points` (any order, no duplicates needed) into out[3*i + c].
    /// @throws std::out_of_range for a point outside [0, N).
    void evaluate(const ControlVector& controls, std::span<const Index> points, double* out) const;
    /// Poses all N points into out (3N doubles).
    void evaluateAll(const ControlVector& controls, double* out) const;
    /// The control face of cross point multiplication (paper section 7): the rig
    /// without its expensive stages, i.e. stages 1-4 only (blendshapes, jaw, eyelids, eyes; no
    /// relax, flesh or contact). Per point, no closure: any subset costs only its own points.
    void evaluateControl(const ControlVector& controls, std::span<const Index> points, double* out) const;

    /// How many vertices pass through each stage when posing `points`: the dependency closure.
    struct ClosureSize {
        Index blendshapes = 0;  ///< stages 1-4
        Index relax = 0;        ///< vertices whose relaxed value is needed (last sweep)
        Index contact = 0;      ///< contact evaluations (lips, lids)
    };
    ClosureSize closureSize(std::span<const Index> points) const;

    // --- parts, for tests, the demo and renderers ---
    const MeshTopology& topology() const { return topology_; }
    const std::vector<double>& restPositions() const { return rest_; }
    const JawDeformer& jaw() const { return jaw_; }
    const EyelidDeformer& eyelids() const { return eyelids_; }
    const EyeAimDeformer& eyes() const { return eyes_; }
    const LipContact& lipContact() const { return contact_; }
    const ColliderContact& lidContact() const { return *lidContact_; }
    const FleshDeformer& flesh() const { return flesh_; }
    double fleshWeight(Index v) const { return fleshWeight_[static_cast<size_t>(v)]; }
    double relaxWeight(Index v) const { return relax_[static_cast<size_t>(v)]; }
    Index channelCount() const { return static_cast<Index>(channelNames_.size()); }
    const std::string& channelName(Index ch) const { return channelNames_[static_cast<size_t>(ch)]; }
    /// Stored blendshape entries (vertex, channel) with a non-zero delta.
    Index blendshapeEntries() const { return static_cast<Index>(entries_.size()); }

private:
    struct Plan;
    struct Entry {
        std::int32_t channel;
        double delta[3];
    };
    std::shared_ptr<const Plan> planFor(std::span<const Index> points) const;
    std::shared_ptr<const Plan> buildPlan(std::span<const Index> points) const;
    void run(const Plan& plan, const Pose& pose, std::span<const Index> points, double* out) const;
    Eigen::Vector3d stageA(Index v, const Pose& pose) const;

    std::vector<double> rest_;
    MeshTopology topology_;
    JawDeformer jaw_;
    EyelidDeformer eyelids_;
    EyeAimDeformer eyes_;
    LipContact contact_;
    FleshDeformer flesh_;
    std::unique_ptr<ColliderContact> lidContact_;
    std::vector<double> relax_;
    std::vector<double> fleshWeight_;
    std::vector<std::string> channelNames_;
    std::vector<std::int32_t> entryStart_;
    std::vector<Entry> entries_;
    int lookChannel_ = 0;         // first of the 8 eyeLook channels
    int combinationChannel_ = 0;  // first combination corrective channel

    std::shared_ptr<const Plan> fullPlan_;
    mutable std::mutex cacheMutex_;
    mutable std::list<std::pair<std::vector<Index>, std::shared_ptr<const Plan>>> cache_;
};

}  // namespace pmsc::face
