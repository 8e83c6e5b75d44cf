// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"  // Index

#include <Eigen/Core>

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace pmsc {

struct Model;
struct ModelSectionCodec;

/// Points spread evenly over the part of the shape training saw move, computed for real beside
/// every hit (Model::sentinels; model-file section "SENTINEL"; checked by HitCheck).
///
/// Why: the keys see what they were chosen for. A control the training never moved can bend a
/// patch of points that no key, and no key's neighbour, sits in; the key error then looks like an
/// ordinary frame's and the hit hands back points over the tolerance (the novelty suite,
/// docs/calibration.md). PM's error at a point it did not fit is a prediction, so computing a few
/// such points tests the part of the frame the keys cannot see. They are chosen by farthest-point
/// sampling, so every moving point lies within `coveringRadius` of one: an error patch that
/// reaches over kSentinelShare * T across a disc of that radius anywhere on the moving part is seen.
/// That is the promise, and its limit: a patch over T narrower than the spacing can slip between
/// sentinels.
///
/// Points without positions (light values trained without `--positions`) get sentinels drawn in
/// point order instead (pointOrderSentinels): one at random in each of S equal runs of the moving
/// points. A patch of n adjacent points that are all over kSentinelShare * T is then seen when it
/// covers a whole run, and otherwise with probability n / (run length) per run it touches. Renderers'
/// and volumes' point orders follow space (voxels, surfaces), so that is close to spatial coverage;
/// in an arbitrary order it is a random sample, whose chance of missing a share f of the moving
/// points is (1 - f)^S. Positions are always better: `pmsc export-frames --positions` writes them.
enum class SentinelSource : std::uint32_t {
    Given = 0,       ///< farthest-point samples of positions the user gave (learn chooses again from the
                     ///< same positions, else keeps them less the new keys)
    Mean = 1,        ///< farthest-point samples of the training mean, a shape (learn chooses again)
    PointOrder = 2,  ///< one at random in each equal run of moving points (learn chooses again)
    Frame = 3,       ///< farthest-point samples of a training frame, a shape whose mean is not (frameShape;
                     ///< learn chooses again from its new frames)
};

struct Sentinels {
    std::vector<Index> points;  ///< in the order they were chosen, no keys, no duplicates
    /// Given or Mean: the largest distance from a moving point to its nearest sentinel, in the
    /// positions' units. PointOrder: the length of a run, in points.
    double coveringRadius = 0;
    SentinelSource source = SentinelSource::Mean;
    /// Each sentinel's kSentinelNeighbours nearest other sentinels (their positions in `points`),
    /// nearest first, `perSentinel` of them (fewer sentinels: all the others), and their distances;
    /// what the slope check reads (HitCheck). Given or Mean: in space; PointOrder:
    /// the runs beside it, at runs apart times a run's length (the covering radius's units), which
    /// are near in space as far as the point order follows space.
    Index perSentinel = 0;
    std::vector<Index> neighbours;           ///< points.size() x perSentinel
    std::vector<double> neighbourDistances;  ///< the same shape, > 0

    /// Checks ranges against the model (N): throws std::invalid_argument naming the first problem.
    void validate(const Model& model) const;
};

/// Sentinels `pmsc train` chooses unless told (--sentinels): 1024. Why: on the novelty suite's
/// sets A-H (the face, 26,719 points, 600 training frames, both basis sizes) 1024 at
/// kSentinelShare = 0.8 left no frame over T where 512 left 30 and 256 left 70, and refused 1.3%
/// of the validation frames' hits; sets I-L, made after, had none over T with them (192 without).
constexpr Index kDefaultSentinels = 1024;

/// At most one point in kSentinelSpacing is a sentinel: a hit's check costs at most 1/16 of the
/// full calculation besides the keys. Why: the count the face needs (1024 of 26,719 points, 1 in 26)
/// would be 40% of a 2,592-point body; on small point sets the spacing, not the count, is what
/// a user can afford, and `pmsc inspect` prints the covering radius it gives.
constexpr Index kSentinelSpacing = 16;

/// A hit stands only where PM is within kSentinelShare * T of every sentinel's computed value.
/// Any model trained with a tolerance has them, whatever its key error and whether its channels
/// share the basis.
/// Why 0.8: on sets A-H, 0.9 let 10 frames over T through and 0.7 refused 4.5% of the validation
/// hits against 1.3% at 0.8.
constexpr double kSentinelShare = 0.8;

/// Sentinels drawn in point order (no positions) are kPointOrderFactor times as many as asked
/// (still at most one point in kSentinelSpacing). Why: their detection is a draw, not a covering.
/// On the light novelty suite (bench/light_novelty.py: the Cornell box and the smoke, lights outside
/// the trained range) 1024 in point order let one frame of each scene through (1.01 T and 1.115 T),
/// which farthest-point samples of the positions refused; 2048 refused both in every draw the
/// replica tried (six seeds).
constexpr Index kPointOrderFactor = 2;

/// The slope check (HitCheck) reads each sentinel's kSentinelNeighbours nearest sentinels.
constexpr Index kSentinelNeighbours = 6;

/// The slope check: a hit stands only where, at every sentinel i,
///     e_i + kSentinelSlopeShare * r * max_j |e_i - e_j| / d_ij <= T
/// (e PM's error at a sentinel, j its computed neighbours at distance d_ij, r the covering radius).
/// Why: a sentinel's own error bounds the error around it only where the error field is flat at
/// the scale of the spacing. Where neighbouring sentinels disagree the field changes at that scale,
/// and a patch between them can peak over both; the check extrapolates the steepest neighbouring
/// slope half the covering radius beyond the sentinel. Farthest-point sentinels are at least r
/// apart, so the term is at most half the difference: only a sentinel over 2/3 T whose neighbours
/// see much less can fail it. Sentinels drawn in point order read the runs beside them (a run's
/// length is their covering radius): on the quick light suite that refused the Cornell box's hit
/// at 1.031 T at --energy 0.99999 without positions, and no hit between the training lights. Why 0.5: in a
/// replica of the check on the novelty suite's frames (bench/sentinel_slope.py) it refused the two frames of
/// the quick Cornell box at --energy 0.99999 that pass at kSentinelShare (up to 1.034 T, a patch of 12-15
/// points between sentinels) and one of the three of the four cubes in Cycles, at a cost of 16 more of the
/// face's 5,500 validation hits and local frames on sets A-N, both bases (49 to 65); 0.75 refused
/// 96 more.
constexpr double kSentinelSlopeShare = 0.5;

/// A point moves when its RMS motion in the basis is at least this share of the largest point's.
constexpr double kMovingShare = 1e-3;

/// Each point's RMS motion over the training frames as the basis holds it: the norm of its rows of
/// basis * diag(singular values) (up to the common factor 1/sqrt(F)). Needs only the model, so train
/// and learn choose from the same measure.
Eigen::VectorXd basisMotion(const Model& model);

/// The sentinels a model of `points` points gets when `requested` are asked for:
/// min(requested, points / kSentinelSpacing).
Index sentinelCount(Index requested, Index points);

/// `count` sentinels among the moving points (motion >= kMovingShare * the largest) that are not
/// keys, by farthest-point sampling of `positions` (N x 3) from the point that moves most; fewer
/// when fewer points qualify (none: an empty set). Ties by point index: deterministic.
/// @throws std::invalid_argument when the sizes disagree or a key is out of range.
Sentinels farthestPointSentinels(const Eigen::Ref<const Eigen::MatrixXd>& positions,
                                 const Eigen::Ref<const Eigen::VectorXd>& motion, std::span<const Index> keys,
                                 Index count, SentinelSource source);

/// `count` sentinels for points without positions: the moving points that are not keys, in point
/// order, cut into `count` runs of equal length (as near as integers allow), one point from each,
/// drawn with std::mt19937_64 seeded by `seed` (the same on every machine). Why one at random in
/// each run, not the middle: a fixed stride can fall in step with a periodic point order (the
/// rows of a voxel grid) and see one column only.
/// @throws std::invalid_argument when a key is out of range.
Sentinels pointOrderSentinels(const Eigen::Ref<const Eigen::VectorXd>& motion, std::span<const Index> keys,
                              Index count, std::uint64_t seed);

/// `s` less the sentinels at `removed` points, for when the positions that placed them are gone
/// (learn without them, when sentinels became keys). Each kept sentinel's neighbours are its old
/// ones that are kept, renumbered: they were its nearest among all, so they are its nearest among
/// those kept; every list is cut to the shortest (perSentinel falls by as many as one sentinel
/// lost). The covering radius grows to a bound that needs no positions: a point whose nearest
/// sentinel was a removed r is within R + d(r, the nearest kept sentinel along r's neighbour
/// lists) of a kept one, a larger reach for the slope check, never a smaller. When some removed
/// sentinel reaches no kept one through the lists, nothing bounds R: the neighbours are dropped
/// (perSentinel 0, no slope check) and each sentinel's own check stays.
Sentinels withoutPoints(const Sentinels& s, std::span<const Index> removed);

/// frameShape's test: at most kShapeSamples points, their nearest neighbours' distances over at
/// most kShapeFrames frames, and a median relative spread (std / mean) of at most kMostStretch.
constexpr Index kShapeSamples = 256;
constexpr Index kShapeFrames = 256;
constexpr double kMostStretch = 0.1;

/// The positions a 3-channel data set's own frames give it when no positions are given and its
/// mean is not a shape (a body whose limbs sweep far: the mean folds them together), for the
/// sentinels: the frame nearest the mean, mean + basis * coefficients.col(f), N x 3, when the data
/// deform as a surface does, near-isometrically. The test: at up to kShapeSamples points spread in
/// point order, the distance to the point nearest it in that frame varies over the frames (up to
/// kShapeFrames, evenly spaced) by a median relative spread (std / mean) of at most kMostStretch.
/// Empty when it does not (light: the points nearest in one frame's values are not near in the
/// next) or there is nothing to test. `mean` is N*3, `basis` N*3 x M, `coefficients` M x F (the
/// frames' coordinates in the basis).
///
/// Why: without positions the sentinels are drawn in point order, whose slope check reads runs of
/// points as neighbours; a skinned body's runs are not near in space as its surface is, and the
/// check would refuse 57 of the CMU take 01_01's 509 hits at 2.5% (every one under T). Spread over a
/// frame the body actually takes, the sentinels cover the body as they cover the face, and the
/// slope check reads real distances. Why the test and 0.1: on the motion-capture ranges of motion
/// (bench/mocap_suite.py: skinned tubes, poses swept to +-75 degrees) the median spread is 0.000
/// (90th percentile 0.03); on light (the light novelty suite's Cornell box and smoke, Blender's
/// four cubes) it is 0.71-0.89.
Eigen::MatrixXd frameShape(const Eigen::Ref<const Eigen::VectorXd>& mean,
                           const Eigen::Ref<const Eigen::MatrixXd>& basis,
                           const Eigen::Ref<const Eigen::MatrixXd>& coefficients);

/// The positions sentinels spread over when none are given, chosen in the same order by training
/// and learn: the model's mean when it is a shape (meanShape), else frameShape of the frames whose
/// coordinates in the model's basis `coefficients()` gives (asked only then); `source` says which
/// (Mean or Frame). Empty for data whose channels are not positions (not 3, or shared).
Eigen::MatrixXd sentinelShape(const Model& model, SentinelSource& source,
                              const std::function<Eigen::MatrixXd()>& coefficients);

/// "given" / "mean" / "point order" / "frame": the name `pmsc inspect --json` prints.
const char* toString(SentinelSource source);
/// How a model's sentinels were chosen, for `pmsc inspect` ("positions given to train", ...).
const char* describe(SentinelSource source);

/// Codec of the "SENTINEL" model-file section (ModelSections.h).
ModelSectionCodec sentinelsSectionCodec();
/// Codec of the "SENTNBRS" section: the sentinels' neighbours (written after "SENTINEL").
ModelSectionCodec sentinelNeighboursSectionCodec();

}  // namespace pmsc
