#include "pmsc/Regions.h"

#include "pmsc/Model.h"
#include "pmsc/ModelSections.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace pmsc {

namespace {

[[noreturn]] void invalidRegions(const std::string& what) { throw std::invalid_argument("regions: " + what); }

bool ascendingUnique(const std::vector<Index>& v) {
    for (size_t i = 1; i < v.size(); ++i)
        if (v[i] <= v[i - 1]) return false;
    return true;
}

}  // namespace

std::vector<Index> LocalRegions::regionOfPoints(Index n) const {
    std::vector<Index> of(static_cast<size_t>(n), -1);
    for (Index r = 0; r < regionCount(); ++r)
        for (const Index p : regions[size_t(r)].points) of[size_t(p)] = r;
    return of;
}

Index LocalRegions::keyPoint(const Model& model, Index key) const {
    const Index k = model.keyCount();
    return key < k ? model.keyPoints[size_t(key)] : extraKeyPoints[size_t(key - k)];
}

std::vector<Index> LocalRegions::failSet(Index r) const {
    std::vector<Index> out = regions[size_t(r)].points;
    const Index n = static_cast<Index>(featherStart.size()) - 1;
    for (Index p = 0; p < n; ++p) {
        for (Index e = featherStart[size_t(p)]; e < featherStart[size_t(p) + 1]; ++e) {
            if (featherRegion[size_t(e)] == r) out.push_back(p);
        }
    }
    return out;
}

void LocalRegions::validate(const Model& model) const {
    const Index n = model.points;
    const Index c = model.channels;
    const Index k = model.keyCount() + static_cast<Index>(extraKeyPoints.size());
    if (regions.empty()) invalidRegions("no regions");
    for (const Index p : extraKeyPoints)
        if (p < 0 || p >= n)
            invalidRegions("region key point " + std::to_string(p) + " outside [0, " + std::to_string(n) +
                           ")");
    if (!std::isfinite(featherWidth) || featherWidth < 0)
        invalidRegions("feather width must be finite and >= 0, got " + std::to_string(featherWidth));
    if (!(maxLocalFraction > 0 && maxLocalFraction <= 1))
        invalidRegions("largest local fraction must be in (0, 1], got " + std::to_string(maxLocalFraction));
    std::vector<char> seen(static_cast<size_t>(n), 0);
    Index covered = 0;
    for (Index r = 0; r < regionCount(); ++r) {
        const Region& g = regions[size_t(r)];
        const std::string name = "region " + std::to_string(r) + ": ";
        if (g.points.empty()) invalidRegions(name + "no points");
        if (!ascendingUnique(g.points)) invalidRegions(name + "points not ascending and unique");
        for (const Index p : g.points) {
            if (p < 0 || p >= n)
                invalidRegions(name + "point " + std::to_string(p) + " outside [0, " + std::to_string(n) +
                               ")");
            if (seen[size_t(p)]++) invalidRegions(name + "point " + std::to_string(p) + " is in two regions");
            ++covered;
        }
        if (g.keys.empty()) invalidRegions(name + "no keys");
        if (!ascendingUnique(g.keys)) invalidRegions(name + "keys not ascending and unique");
        if (g.keys.front() < 0 || g.keys.back() >= k)
            invalidRegions(name + "key number outside [0, " + std::to_string(k) + ")");
        const Index m = g.basis.cols();
        const Index rows = static_cast<Index>(g.points.size()) * c;
        const Index kc = static_cast<Index>(g.keys.size()) * c;
        if (m < 1) invalidRegions(name + "empty basis");
        if (g.basis.rows() != rows)
            invalidRegions(name + "basis has " + std::to_string(g.basis.rows()) + " rows, expected " +
                           std::to_string(rows));
        if (g.keyBasis.rows() != kc || g.keyBasis.cols() != m)
            invalidRegions(name + "key basis is not " + std::to_string(kc) + " x " + std::to_string(m));
        if (g.projector.rows() != m || g.projector.cols() != kc)
            invalidRegions(name + "projector is not " + std::to_string(m) + " x " + std::to_string(kc));
        if (!g.basis.allFinite() || !g.keyBasis.allFinite() || !g.projector.allFinite())
            invalidRegions(name + "NaN or Inf in its basis or projector");
        if (!std::isfinite(g.epsMin) || !std::isfinite(g.epsMax) || g.epsMin < 0 || g.epsMax < g.epsMin)
            invalidRegions(name + "thresholds must satisfy 0 <= eps_min <= eps_max, got [" +
                           std::to_string(g.epsMin) + ", " + std::to_string(g.epsMax) + "]");
        if (!std::isfinite(g.ratio) || g.ratio < 0)
            invalidRegions(name + "calibration ratio must be finite and >= 0");
    }
    if (covered != n)
        invalidRegions("the regions cover " + std::to_string(covered) + " of the " + std::to_string(n) +
                       " points");
    if (static_cast<Index>(featherStart.size()) != n + 1)
        invalidRegions("feather index has " + std::to_string(featherStart.size()) +
                       " entries, expected N+1 = " + std::to_string(n + 1));
    if (featherStart.front() != 0 || featherStart.back() != static_cast<Index>(featherRegion.size()) ||
        featherRegion.size() != featherFactor.size())
        invalidRegions("feather index does not match its " + std::to_string(featherRegion.size()) +
                       " entries");
    const std::vector<Index> of = regionOfPoints(n);
    for (Index p = 0; p < n; ++p) {
        if (featherStart[size_t(p) + 1] < featherStart[size_t(p)])
            invalidRegions("feather index not ascending");
        for (Index e = featherStart[size_t(p)]; e < featherStart[size_t(p) + 1]; ++e) {
            const Index r = featherRegion[size_t(e)];
            const double f = featherFactor[size_t(e)];
            if (r < 0 || r >= regionCount() || r == of[size_t(p)])
                invalidRegions("point " + std::to_string(p) + " has a feather entry for region " +
                               std::to_string(r));
            if (!(f > 0 && f <= 1))
                invalidRegions("point " + std::to_string(p) + " has feather factor " + std::to_string(f) +
                               " outside (0, 1]");
        }
    }
}

// --- the "REGIONS" section ---------------------------------------------------------------------
//
//   u64 R, f64 feather width, f64 largest local fraction
//   R times: u64 points P, u64 keys Kr, u64 M_r, f64 eps_min, f64 eps_max, f64 ratio,
//            u64[P] points, u64[Kr] key numbers, f64[P*C*M_r] basis, f64[Kr*C*M_r] key basis,
//            f64[M_r*Kr*C] projector (matrices column-major)
//   u64 E feather entries, u64[N+1] feather start, u64[E] regions, f64[E] factors
//   only when the model has region keys: u64 X region keys, u64[X] their points (a region's key
//   numbers K .. K+X-1 name them). A section without them ends
//   after the factors and is read as a model without region keys.

namespace {

bool regionsPresent(const Model& model) { return model.regions.has_value(); }

void encodeRegions(const Model& model, ByteWriter& out) {
    const LocalRegions& regions = *model.regions;
    out.index(regions.regionCount());
    out.f64(regions.featherWidth);
    out.f64(regions.maxLocalFraction);
    for (const Region& g : regions.regions) {
        out.index(static_cast<Index>(g.points.size()));
        out.index(static_cast<Index>(g.keys.size()));
        out.index(g.basisSize());
        out.f64(g.epsMin);
        out.f64(g.epsMax);
        out.f64(g.ratio);
        out.indices(g.points);
        out.indices(g.keys);
        out.doubles(g.basis.data(), static_cast<size_t>(g.basis.size()));
        out.doubles(g.keyBasis.data(), static_cast<size_t>(g.keyBasis.size()));
        out.doubles(g.projector.data(), static_cast<size_t>(g.projector.size()));
    }
    out.index(static_cast<Index>(regions.featherRegion.size()));
    out.indices(regions.featherStart);
    out.indices(regions.featherRegion);
    out.doubles(regions.featherFactor.data(), regions.featherFactor.size());
    if (!regions.extraKeyPoints.empty()) {
        out.index(static_cast<Index>(regions.extraKeyPoints.size()));
        out.indices(regions.extraKeyPoints);
    }
}

void decodeRegions(ByteReader& in, Model& model) {
    const auto n = static_cast<std::uint64_t>(model.points);
    const auto c = static_cast<std::uint64_t>(model.channels);
    const auto k = static_cast<std::uint64_t>(model.keyCount());
    LocalRegions regions;
    // Each region takes at least its 48-byte header: a count that cannot fit is caught here.
    const std::uint64_t count = in.count("region count", 48);
    if (count == 0 || count > n) in.fail("region count " + std::to_string(count) + " outside [1, N]");
    regions.featherWidth = in.finite("feather width");
    regions.maxLocalFraction = in.finite("largest local fraction");
    regions.regions.resize(count);
    for (std::uint64_t r = 0; r < count; ++r) {
        Region& g = regions.regions[r];
        const std::string name = "region " + std::to_string(r);
        const std::uint64_t points = in.count(name + " point count", 8);
        const std::uint64_t keys = in.count(name + " key count", 8);
        const std::uint64_t m = in.u64(name + " basis size");
        if (points > n || keys > k + n || m == 0 || m > points * c)
            in.fail(name + ": sizes out of range (points " + std::to_string(points) + ", keys " +
                    std::to_string(keys) + ", basis " + std::to_string(m) + ")");
        g.epsMin = in.finite(name + " eps_min");
        g.epsMax = in.finite(name + " eps_max");
        g.ratio = in.finite(name + " ratio");
        g.points = in.indices(points, n, name + " point");
        // Key numbers may name region keys (K .. K+X-1, X <= N, read at the end): validate()
        // checks them against X once it is known.
        g.keys = in.indices(keys, k + n, name + " key number");
        // Sizes are bounded by N and K above, so these products cannot wrap; doubles() checks
        // each against the bytes left before copying.
        std::uint64_t basisValues = 0;
        if (__builtin_mul_overflow(points * c, m, &basisValues)) in.fail(name + ": basis too large");
        in.require(basisValues, 8, name + " basis");
        g.basis.resize(static_cast<Index>(points * c), static_cast<Index>(m));
        in.doubles(g.basis.data(), points * c * m, name + " basis");
        in.require(keys * c, 8 * m, name + " key basis");
        g.keyBasis.resize(static_cast<Index>(keys * c), static_cast<Index>(m));
        in.doubles(g.keyBasis.data(), keys * c * m, name + " key basis");
        g.projector.resize(static_cast<Index>(m), static_cast<Index>(keys * c));
        in.doubles(g.projector.data(), keys * c * m, name + " projector");
    }
    const std::uint64_t entries = in.count("feather entry count", 16);
    regions.featherStart = in.indices(n + 1, entries + 1, "feather start");
    regions.featherRegion = in.indices(entries, count, "feather region");
    regions.featherFactor.resize(entries);
    in.doubles(regions.featherFactor.data(), entries, "feather factor");
    if (in.remaining() > 0) {
        const std::uint64_t extra = in.count("region key count", 8);
        if (extra == 0 || extra > n) in.fail("region key count " + std::to_string(extra) + " outside [1, N]");
        regions.extraKeyPoints = in.indices(extra, n, "region key point");
    }
    try {
        regions.validate(model);
    } catch (const std::invalid_argument& e) {
        in.fail(std::string("inconsistent: ") + e.what());
    }
    model.regions = std::move(regions);
}

}  // namespace

ModelSectionCodec regionsSectionCodec() {
    return {{'R', 'E', 'G', 'I', 'O', 'N', 'S', '\0'}, &regionsPresent, &encodeRegions, &decodeRegions};
}

}  // namespace pmsc
