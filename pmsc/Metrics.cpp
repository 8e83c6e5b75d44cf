// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "pmsc/Metrics.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace pmsc {

double maxPointError(const double* a, const double* b, Index points, Index channels, Index* where) {
    double worst = 0;
    Index at = 0;
    for (Index p = 0; p < points; ++p) {
        double sum = 0;
        for (Index c = 0; c < channels; ++c) {
            const double d = a[p * channels + c] - b[p * channels + c];
            sum += d * d;
        }
        if (sum > worst) {
            worst = sum;
            at = p;
        }
    }
    if (where) *where = at;
    return std::sqrt(worst);
}

namespace {

// The nearest-rank q-percentile of sorted, non-empty values.
double rankOf(const std::vector<double>& sorted, double q) {
    const std::size_t rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(sorted.size())));
    return sorted[std::min(sorted.size() - 1, rank == 0 ? 0 : rank - 1)];
}

}  // namespace

double percentile(std::vector<double> values, double q) {
    if (!(q >= 0 && q <= 1))
        throw std::invalid_argument("percentile: q = " + std::to_string(q) + " outside [0, 1]");
    if (values.empty()) return 0;
    std::sort(values.begin(), values.end());
    return rankOf(values, q);
}

Percentiles percentiles(std::vector<double> values) {
    Percentiles p;
    if (values.empty()) return p;
    std::sort(values.begin(), values.end());
    p.p50 = rankOf(values, 0.5);
    p.p99 = rankOf(values, 0.99);
    p.p995 = rankOf(values, 0.995);
    p.max = values.back();
    return p;
}

}  // namespace pmsc
