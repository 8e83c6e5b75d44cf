#include "pmsc/Communicator.h"

namespace pmsc {

void maxOverRanks(Communicator& comm, double* values, std::size_t count) {
    if (comm.size() == 1 || count == 0) return;
    std::vector<double> all;
    comm.allGather(values, count, all);
    for (std::size_t i = 0; i < count; ++i) {
        double best = values[i];
        for (int r = 0; r < comm.size(); ++r) {
            const double v = all[static_cast<std::size_t>(r) * count + i];
            if (!(v <= best)) best = v;  // NaN wins
        }
        values[i] = best;
    }
}

ValueIndex argMaxOverRanks(Communicator& comm, ValueIndex local) {
    if (comm.size() == 1) return local;
    // The index travels as a double: exact below 2^53, far beyond any point count.
    const double mine[2] = {local.value, static_cast<double>(local.index)};
    std::vector<double> all;
    comm.allGather(mine, 2, all);
    ValueIndex best{0.0, -1};
    for (int r = 0; r < comm.size(); ++r) {
        const ValueIndex c{all[2 * static_cast<std::size_t>(r)],
                           static_cast<long long>(all[2 * static_cast<std::size_t>(r) + 1])};
        if (c.index < 0) continue;
        if (best.index < 0 || c.value > best.value || (c.value == best.value && c.index < best.index))
            best = c;
    }
    return best;
}

}  // namespace pmsc
