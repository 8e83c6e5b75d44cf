// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"
#include "pmsc/Model.h"
#include "pmsc/NpyIO.h"
#include "pmsc/SoftCache.h"

#include <nlohmann/json.hpp>

#include <atomic>
#include <optional>
#include <span>
#include <utility>
#include <vector>

namespace pmsc::app {

/// The soft cache driven pass by pass, through files (`pmsc reconstruct`), for a calculation
/// pmsc cannot call: a renderer that bakes values at the points it is given (paper section 8:
/// "the illumination gather step is initially limited to only the key points. If error
/// tolerances are exceeded the fail through is easily accommodated through additional gathers").
///
/// The renderer first computes every frame's key points. Each pass then says, per frame, which
/// points the soft cache still needs; the renderer computes those and hands them back as the
/// answer to that pass. A frame needs, in order:
///   1. nothing more, when its keys hit, unless only one part of the predicted error certifies
///      the hit: then the points of its check (HitCheck: region keys and the neighbours of its
///      worst keys), and every point when the check fails;
///   2. for a model with regions (local fail-through), the region keys
///      (LocalRegions::extraKeyPoints) when the frame does not hit as a whole;
///   3. the points its failing regions evaluate fully (a local frame), or every point (a frame that
///      fails through whole): the keys and the points already answered are never asked again.
/// So a frame takes at most two passes beyond its keys, and a hit costs its K keys (and its
/// check's points when it is checked).
///
/// Decision: the passes are stateless. Each call is given the key values and every answer so
/// far, in pass order, and re-derives from them what each pass asked for (the decisions are
/// deterministic functions of the values); an answer is read only at the entries its pass
/// asked for, so the rest of an answer file may hold anything, NaN included. A renderer may write
/// all its answers into one array and give that array for every pass.
///
/// The frames that need nothing more are then run through the evaluation engine with an
/// evaluator that serves exactly the values known, so their output is what `pmsc replay`
/// gives on the same frames, byte for byte (the engine's fail-through asks for no value beyond
/// those the passes asked for; an evaluator that did would fail the run as an internal error).
struct PassOptions {
    /// Overrides the model's [eps_min, eps_max] (`--eps`).
    std::optional<std::pair<double, double>> eps;
    /// Models with regions: route frames region by region (`--whole-frame-fail-through` turns it off).
    bool localFailThrough = true;
    /// Worker threads of the engine; 0 = every core. Results do not depend on it.
    int threads = 0;
    /// Set by another thread (SIGINT) to stop; throws pmsc::Cancelled.
    const std::atomic<bool>* cancel = nullptr;
};

/// What the passes so far gave for one frame.
struct PassFrame {
    Index frame = 0;
    double keyRms = 0;          ///< the key points' RMS error (PointMultiplier::keyError)
    CacheDecision decision;     ///< the whole frame's hit / blend / miss
    bool done = false;          ///< every value the soft cache needs is known: the output is final
    Index passes = 0;           ///< passes beyond the keys this frame asked for and got answered
    std::vector<Index> needs;   ///< the points the next pass must compute (ascending; empty when done)
    Index pointsAnswered = 0;   ///< points computed for this frame beyond its keys, all passes
    bool local = false;         ///< routed region by region (done frames)
    Index pointsEvaluated = 0;  ///< points whose full value the output used (done frames)
    std::vector<CacheState> regionStates;  ///< per region, for done frames of models with regions
};

struct PassResult {
    double epsMin = 0, epsMax = 0;
    Index answersGiven = 0;         ///< answer files given (passes already computed)
    bool localFailThrough = false;  ///< frames are routed region by region when they do not hit
    std::vector<PassFrame> frames;  ///< in frame order
    Index framesDone() const;
    Index pointsNeeded() const;  ///< the next pass's points, all frames
};

/// Runs the passes: decides each frame from `keys` (F frames x K key points x C channels, model key
/// order) and `answers` (each F x N x C, read only where its pass asked), writes every frame to
/// `out` when given (the final soft-cached values for done frames; the point-multiplication
/// estimate for frames still waiting) and returns what each frame needs next.
/// @throws InputError for keys or answers whose shape does not match the model, or a NaN or
///         infinite value where a pass asked for a point (named: pass, frame, point, channel);
///         std::invalid_argument for a cross model or bad eps; pmsc::Cancelled.
PassResult reconstructPasses(const Model& model, const FrameSet& keys,
                             std::span<const MappedFrames* const> answers, const PassOptions& options,
                             NpyFrameWriter* out = nullptr);

/// The REPORT.json of `pmsc reconstruct` (docs/passes.md): {"summary": {...}, "frames": [...]}.
nlohmann::ordered_json passReport(const Model& model, const PassResult& result);

}  // namespace pmsc::app
