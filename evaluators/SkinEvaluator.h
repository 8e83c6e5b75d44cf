// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameWriter.h"
#include "pmsc/PointEvaluator.h"

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace pmsc::evaluators {

/// How to pose an asset: which file, which animation, how frames map to time.
struct SkinOptions {
    std::string path;       ///< any format Assimp reads (glTF 2, FBX, Collada, X, BVH, ...)
    double fps = 24;        ///< frame f is posed at time f / fps seconds of the animation
    std::string animation;  ///< animation name or index; empty = the first one (index 0)
    /// Import the asset in a forked child process (exec::runIsolated), so an importer that
    /// crashes, hangs or asks for tens of GB on a damaged file fails with one InputError instead
    /// of taking the program down. The child sends back only the posing arrays.
    bool isolate = true;
    double importTimeoutSeconds = 600;  ///< isolated imports only
    /// Dress the asset's skeleton in a body of tubes, one around each bone, skinned to it and
    /// blended across each joint, in place of the asset's meshes: for motion capture (a BVH has
    /// joints and motion; Assimp gives it only a display mesh of one rigid pyramid per bone).
    /// Off by default: points a user did not model should be asked for. See SkinEvaluator.
    bool tubes = false;
    /// Pose in the frame of the root joint (the first animated node, depth-first), held at its
    /// rest place: the character's own motion without where it walks or turns, as a deformation
    /// cache stores it (the rig's world transform is one rigid motion applied after). Off by
    /// default (the scene's root space).
    bool rootSpace = false;
};

/// Parses the ARGS of the command line's `skin:ARGS`:
/// `ASSET[:fps=F][:animation=NAME|INDEX][:isolate=yes|no][:body=tubes][:space=root]`.
/// Options are taken from the end, so a path may itself hold a colon as long
/// as what follows it is not `fps=` or `animation=`.
/// @throws InputError for an empty path, a bad number or an unknown option.
SkinOptions parseSkinArgs(const std::string& args);

/// The users'-own-character evaluator of the render-farm work: a skinned,
/// animated asset loaded with Assimp and posed by linear blend skinning (and
/// morph targets where the asset has them). Stands for the paper's "standard
/// posing engine" of section 2 / figure 3; its points are the asset's vertices.
///
/// Points: the vertices of all meshes concatenated in the scene's mesh order
/// (aiScene::mMeshes), each mesh's vertices in their stored order, each mesh
/// once. meshOffsets() gives where each mesh starts. Channels: 3 (x, y, z) in
/// the scene's root space (the root node's transform included).
///
/// Posing of frame f, time t = f / fps seconds = t * ticksPerSecond ticks
/// (ticksPerSecond 0 in the file -> 25, Assimp's documented default):
///  - every animated node's local transform is T * R * S from its channel's
///    keys, linearly interpolated (rotations by shortest-path slerp); before
///    the first key or after the last one the nearest key holds; a node with
///    no channel keeps its stored transform;
///  - morph targets: v = base + sum_i w_i (target_i - base), weights from the
///    animation's morph channel of the mesh (interpolated linearly between
///    keys) or the targets' stored default weights;
///  - a skinned mesh: p = sum_b w_b (G_b * O_b) v with G_b the bone node's
///    global transform and O_b its offset (inverse bind) matrix; weights are
///    normalized to sum 1 at load time; a vertex without weights follows the
///    mesh's node rigidly;
///  - an unskinned mesh: p = G_node v, the node being the first (depth-first,
///    pre-order) that references the mesh, identity if none does.
///  - body=tubes: one mesh of tubes in place of the asset's meshes. Every bone (a joint and its parent
///    joint apart by more than 1e-6 of the skeleton's size, in the rest pose of the node
///    transforms) gets a tube of 8 rings x 12 vertices from the parent joint to the joint, radius
///    0.15 of its length, skinned to the parent joint; its last quarter blends linearly towards
///    the child joint and its first quarter towards the grandparent joint (half and half at the
///    joint itself), so bending a joint bends the tubes that meet there as flesh would, not as
///    rigid sticks. The skeleton's own motion is what a real capture gives; the tubes only make
///    it points.
/// Frames: 0 .. floor(duration_seconds * fps), so the last key is reached.
///
/// Thread safety: immutable after construction; evaluate() may run from any
/// number of threads. Determinism: a point's value depends only on the frame
/// and the point (the per-frame pose is recomputed by every call, the same
/// way), so any subset is bit-identical to the same points of a full pose.
class SkinEvaluator final : public PointEvaluator, public FrameWriterProvider {
public:
    /// Loads the asset and keeps only what posing needs (Assimp's scene is
    /// released). @throws InputError with Assimp's message (one line) when the
    /// file cannot be read, or when it has no vertices, no animation, or not
    /// the requested one.
    explicit SkinEvaluator(const SkinOptions& options);
    ~SkinEvaluator() override;

    std::string name() const override { return "skin"; }
    Index pointCount() const override;
    Index channelCount() const override { return 3; }
    Index frameCount() const override;
    void evaluate(Index frame, std::span<const Index> points, double* out) const override;

    /// .obj (positions + the triangles of every mesh) for `pmsc run`.
    std::vector<std::shared_ptr<const FrameWriter>> frameWriters() const override;

    /// First point of each mesh, plus the total at the end (meshes + 1 entries).
    const std::vector<Index>& meshOffsets() const;
    /// Triangles (and larger polygons, fan-split) as point indices into the
    /// concatenated points, 3 per triangle.
    const std::vector<std::int64_t>& triangles() const;
    /// Name of the animation used, and the number of bones that move points.
    std::string animationName() const;
    Index boneCount() const;
    Index morphTargetCount() const;
    double fps() const;

private:
    struct Data;
    static std::unique_ptr<Data> load(const SkinOptions& options);
    static std::unique_ptr<Data> loadInProcess(const SkinOptions& options);
    std::unique_ptr<const Data> data_;
};

/// `skin:ARGS` of the command line -> an evaluator.
std::unique_ptr<SkinEvaluator> makeSkinEvaluator(const std::string& args);

}  // namespace pmsc::evaluators
