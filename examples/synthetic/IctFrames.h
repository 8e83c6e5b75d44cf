// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <Eigen/Core>

#include <string>
#include <utility>
#include <vector>

namespace pmsc::synthetic {

/// A small blendshape + rotational-jaw rig built from the ICT FaceKit meshes
/// (ICT-VGL/ICT-FaceKit, FaceXModel/): the neutral mesh and one whole mesh per
/// expression, so a blendshape delta is expression - neutral. It makes
/// training and test frames at the face scale (600 frames x 26,719
/// points); the face example has the full rig.
///
/// The jaw is not the linear jawOpen blendshape but a rotation about a hinge,
/// which is what makes the data nonlinear in the animation controls (section 2):
/// the hinge (an axis along x through a point c fitted in the y-z plane) and each
/// vertex's skin weight are derived from the jawOpen delta: a least-squares fit
/// of the rigid rotation jawOpen = c + R(alpha)(neutral - c) over the vertices
/// that move most, then weight_p = |d_p| / (2 |sin(alpha/2)| |p - c|) (the
/// fraction of the full rotation's chord the vertex travels), clamped to [0, 1].
struct IctRig {
    Index points = 0;
    Eigen::VectorXd neutral;  ///< 3N, point-major
    struct Shape {
        std::string name;
        std::vector<Index> vertices;  ///< vertices the shape moves (|delta| > 1e-9)
        std::vector<Eigen::Vector3d> deltas;
    };
    std::vector<Shape> shapes;  ///< every expression except jawOpen, sorted by name
    Eigen::Vector2d jawPivotYZ = Eigen::Vector2d::Zero();  ///< hinge axis: x, through (y, z)
    double jawAngle = 0;                                   ///< radians of rotation at jawOpen = 1 (fitted)
    std::vector<Index> jawVertices;                        ///< vertices with a jaw weight > 0
    std::vector<double> jawWeights;
    double bboxDiagonal = 0;  ///< of the neutral mesh (the paper's error unit, section 7)
};

/// Reads generic_neutral_mesh.obj and every other *.obj in `folder`.
/// @throws InputError naming the file for a missing folder, an unreadable or
///         malformed mesh, or a vertex count that differs from the neutral's.
IctRig loadIctRig(const std::string& folder);

/// Frames of the rig posed by smooth random blendshape weights in [0, 1] (left /
/// right pairs mostly move together) and a jaw opening between 0 and 1: point
/// positions, shape (frames, N, 3). Deterministic for a seed; different seeds
/// give different motion of the same rig.
/// @param without blendshapes held at 0 (e.g. train without "mouthPucker", then test
///        with it: a control the training set never exercised, section 5). The curves
///        of the others do not change.
/// @param hold  blendshapes held at a fixed weight in every frame instead of their curves (a
///        control training left still, moved at a chosen amplitude: the novelty sets of
///        docs/calibration.md). The curves of the others do not change.
/// @throws InputError for a name in `without` or `hold` that is not a blendshape of the rig, or a
///         held weight outside [0, 1].
FrameSet poseIctFrames(const IctRig& rig, Index frames, unsigned seed,
                       const std::vector<std::string>& without = {},
                       const std::vector<std::pair<std::string, double>>& hold = {});

/// Segments of one take, one after another: for each entry of `holds`, poseIctFrames(rig,
/// framesPerSegment, seed, without, that entry), that is the take's frames 0 to
/// framesPerSegment - 1 with those shapes held. A held weight overrides `without`. A test set of
/// many held controls thus comes from one load of the rig, which is most of a short set's time.
/// @throws InputError as poseIctFrames, or for no segments.
FrameSet poseIctSegments(const IctRig& rig, Index framesPerSegment, unsigned seed,
                         const std::vector<std::string>& without,
                         const std::vector<std::vector<std::pair<std::string, double>>>& holds);

}  // namespace pmsc::synthetic
