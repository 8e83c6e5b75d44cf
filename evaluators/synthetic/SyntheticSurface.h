// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/synthetic/SmoothNoise.h"
#include "pmsc/PointEvaluator.h"

#include <memory>
#include <string>
#include <vector>

namespace pmsc::synthetic {

/// What the generated shot looks like.
struct SurfaceOptions {
    Index grid = 64;     ///< grid x grid points on [-1, 1]^2 (N = grid^2), 3 channels (x, y, z)
    Index frames = 400;  ///< frames of the shot
    unsigned seed = 1;   ///< animation curves (different seeds: different motion, same rig)
    /// The last `novelFrames` frames ramp in a deformer the training shots never use (a
    /// pinch at a spot no other deformer touches): motion outside the training set, which
    /// the soft cache must notice and fail through on (section 5).
    Index novelFrames = 0;
};

/// A deforming procedural surface standing in for an articulated character: a
/// sheet posed by a few smooth global modes (linear in their controls), local
/// bumps that SLIDE across the sheet (nonlinear in the slide control) and a
/// local twist about a pivot (a rotation, nonlinear in its angle, like a jaw).
/// The point multiplication has to catch the nonlinear parts through its key
/// points (section 2, figure 3).
///
/// Every point of every frame is computed independently from the frame's
/// control values, so evaluate() is exact for any subset, deterministic and
/// thread-safe. The rig (rest grid, deformer placements) is the same for every
/// seed; only the animation differs, so a model trained on one seed applies to
/// another.
class SyntheticSurface : public PointEvaluator {
public:
    explicit SyntheticSurface(const SurfaceOptions& options);

    std::string name() const override { return "synthetic"; }
    Index pointCount() const override { return options_.grid * options_.grid; }
    Index channelCount() const override { return 3; }
    Index frameCount() const override { return options_.frames; }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override;

    /// The controls of one frame (exposed for tests).
    struct Controls {
        std::vector<double> modes;    ///< global mode amplitudes
        std::vector<double> heights;  ///< bump heights
        std::vector<double> slides;   ///< bump slides along their directions
        double twist = 0;             ///< twist angle, radians
        double novel = 0;             ///< the novel pinch, 0 except in the last novelFrames frames
    };
    Controls controls(Index frame) const;

private:
    void evaluatePoint(const Controls& c, Index point, double* out) const;

    struct Bump {
        double x, y;    ///< rest centre
        double dx, dy;  ///< slide direction (unit)
        double radius;
    };
    SurfaceOptions options_;
    std::vector<SmoothNoise> modeCurves_, heightCurves_, slideCurves_;
    SmoothNoise twistCurve_;
    std::vector<Bump> bumps_;
};

/// What "synthetic[:grid=G][:frames=F][:seed=S][:novel=N]" means on the command line and in
/// Python: a SyntheticSurface with those SurfaceOptions (defaults as there). Options are separated
/// by ':' as the other evaluators' are.
/// @throws pmsc::InputError naming the option for an unknown key or a value out of range.
std::unique_ptr<SyntheticSurface> makeSyntheticSurface(const std::string& args);

}  // namespace pmsc::synthetic
