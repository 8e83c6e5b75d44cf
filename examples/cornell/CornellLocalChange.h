// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/cornell/CornellEvaluator.h"
#include "pmsc/Model.h"

#include <nlohmann/json.hpp>

#include <functional>
#include <map>
#include <memory>
#include <string_view>
#include <vector>

namespace pmsc::cornell {

/// The local change of the Cornell box: a white cube of edge `edgeMm` standing on the floor
/// 10 mm from a wall. Training never sees it: it covers the floor under it, throws a contact shadow
/// on the floor and the wall next to it, and reflects light onto both.
///
/// Where: whereKeysSee() puts it where the most key points lie within half an edge of it, because a
/// change no key point sees cannot be detected by any key error, the frame's or a region's.
/// Measured: a 100 mm cube at the fixed place againstBackWall() failed 2 of 8 frames as a whole at
/// --quick (6,000 points), both routed locally, but at the default size (160,432 points, other
/// keys) every frame hit with a largest error of 1.05 tolerances. At --quick, cubes by the red wall
/// (80-120 mm, z 90-210), by the green wall (120 mm, z 400-520: every frame a hit with a largest
/// error of 1.11 tolerances), in the front right corner and against the back wall at x 230-400
/// changed the full gather by 0.6-1.1 tolerances and no frame missed.
struct LocalChangeBox {
    Vec3 lo, hi;
    /// On the floor against the back wall, centred on x = 200 mm (clear of both blocks for edges
    /// up to 150 mm).
    static LocalChangeBox againstBackWall(double edgeMm);
    /// Among cubes every 10 mm along the foot of the back, green and red walls (10 mm from the wall,
    /// 5 mm clear of the blocks), the first with the most `keys` (point indices of world's voxels)
    /// within edgeMm / 2 of it; that count into *keysNear.
    static LocalChangeBox whereKeysSee(double edgeMm, const CornellWorld& world,
                                       const std::vector<Index>& keys, Index* keysNear = nullptr);
};

/// What measureLocalFailThrough needs from the demo: the model, the validation evaluator and the
/// full gathers it holds, and how the demo runs things.
struct LocalFailThroughInputs {
    const Model& model;
    const CornellEvaluator& validation;  ///< its first `scattered` frames are the scattered lights
    Index scattered = 0;                 ///< validation frames [0, scattered): scattered lights
    const std::map<Index, std::vector<double>>&
        fullGathers;          ///< of validation's frames, every scattered one included
    double tolerance = 0;     ///< the demo's tolerance of a hit (data units: Euclidean RGB irradiance)
    double changeEdgeMm = 0;  ///< LocalChangeBox edge; 0 = no local-change set
    int changeLights = 0;     ///< the local-change set: the first this many scattered lights
    int threads = 1;          ///< cores of the error runs (the speed runs use one)
    /// Runs work in the demo's task arena (full gathers of the changed scene).
    std::function<void(const std::function<void()>&)> inArena;
    /// Progress (stage, done, total); may throw to cancel.
    std::function<void(std::string_view, double, double)> progress;
};

/// report.json's "local_fail_through": the regions, then
/// examples::localFailThroughReport() (errors as multiples of the tolerance) both ways on
/// - "validation": the scattered validation lights (the ordinary validation set), and
/// - "local_change": the same cache points and the first changeLights scattered lights in the box
///   with LocalChangeBox::whereKeysSee(changeEdgeMm, ..., the model's keys), against full gathers of that
///   changed scene; with the change itself: its box, the points it covers, and how far the changed full
///   gather moves from the unchanged one (largest move over the tolerance, fraction of points moved by more
///   than a tenth of the tolerance).
nlohmann::json measureLocalFailThrough(const LocalFailThroughInputs& in);

}  // namespace pmsc::cornell
