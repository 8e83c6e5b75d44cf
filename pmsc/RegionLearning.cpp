#include "pmsc/RegionLearning.h"

#include "pmsc/Calibration.h"
#include "pmsc/Parallel.h"
#include "pmsc/Subspace.h"
#include "pmsc/Varimax.h"

#include <Eigen/QR>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

namespace pmsc {

namespace {

[[noreturn]] void badRegionOption(const std::string& what) {
    throw std::invalid_argument("train: regions: " + what);
}

/// The note training and learn give when the cap made some regions' bases smaller than M.
std::string cappedBasesNote(Index capped, Index regions) {
    return "regions: " + std::to_string(capped) + " of " + std::to_string(regions) +
           " regions' local bases were capped by their share of key values";
}

/// Step 1: each point's loading pattern on the Varimax-rotated leading factors (N x J).
Eigen::MatrixXd loadingPatterns(const Model& model) {
    const Index n = model.points;
    Eigen::MatrixXd pattern = rotatedLoadings(model);
    Eigen::VectorXd norms(n);
    for (Index p = 0; p < n; ++p) norms[p] = pattern.row(p).norm();
    // Nearly still points: their pattern is noise, so it counts less (down to nothing).
    std::vector<double> sorted(norms.data(), norms.data() + n);
    std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
    const double median = sorted[size_t(n / 2)];
    for (Index p = 0; p < n; ++p) {
        const double s = norms[p];
        if (s > 0) pattern.row(p) *= std::min(1.0, median > 0 ? s / median : 1.0) / s;
    }
    return pattern;
}

/// Step 2: k-means on feature rows; returns the cluster of every row (clusters renumbered 0..R'-1
/// in order of their first point, empty ones dropped).
std::vector<Index> kmeans(const Eigen::MatrixXd& x, Index k, int iterations) {
    const Index n = x.rows();
    k = std::min(k, n);
    // Farthest-point seeding from the point nearest the centroid: deterministic, spread out.
    const Eigen::RowVectorXd centroid = x.colwise().mean();
    Index first = 0;
    (x.rowwise() - centroid).rowwise().squaredNorm().minCoeff(&first);
    Eigen::MatrixXd centres(k, x.cols());
    centres.row(0) = x.row(first);
    Eigen::VectorXd nearest = (x.rowwise() - centres.row(0)).rowwise().squaredNorm();
    for (Index i = 1; i < k; ++i) {
        Index far = 0;
        nearest.maxCoeff(&far);
        centres.row(i) = x.row(far);
        nearest = nearest.cwiseMin((x.rowwise() - centres.row(i)).rowwise().squaredNorm());
    }
    std::vector<Index> label(size_t(n), 0);
    // The assignment runs on every core in fixed blocks of points: each block is the same
    // arithmetic on any thread, so the labels do not depend on the thread count.
    // Decision: a point's nearest centre minimises |c|^2 - 2 x.c (|x - c|^2 less |x|^2, the same
    // for every centre), one matrix product per block. Why: on the face's training (`perf record
    // pmsc train`: 26,719 points, 159 centres, 27 features) a k x d difference per point is 14% of
    // the CPU and the product 2%. The product rounds to about 1e-16 |x|^2, which reorders only
    // centres that all but tie: the novelty suite's set A gives the same model file, byte for byte.
    constexpr Index kBlock = 1024;
    const Index blocks = (n + kBlock - 1) / kBlock;
    for (int it = 0; it < iterations; ++it) {
        std::atomic<Index> next{0};
        std::atomic<bool> changed{false};
        const Eigen::RowVectorXd centreNorms = centres.rowwise().squaredNorm().transpose();
        const Eigen::MatrixXd centresT = centres.transpose();
        runOnEveryCore(
            [&] {
                Eigen::MatrixXd dots;
                for (Index b = next++; b < blocks; b = next++) {
                    const Index first = b * kBlock, rows = std::min(n, first + kBlock) - first;
                    dots.noalias() = x.middleRows(first, rows) * centresT;
                    bool moved = false;
                    for (Index i = 0; i < rows; ++i) {
                        Index best = 0;
                        (centreNorms - 2 * dots.row(i)).minCoeff(&best);
                        moved = moved || best != label[size_t(first + i)];
                        label[size_t(first + i)] = best;
                    }
                    if (moved) changed = true;
                }
            },
            blocks);
        Eigen::MatrixXd sum = Eigen::MatrixXd::Zero(k, x.cols());
        Eigen::VectorXd count = Eigen::VectorXd::Zero(k);
        for (Index p = 0; p < n; ++p) {
            sum.row(label[size_t(p)]) += x.row(p);
            count[label[size_t(p)]] += 1;
        }
        for (Index i = 0; i < k; ++i)
            if (count[i] > 0) centres.row(i) = sum.row(i) / count[i];
        if (!changed && it > 0) break;
    }
    std::vector<Index> renumber(size_t(k), -1);
    Index next = 0;
    for (Index p = 0; p < n; ++p) {
        Index& r = renumber[size_t(label[size_t(p)])];
        if (r < 0) r = next++;
        label[size_t(p)] = r;
    }
    return label;
}

/// Step 5: for every point, its distance to each other region within `width` (a uniform grid of
/// cell `width`, so only the 27 cells around a point are searched).
void featherEntries(const Eigen::MatrixXd& pos, const std::vector<Index>& regionOf, double width,
                    LocalRegions& out) {
    const Index n = pos.rows();
    out.featherStart.assign(size_t(n) + 1, 0);
    out.featherRegion.clear();
    out.featherFactor.clear();
    if (!(width > 0)) return;
    const Eigen::RowVector3d lo = pos.colwise().minCoeff();
    auto cellOf = [&](Index p, int axis) {
        return static_cast<std::int64_t>(std::floor((pos(p, axis) - lo[axis]) / width));
    };
    auto key = [](std::int64_t x, std::int64_t y, std::int64_t z) { return (x * 1048576 + y) * 1048576 + z; };
    std::vector<std::pair<std::int64_t, Index>> cells(static_cast<size_t>(n));
    for (Index p = 0; p < n; ++p) cells[size_t(p)] = {key(cellOf(p, 0), cellOf(p, 1), cellOf(p, 2)), p};
    std::sort(cells.begin(), cells.end());
    std::vector<double> best;
    std::vector<Index> touched;
    best.assign(out.regions.size(), std::numeric_limits<double>::infinity());
    for (Index p = 0; p < n; ++p) {
        const std::int64_t cx = cellOf(p, 0), cy = cellOf(p, 1), cz = cellOf(p, 2);
        for (int dx = -1; dx <= 1; ++dx)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dz = -1; dz <= 1; ++dz) {
                    const std::int64_t kk = key(cx + dx, cy + dy, cz + dz);
                    auto it = std::lower_bound(cells.begin(), cells.end(), std::make_pair(kk, Index{-1}));
                    for (; it != cells.end() && it->first == kk; ++it) {
                        const Index r = regionOf[size_t(it->second)];
                        if (r == regionOf[size_t(p)]) continue;
                        const double d = (pos.row(p) - pos.row(it->second)).norm();
                        if (d < width) {
                            if (best[size_t(r)] == std::numeric_limits<double>::infinity())
                                touched.push_back(r);
                            best[size_t(r)] = std::min(best[size_t(r)], d);
                        }
                    }
                }
        std::sort(touched.begin(), touched.end());
        for (const Index r : touched) {
            out.featherRegion.push_back(r);
            out.featherFactor.push_back(1.0 - best[size_t(r)] / width);
            best[size_t(r)] = std::numeric_limits<double>::infinity();
        }
        touched.clear();
        out.featherStart[size_t(p) + 1] = static_cast<Index>(out.featherRegion.size());
    }
}

/// The options and the model regions are learned for, checked before any work.
void checkRegionInput(const Eigen::Ref<const Eigen::MatrixXd>& q, const Model& model,
                      const RegionOptions& options) {
    const Index n = model.points;
    const Index c = model.channels;
    if (options.count < 1 || options.count > n)
        badRegionOption("count must be in [1, " + std::to_string(n) + "], got " +
                        std::to_string(options.count));
    if (!(options.featherFraction >= 0 && options.featherFraction < 1))
        badRegionOption("feather fraction must be in [0, 1), got " + std::to_string(options.featherFraction));
    if (!(options.maxLocalFraction > 0 && options.maxLocalFraction <= 1))
        badRegionOption("largest local fraction must be in (0, 1], got " +
                        std::to_string(options.maxLocalFraction));
    if (!(options.energy > 0 && options.energy <= 1)) badRegionOption("energy must be in (0, 1]");
    if (options.minKeys < 1) badRegionOption("min keys must be >= 1");
    if (options.frameStride < 1)
        badRegionOption("frame stride must be >= 1, got " + std::to_string(options.frameStride));
    if (!(options.keyRadius >= 0)) badRegionOption("key radius must be >= 0");
    if (!(options.basisShare > 0 && options.basisShare <= 1))
        badRegionOption("basis share must be in (0, 1]");
    if (!(options.ratioMargin >= 1)) badRegionOption("ratio margin must be >= 1");
    if (model.sharedChannels)  // its basis has N rows, not N*C; Model::validate refuses the pair too
        throw std::invalid_argument(
            "learnRegions: a model whose channels share the basis has no regions in this version");
    if (q.rows() != n * c) throw std::invalid_argument("learnRegions: q has the wrong row count");
}

/// The points' positions (N x 3): the given ones, else the mean of 3-channel data.
Eigen::MatrixXd pointPositions(const Model& model, const RegionOptions& options) {
    const Index n = model.points;
    const Index c = model.channels;
    Eigen::MatrixXd pos;
    if (options.positions.size() > 0) {
        if (options.positions.rows() != n || options.positions.cols() != 3 || !options.positions.allFinite())
            badRegionOption("positions must be N x 3 finite values (N = " + std::to_string(n) + ")");
        pos = options.positions;
    } else if (c == 3) {
        pos = Eigen::Map<const Eigen::MatrixXd>(model.mean.data(), 3, n).transpose();
    } else {
        badRegionOption("point positions are needed for " + std::to_string(c) + "-channel data (none given)");
    }
    return pos;
}

/// Step 3a: region keys where a region holds fewer than ownKeys of the model's keys:
/// farthest-point sampling over its points, seeded by its most moving point.
void addRegionKeys(const Eigen::Ref<const Eigen::MatrixXd>& q, const Model& model,
                   const RegionOptions& options, const std::vector<Index>& regionOf,
                   const Eigen::MatrixXd& pos, LocalRegions& out) {
    const Index c = model.channels;
    const Index r = Index(out.regions.size());
    std::vector<Index> inside(size_t(r), 0);
    for (const Index p : model.keyPoints) ++inside[size_t(regionOf[size_t(p)])];
    for (Index ri = 0; ri < r; ++ri) {
        const std::vector<Index>& pts = out.regions[size_t(ri)].points;
        const Index need = std::min<Index>(options.ownKeys - inside[size_t(ri)], Index(pts.size()));
        if (need <= 0) continue;
        Index seed = 0;
        double most = -1;
        for (size_t i = 0; i < pts.size(); ++i) {
            const double motion = q.middleRows(pts[i] * c, c).squaredNorm();
            if (motion > most) most = motion, seed = Index(i);
        }
        std::vector<double> nearest(pts.size(), std::numeric_limits<double>::infinity());
        Index next = seed;
        for (Index j = 0; j < need; ++j) {
            out.extraKeyPoints.push_back(pts[size_t(next)]);
            for (size_t i = 0; i < pts.size(); ++i)
                nearest[i] =
                    std::min(nearest[i], (pos.row(pts[i]) - pos.row(pts[size_t(next)])).squaredNorm());
            next = Index(std::max_element(nearest.begin(), nearest.end()) - nearest.begin());
        }
    }
}

/// Step 3: region `ri`'s keys: every key inside it, then the nearest outside ones until it has
/// minKeys, and any within keyRadius of it; sorted.
void chooseRegionKeys(Region& g, Index ri, const Model& model, const LocalRegions& out,
                      const RegionOptions& options, const std::vector<Index>& regionOf,
                      const Eigen::MatrixXd& pos, double diagonal) {
    const Index k = model.keyCount() + Index(out.extraKeyPoints.size());
    std::vector<std::pair<double, Index>> outside;  // (distance to the region's nearest point, key number)
    for (Index key = 0; key < k; ++key) {
        const Index p = out.keyPoint(model, key);
        if (regionOf[size_t(p)] == ri) {
            g.keys.push_back(key);
        } else {
            double d = std::numeric_limits<double>::infinity();
            for (const Index other : g.points) d = std::min(d, (pos.row(p) - pos.row(other)).squaredNorm());
            outside.push_back({std::sqrt(d), key});
        }
    }
    std::sort(outside.begin(), outside.end());
    for (size_t i = 0; i < outside.size() && (Index(g.keys.size()) < options.minKeys ||
                                              outside[i].first <= options.keyRadius * diagonal);
         ++i)
        g.keys.push_back(outside[i].second);
    std::sort(g.keys.begin(), g.keys.end());
}

/// The region's rows of q: its points, then its keys that lie outside it; `keyLocal` gets the
/// position of each key among them. Every `stride`-th frame (column) only.
Eigen::MatrixXd regionRows(const Eigen::Ref<const Eigen::MatrixXd>& q, const Region& g, const Model& model,
                           const LocalRegions& out, Index stride, std::vector<Index>& keyLocal) {
    const Index c = model.channels;
    std::vector<Index> local = g.points;
    for (const Index key : g.keys) {
        const Index p = out.keyPoint(model, key);
        const auto at = std::lower_bound(g.points.begin(), g.points.end(), p);
        if (at != g.points.end() && *at == p) {
            keyLocal.push_back(at - g.points.begin());
        } else {
            keyLocal.push_back(static_cast<Index>(local.size()));
            local.push_back(p);
        }
    }
    const Index frames = (q.cols() + stride - 1) / stride;
    Eigen::MatrixXd qr(Index(local.size()) * c, frames);
    for (size_t i = 0; i < local.size(); ++i)
        for (Index f = 0; f < frames; ++f)
            qr.block(Index(i) * c, f, c, 1) = q.block(local[i] * c, f * stride, c, 1);
    return qr;
}

/// Step 4: the region's thresholds from its calibration (or training) key errors.
void setRegionThresholds(Region& g, const CalibrationStats& cal, double tolerance,
                         const RegionOptions& options) {
    // Decision: a region's blend zone is [eps_min, 1.5 eps_min] (the paper's hand-picked ratio,
    // section 7), narrower than the frame's [eps_min, 2 eps_min]: its bound rests on a few keys
    // and a motion training never saw (the reason a region fails) can exceed the calibrated
    // ratio, so a region that sees any of it should reach the full result sooner.
    g.epsMin = cal.epsMin;
    // A region PM reconstructed exactly on every held-out frame (a part that never moved in
    // training: the back of a head) gets its largest held-out key error as eps_min, which is
    // rounding noise: the same noise on a new frame would fail it through. Any key error under
    // 1e-6 of the tolerance is noise for such a region, so it is the floor.
    if (tolerance > 0 && cal.ratio == 0) g.epsMin = std::max(g.epsMin, 1e-6 * tolerance);
    // The margin (RegionOptions::ratioMargin) on the calibrated bound, not on the noise floor.
    if (tolerance > 0 && cal.ratio > 0) g.epsMin /= options.ratioMargin;
    g.epsMax = 1.5 * g.epsMin;
}

/// Step 4a: region `ri`'s local basis from its rows `qr` (the energy rule, capped by its share of
/// key values) and its key projector; returns the basis over all of qr's rows (its points', then its
/// outside keys'), zero for a region that never moved. `capped`: the cap made it smaller than M.
Eigen::MatrixXd fitRegionBasis(Region& g, Index ri, const Eigen::MatrixXd& qr,
                               const std::vector<Index>& keyLocal, const Model& model,
                               const RegionOptions& options, const SvdOptions& svd, bool& capped) {
    const Index c = model.channels;
    const Index f = qr.cols();
    const Index kc = Index(g.keys.size()) * c;
    const Index cap =
        std::max<Index>(1, std::min({model.basisSize(), Index(options.basisShare * double(kc)), f - 1}));
    SvdOptions o = svd;
    o.seed = svd.seed + 7919u * static_cast<unsigned>(ri + 1);
    const TruncatedSvd local_svd = truncatedSvd(qr, cap, o);
    const double energy = qr.squaredNorm();
    Index m = local_svd.sigma.size() > 0
                  ? basisSizeForEnergy(local_svd.sigma, energy > 0 ? energy : 1.0, options.energy)
                  : 0;
    m = std::clamp<Index>(m, 1, std::max<Index>(1, local_svd.sigma.size()));
    // A region that never moved in training: a zero basis vector reconstructs the mean.
    Eigen::MatrixXd u = local_svd.sigma.size() == 0 ? Eigen::MatrixXd::Zero(qr.rows(), 1)
                                                    : Eigen::MatrixXd(local_svd.u.leftCols(m));
    g.basis = u.topRows(Index(g.points.size()) * c);
    g.keyBasis = gatherKeyRows(u, c, keyLocal);
    capped = m == cap && cap < model.basisSize();
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(g.keyBasis);
    g.projector = cod.pseudoInverse();
    return u;
}

/// Step 4: region `ri`'s local basis, key projector and thresholds, learned from its rows `qr`;
/// true if the cap made the basis smaller than the model's.
bool fitRegion(Region& g, Index ri, const Eigen::MatrixXd& qr, const std::vector<Index>& keyLocal,
               const Model& model, const RegionOptions& options, double tolerance, Index slices,
               const SvdOptions& svd) {
    bool capped = false;
    const Eigen::MatrixXd u = fitRegionBasis(g, ri, qr, keyLocal, model, options, svd, capped);
    const bool moved = u.squaredNorm() > 0;
    CalibrationStats cal;
    if (tolerance > 0 && moved) {
        SvdOptions o = svd;
        o.seed = svd.seed + 7919u * static_cast<unsigned>(ri + 1);
        cal = calibrate(qr, model.channels, keyLocal, g.basisSize(), tolerance, slices, o);
        g.ratio = cal.ratio;
    } else {
        cal = thresholdsFromTraining(qr, u, model.channels, keyLocal, g.projector);
    }
    setRegionThresholds(g, cal, tolerance, options);
    return capped;
}

/// relearnRegions step 2: each region's key numbers in the learned model. A region reads the
/// learned keys inside it, the old region keys (they were placed where it held too few keys), the
/// old keys outside it that are still read (learned keys, region keys), and with `positions` the
/// learned keys within keyRadius of it; old keys that are no longer keys come back only while it
/// holds fewer than training's ownKeys inside, then minKeys in all (RegionOptions' defaults), those
/// inside first, each in the old order. Points that are not learned keys become region keys,
/// appended to out.extraKeyPoints in region order (deterministic).
/// Why not every old key: kept as region keys, they are computed by every checked hit; on the ICT
/// take split of bench/learn_novelty.py (seed 1) all 679 refused 3 more hits in 200 than these 536.
/// Why the learned keys near it: a motion that breaks a region shows first at the keys next to it
/// (RegionOptions::keyRadius); on the same script's --novel takes they cut the points evaluated
/// from 45.7% to 34.8% and from 24.4% to 23.0%, no frame over T either way.
void relearnedRegionKeys(const LocalRegions& old, const Model& oldModel, const Model& learned,
                         const Eigen::MatrixXd& positions, LocalRegions& out) {
    const Index n = learned.points;
    const Index k = learned.keyCount();
    const Index oldK = oldModel.keyCount();
    const RegionOptions defaults;
    std::vector<Index> keyOf(size_t(n), -1), extraOf(size_t(n), -1);
    std::vector<char> oldExtra(size_t(n), 0);
    for (Index j = 0; j < k; ++j) keyOf[size_t(learned.keyPoints[size_t(j)])] = j;
    for (const Index p : old.extraKeyPoints) oldExtra[size_t(p)] = 1;
    const std::vector<Index> regionOf = old.regionOfPoints(n);
    std::vector<std::vector<Index>> inside(old.regions.size());
    for (const Index p : learned.keyPoints) inside[size_t(regionOf[size_t(p)])].push_back(p);
    const double reach =
        positions.size() > 0
            ? defaults.keyRadius * (positions.colwise().maxCoeff() - positions.colwise().minCoeff()).norm()
            : -1.0;
    for (size_t r = 0; r < old.regions.size(); ++r) {
        std::vector<Index> pts, droppedInside, droppedOutside;
        Index own = 0;
        // Each point once (training may give a region a region key at one of the model's keys).
        auto add = [&](Index p, bool in) {
            if (std::find(pts.begin(), pts.end(), p) != pts.end()) return;
            pts.push_back(p);
            own += in;
        };
        for (const Index p : inside[r]) add(p, true);
        for (const Index key : old.regions[r].keys) {
            const Index p = old.keyPoint(oldModel, key);
            const bool in = regionOf[size_t(p)] == Index(r);
            if (keyOf[size_t(p)] >= 0 || oldExtra[size_t(p)] || key >= oldK)
                add(p, in);
            else
                (in ? droppedInside : droppedOutside).push_back(p);
        }
        for (Index j = 0; j < k && reach >= 0; ++j) {  // learned keys near the region (chooseRegionKeys)
            const Index p = learned.keyPoints[size_t(j)];
            if (regionOf[size_t(p)] == Index(r)) continue;
            double nearest = std::numeric_limits<double>::infinity();
            for (const Index q : old.regions[r].points)
                nearest = std::min(nearest, (positions.row(p) - positions.row(q)).squaredNorm());
            if (std::sqrt(nearest) <= reach) add(p, false);
        }
        size_t next = 0;
        for (; next < droppedInside.size() && own < defaults.ownKeys; ++next) add(droppedInside[next], true);
        droppedOutside.insert(droppedOutside.begin(), droppedInside.begin() + std::ptrdiff_t(next),
                              droppedInside.end());
        for (size_t i = 0; i < droppedOutside.size() && Index(pts.size()) < defaults.minKeys; ++i)
            add(droppedOutside[i], false);
        std::sort(pts.begin(), pts.end());
        std::vector<Index>& keys = out.regions[r].keys;
        for (const Index p : pts) {
            if (keyOf[size_t(p)] >= 0) {
                keys.push_back(keyOf[size_t(p)]);
                continue;
            }
            if (extraOf[size_t(p)] < 0) {
                extraOf[size_t(p)] = Index(out.extraKeyPoints.size());
                out.extraKeyPoints.push_back(p);
            }
            keys.push_back(k + extraOf[size_t(p)]);
        }
        std::sort(keys.begin(), keys.end());
    }
}

/// The region's rows of frames `frames` about `mean` (N*C): its points, then its outside keys.
Eigen::MatrixXd centredRegionRows(const Eigen::Ref<const Eigen::MatrixXd>& frames,
                                  const Eigen::VectorXd& mean, const Region& g, const Model& model,
                                  const LocalRegions& out) {
    std::vector<Index> keyLocal;
    Eigen::MatrixXd rows = regionRows(frames, g, model, out, 1, keyLocal);
    keyLocal.clear();
    const Eigen::MatrixXd centre = regionRows(mean, g, model, out, 1, keyLocal);
    rows.colwise() -= centre.col(0);
    return rows;
}

/// relearnRegions step 4: region g's held-out scores under one fold of learn's new frames, appended
/// to `s`: its basis of m vectors from the fold's surrogate rows, as the learned region's comes from
/// every frame's; per held-out frame its key RMS (RegionMultiplier's measure) and the largest
/// error at its own points.
void scoreRegionFold(const Region& g, Index ri, const std::vector<Index>& keyLocal, const Model& learned,
                     const LocalRegions& out, const RegionFold& fold,
                     const Eigen::Ref<const Eigen::MatrixXd>& fresh, const SvdOptions& svd,
                     CalibrationStats& s) {
    const Index c = learned.channels;
    std::vector<Index> local;
    const Eigen::MatrixXd qf = regionRows(fold.basis, g, learned, out, 1, local) * fold.sigma.asDiagonal();
    SvdOptions o = svd;
    o.seed = svd.seed + 7919u * static_cast<unsigned>(ri + 1);
    const TruncatedSvd t = truncatedSvd(qf, std::min<Index>(g.basisSize(), qf.cols()), o);
    if (t.sigma.size() == 0) return;  // the region did not move in this fold's frames
    const Eigen::MatrixXd u = t.u.leftCols(std::min<Index>(g.basisSize(), t.sigma.size()));
    const Eigen::MatrixXd bk = gatherKeyRows(u, c, keyLocal);
    const Eigen::MatrixXd projector =
        Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd>(bk).pseudoInverse();
    const Eigen::MatrixXd h =
        centredRegionRows(fresh.middleCols(fold.first, fold.last - fold.first), fold.mean, g, learned, out);
    const Eigen::MatrixXd hk = gatherKeyRows(h, c, keyLocal);
    const Eigen::MatrixXd b = projector * hk;
    const Index rows = Index(g.points.size()) * c;
    const Eigen::MatrixXd keyResidual = hk - bk * b;
    const Eigen::MatrixXd pointResidual = h.topRows(rows) - u.topRows(rows) * b;
    // The region's key error as the soft cache computes it at run time (the RMS over its keys).
    const Eigen::VectorXd largest = maxPointNormPerColumn(pointResidual, c);
    for (Index j = 0; j < h.cols(); ++j) {
        s.keyRms.push_back(keyErrorOfResidual(keyResidual.col(j), c, KeyErrorNorm::Rms));
        s.maxPointError.push_back(largest[j]);
    }
}

/// relearnRegions steps 3-4 for region ri: basis, projector and thresholds. Returns whether the
/// cap made its basis smaller than M.
bool relearnRegion(Index ri, const Region& was, const Model& learned, LocalRegions& out,
                   const Eigen::Ref<const Eigen::MatrixXd>& basis, const Eigen::VectorXd& sigma,
                   const Eigen::Ref<const Eigen::MatrixXd>& fresh, const std::vector<RegionFold>& folds,
                   const SvdOptions& svd) {
    Region& g = out.regions[size_t(ri)];
    std::vector<Index> keyLocal;
    const Eigen::MatrixXd qr = regionRows(basis, g, learned, out, 1, keyLocal) * sigma.asDiagonal();
    RegionOptions options;  // training's defaults: a model does not store the options it had
    bool capped = false;
    const Eigen::MatrixXd u = fitRegionBasis(g, ri, qr, keyLocal, learned, options, svd, capped);
    const double t = learned.tolerance;
    CalibrationStats cal;
    if (t > 0) {
        if (u.squaredNorm() > 0)
            for (const RegionFold& fold : folds)
                scoreRegionFold(g, ri, keyLocal, learned, out, fold, fresh, svd, cal);
        if (!cal.keyRms.empty()) setThresholds(cal, t, CalibrationRule::MaxRatio, 0.9);
        g.ratio = std::max(cal.ratio, was.ratio);
        cal.ratio = g.ratio;
        cal.epsMin = g.ratio > 0 ? t / g.ratio : was.epsMin;  // never moved: the old noise floor
        // The old margin, recovered from its thresholds (setRegionThresholds: eps_min = T / (margin r)).
        if (was.ratio > 0 && was.epsMin > 0)
            options.ratioMargin = std::max(1.0, t / (was.ratio * was.epsMin));
    } else {
        cal = thresholdsFromTraining(centredRegionRows(fresh, learned.mean, g, learned, out), u,
                                     learned.channels, keyLocal, g.projector);
        cal.epsMin = std::max(cal.epsMin, was.epsMin);
    }
    setRegionThresholds(g, cal, t, options);
    return capped;
}

}  // namespace

Eigen::MatrixXd rotatedLoadings(const Model& model) {
    const Index n = model.points;
    const Index c = model.channels;
    const Index j = std::min<Index>(24, model.basisSize());
    Eigen::MatrixXd loadings = model.basis.leftCols(j) * model.singularValues.head(j).asDiagonal();
    VarimaxOptions vo;
    vo.maxIterations = 100;
    vo.tolerance = 1e-7;
    const Eigen::MatrixXd rotated = j > 1 ? varimax(loadings, vo).rotated : loadings;
    Eigen::MatrixXd norms(n, j);
    for (Index p = 0; p < n; ++p)
        for (Index f = 0; f < j; ++f) norms(p, f) = rotated.block(p * c, f, c, 1).norm();
    return norms;
}

LocalRegions learnRegions(const Eigen::Ref<const Eigen::MatrixXd>& q, const Model& model,
                          const RegionOptions& options, double tolerance, Index slices, const SvdOptions& svd,
                          std::vector<std::string>* notes) {
    const Index n = model.points;
    checkRegionInput(q, model, options);
    const Eigen::MatrixXd pos = pointPositions(model, options);
    const double diagonal = (pos.colwise().maxCoeff() - pos.colwise().minCoeff()).norm();
    const double scale = diagonal > 0 ? std::sqrt(double(options.count)) / diagonal : 1.0;

    // Steps 1-2: loading patterns and k-means.
    const Eigen::MatrixXd pattern = loadingPatterns(model);
    Eigen::MatrixXd features(n, 3 + pattern.cols());
    features.leftCols(3) = pos * scale;
    features.rightCols(pattern.cols()) = pattern;
    const std::vector<Index> regionOf = kmeans(features, options.count, options.kmeansIterations);
    const Index r = *std::max_element(regionOf.begin(), regionOf.end()) + 1;
    if (notes && r < options.count)
        notes->push_back("regions: " + std::to_string(options.count) + " wanted, " + std::to_string(r) +
                         " non-empty clusters");

    LocalRegions out;
    out.maxLocalFraction = options.maxLocalFraction;
    out.featherWidth = options.featherFraction * diagonal;
    out.regions.resize(size_t(r));
    for (Index p = 0; p < n; ++p) out.regions[size_t(regionOf[size_t(p)])].points.push_back(p);
    if (options.ownKeys > 0) addRegionKeys(q, model, options, regionOf, pos, out);

    // Steps 3-4: keys, local basis, projector, thresholds; the regions are independent, so they
    // are learned on every core (each region's result does not depend on the thread count).
    std::atomic<Index> next{0}, smallBases{0};
    auto learnSome = [&] {
        for (Index ri = next++; ri < r; ri = next++) {
            Region& g = out.regions[size_t(ri)];
            chooseRegionKeys(g, ri, model, out, options, regionOf, pos, diagonal);
            std::vector<Index> keyLocal;  // position of each key in the region's rows
            const Eigen::MatrixXd qr = regionRows(q, g, model, out, options.frameStride, keyLocal);
            if (fitRegion(g, ri, qr, keyLocal, model, options, tolerance, slices, svd)) ++smallBases;
        }
    };
    runOnEveryCore(learnSome, r);
    if (notes && smallBases > 0) notes->push_back(cappedBasesNote(smallBases, r));

    // Step 5.
    featherEntries(pos, regionOf, out.featherWidth, out);
    out.validate(model);
    return out;
}

LocalRegions relearnRegions(const LocalRegions& old, const Model& oldModel, const Model& learned,
                            const Eigen::Ref<const Eigen::MatrixXd>& basis, const Eigen::VectorXd& sigma,
                            const Eigen::Ref<const Eigen::MatrixXd>& fresh,
                            const std::vector<RegionFold>& folds, const SvdOptions& svd,
                            const Eigen::MatrixXd& positions, std::vector<std::string>* notes) {
    const Index rows = learned.points * learned.channels;
    if (oldModel.points != learned.points || oldModel.channels != learned.channels || basis.rows() != rows ||
        basis.cols() != sigma.size() || fresh.rows() != rows ||
        (positions.size() > 0 && (positions.rows() != learned.points || positions.cols() != 3)))
        throw std::invalid_argument("relearnRegions: the models, the state and the frames differ in size");
    old.validate(oldModel);
    LocalRegions out;
    out.maxLocalFraction = old.maxLocalFraction;
    out.featherWidth = old.featherWidth;
    out.featherStart = old.featherStart;
    out.featherRegion = old.featherRegion;
    out.featherFactor = old.featherFactor;
    out.regions.resize(old.regions.size());
    for (size_t r = 0; r < old.regions.size(); ++r) out.regions[r].points = old.regions[r].points;
    relearnedRegionKeys(old, oldModel, learned, positions, out);
    const Index r = out.regionCount();
    std::atomic<Index> next{0}, smallBases{0};
    runOnEveryCore(
        [&] {
            for (Index ri = next++; ri < r; ri = next++)
                if (relearnRegion(ri, old.regions[size_t(ri)], learned, out, basis, sigma, fresh, folds, svd))
                    ++smallBases;
        },
        r);
    if (notes && smallBases > 0) notes->push_back(cappedBasesNote(smallBases, r));
    out.validate(learned);
    return out;
}

}  // namespace pmsc
