// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"
#include "pmsc/Subspace.h"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace pmsc {

/// How training learns the regions of local fail-through. count = 0: no regions (the
/// model is then a version-1 model).
struct RegionOptions {
    Index count = 0;  ///< R, the number of regions wanted (fewer if clustering leaves some empty)
    /// count == 0 and automatic: training chooses R from the data, or none where regions do not
    /// pay (chooseRegions in RegionChoice.h; `pmsc train`'s default).
    bool automatic = false;
    /// With automatic: the feather width comes with R (RegionChoice::featherFraction) instead of
    /// featherFraction. `pmsc train` clears it when --feather is given.
    bool automaticFeather = true;
    /// Feather width as a fraction of the positions' bounding-box diagonal (Regions.h).
    double featherFraction = 0.03;
    /// Fraction of N above which a frame fails through whole (LocalRegions::maxLocalFraction).
    double maxLocalFraction = 0.6;
    /// Each region's local basis: the smallest M_r capturing this fraction of the region's
    /// training energy, capped by M and by 2/3 of its key values (K_r*C) so its key error stays a
    /// real test.
    double energy = 0.9999;
    /// Fewest keys a region projects from; the nearest keys outside it are added when it holds fewer.
    /// 12 (36 key values on a face): with 6 a region's key error was noise
    /// on the ICT face's novel set — frames whose region error exceeded 1% of the head diagonal
    /// had key errors below those of frames with 0.1% — because most regions (neck, teeth,
    /// gums, mouth socket) hold no key of their own.
    Index minKeys = 12;
    /// Keys of its own every region gets: a region holding fewer of the model's keys gets region
    /// keys among its points (LocalRegions::extraKeyPoints; evaluated only for frames that miss
    /// as a whole, so hits cost what they did). 0 = none. 4: on the ICT face most regions (neck,
    /// teeth, gums, mouth socket) hold none of the 170 keys, so their key error was made of their
    /// neighbours' keys (the lips') and they failed with every lip motion training never saw,
    /// right or not: the mouth's inner regions alone were ~17% of the points evaluated needlessly
    /// on the novel set. With 4 keys of their own (277 region keys on the face) the novel set's
    /// points evaluated fell from 55.1% to 51.6% and its worst error from 0.97% to 0.51% of the
    /// head diagonal, which let the margin and the radius below come down; 8 keys (621) evaluated
    /// 53.3%, 3 (200) 47.2% at the settings below against 45.8% for 4.
    Index ownKeys = 4;
    /// Keys within this distance of a region's nearest point (fraction of the positions'
    /// diagonal) join its keys: a motion that breaks the region shows first at the keys next to
    /// it (the chin's keys move when jawForward moves the neck below them). 6%: on the face's
    /// novel set, 3% left regions blind to their neighbours' motion (more frames over the
    /// tolerance among region hits) and 10% made every region near the mouth fail with it.
    /// 4.5% since regions have keys of their own (ownKeys): novel set 45.8% of the points, worst
    /// 0.85%; 6% 47.5% (worst 0.78%), 3% 45.0% but worst 0.97%, too close to the tolerance.
    double keyRadius = 0.045;
    /// Each region's basis has at most this share of its key values (K_r*C): the rest of the key
    /// values are left as residual, so the region's key error still tests its points. 0.4, not
    /// 2/3: a region's key RMS measured on 2/3 of a few dozen values left about ten degrees of
    /// freedom, too few to see a motion its basis absorbs.
    double basisShare = 0.4;
    /// Safety factor on each region's calibrated ratio: eps_min = T / (margin r). Held-out slices
    /// are ordinary motion, but a region fails for motion training never saw, and on the ICT
    /// face's novel set (cheekPuff, mouthLeft, jawForward) the region error per key error came
    /// out up to 1.4x the largest held-out ratio (regions bordering the mouth). With 1.5 no
    /// region hit exceeded the tolerance there; 1 let the worst frame reach 1.36%. Measured
    /// with no keys of their own (ownKeys = 0); with 4 of them the worst novel frame is
    /// 0.51% at 1.5 and 0.78% at 1, so 1 (the calibrated bound itself, 47.5% of the points
    /// evaluated against 51.6%). A model trained with ownKeys = 0 should set 1.5 again.
    double ratioMargin = 1.0;
    /// Point positions (N x 3, one row per point) for spatial clustering and feathering. Empty:
    /// the training mean when C == 3 (a face's rest shape); otherwise regions cannot be learned.
    Eigen::MatrixXd positions;
    int kmeansIterations = 30;
    /// Regions' bases and calibration learn from every frameStride-th training frame (1 = all).
    /// Neighbouring frames of an animation are nearly alike; the cost of a region's calibration
    /// grows with the square and cube of the frames (its Gram matrix, its folds' eigensolvers).
    Index frameStride = 1;
};

/// The leading (at most 24) basis vectors scaled by their singular values, Varimax-rotated as
/// key selection rotates them (section 4): per point and rotated factor, the norm of the point's
/// loading over the channels (N x J). Rotated factors are local where the data's motions are.
Eigen::MatrixXd rotatedLoadings(const Model& model);

/// Learns the regions of a trained model: the model's core (mean, basis, keys) must be final.
///
/// Method (the paper's section 9 suggests basis rotation and clustering; this is one such choice):
///  1. Varimax-rotate the leading (at most 24) basis vectors scaled by their singular values, as
///     key selection does (section 4): rotated factors are local, so a point's loading pattern on
///     them says which motions move it. Each point gets the unit vector of its loadings (scaled
///     down for nearly still points, whose pattern is noise).
///  2. k-means (farthest-point seeding from the centroid, Lloyd iterations; deterministic) on
///     [position * sqrt(R) / diagonal, loading pattern]: positions keep regions compact (cheap
///     subsets, short borders), loading patterns split points that sit close but move apart
///     (upper and lower lip), so the points of a region share their motions and so their errors.
///  3. Keys: the model's keys inside the region, those within keyRadius of it, and the nearest
///     outside it up to minKeys.
///  4. A local basis from the SVD of the region's rows of `q` (its points and its keys), and its
///     projector; thresholds calibrated like the frame's (Calibration.h, leave-one-slice-out) for
///     `tolerance` (with ratioMargin), or from the training frames' key RMS when tolerance == 0.
///  5. Feather entries (Regions.h) from the distance to the nearest point of each other region.
/// @param q mean-removed training matrix (N*C) x F of this model
/// @param notes decisions worth a warning are appended
/// @throws std::invalid_argument for bad options or when positions are needed and unknown.
LocalRegions learnRegions(const Eigen::Ref<const Eigen::MatrixXd>& q, const Model& model,
                          const RegionOptions& options, double tolerance, Index slices, const SvdOptions& svd,
                          std::vector<std::string>* notes = nullptr);

/// One held-out slice of `pmsc learn`'s new frames and the subspace that never saw it, for
/// relearnRegions' calibration: columns [first, last) of the new frames were scored by the state
/// `basis` diag(sigma) about `mean`.
struct RegionFold {
    Eigen::MatrixXd basis;  ///< (N*C) x m, orthonormal: the fold's leading directions
    Eigen::VectorXd sigma;  ///< m singular values
    Eigen::VectorXd mean;   ///< N*C
    Index first = 0, last = 0;
};

/// The regions of a learned model (`pmsc learn`), without the frames training learned them from.
///
/// Method:
///  1. The partition, the feather and the largest local fraction are the old model's: positions do
///     not change, and a region's points still share their motions where training saw them share.
///  2. Each region's key points: the learned keys inside it, its old region keys, the old keys
///     outside it that the learned model still reads, and, with the positions the regions were
///     learned from (`positions`, N x 3; empty: unknown), the learned keys within keyRadius of it,
///     as training chooses them (RegionOptions' defaults). Old keys the learned model dropped come
///     back only while the region holds fewer than ownKeys inside, then minKeys in all
///     (relearnedRegionKeys has the measured reason). A point that is a key of the learned model is
///     read as that key; the others are region keys (LocalRegions::extraKeyPoints), read only for
///     frames that do not hit whole and for checked hits, as training's region keys are.
///  3. Each region's basis: the SVD of its rows of the surrogate `basis` diag(sigma) of every frame
///     seen (the updated state, as learn's keys are selected on), with training's energy rule and
///     cap (RegionOptions' defaults: a model does not store the options it was trained with).
///  4. Thresholds, with a tolerance: each fold of `folds` gives its region basis the same way from
///     its own state and scores its held-out new frames (region key RMS, largest point error of
///     the region's points); the region's ratio is the larger of those frames' (MaxRatio) and the
///     old region's, and its margin is the old one (T / (ratio eps_min)). As learn's frame-wide
///     thresholds take the larger of the new frames' ratio and the stored one: a motion the new
///     frames add must not loosen a region, and one they lack must not either.
///     Without a tolerance: eps_min is the larger of the old one and the largest region key RMS of
///     the new frames (`fresh`, about the learned mean) under the new basis, as training's are.
/// @param fresh the new frames, (N*C) x m, raw
/// @param notes when given, gets a line when the cap made some regions' bases smaller than M (as
///     training says it).
/// @throws std::invalid_argument when old does not fit oldModel or the sizes disagree.
LocalRegions relearnRegions(const LocalRegions& old, const Model& oldModel, const Model& learned,
                            const Eigen::Ref<const Eigen::MatrixXd>& basis, const Eigen::VectorXd& sigma,
                            const Eigen::Ref<const Eigen::MatrixXd>& fresh,
                            const std::vector<RegionFold>& folds, const SvdOptions& svd,
                            const Eigen::MatrixXd& positions = {}, std::vector<std::string>* notes = nullptr);

}  // namespace pmsc
