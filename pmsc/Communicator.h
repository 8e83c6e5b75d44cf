// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <cstddef>
#include <vector>

namespace pmsc {

/// The few collectives training needs when the rows of the training matrix are split across
/// processes. pmsc/ stays free of MPI: this is the whole interface; the single-process
/// implementation is below, the MPI one lives in cli/mpi/ and is built only when MPI is found.
///
/// Every call is collective: all ranks make it, in the same order, with the same counts. Results
/// are identical on every rank (bit for bit), so ranks that run the same replicated code on them
/// (an F x F eigensolver, the key set) take the same decisions.
class Communicator {
public:
    virtual ~Communicator() = default;
    virtual int rank() const = 0;
    virtual int size() const = 0;
    /// Element-wise sum over ranks, in place. Decision: reduced in rank order on rank 0 and
    /// broadcast (not an allreduce), so every rank holds the same bits whatever algorithm the MPI
    /// library picks.
    virtual void sum(double* values, std::size_t count) = 0;
    /// Every rank's `count` values, concatenated in rank order, on every rank.
    virtual void allGather(const double* local, std::size_t count, std::vector<double>& all) = 0;
    /// Rank `root`'s values replace everyone's.
    virtual void broadcast(double* values, std::size_t count, int root) = 0;
    /// Every rank's values (counts may differ) concatenated in rank order on `root`; `all` is left
    /// empty on the other ranks.
    virtual void gather(const double* local, std::size_t count, std::vector<double>& all, int root) = 0;
};

/// One process: every collective is the identity.
class SingleProcess final : public Communicator {
public:
    int rank() const override { return 0; }
    int size() const override { return 1; }
    void sum(double*, std::size_t) override {}
    void allGather(const double* local, std::size_t count, std::vector<double>& all) override {
        all.assign(local, local + count);
    }
    void broadcast(double*, std::size_t, int) override {}
    void gather(const double* local, std::size_t count, std::vector<double>& all, int) override {
        all.assign(local, local + count);
    }
};

/// Largest value over ranks, element-wise; a NaN anywhere wins (a NaN residual is an unusable
/// frame, not a small error, as in maxPointNorm).
void maxOverRanks(Communicator& comm, double* values, std::size_t count);

/// The (value, index) pair with the largest value over ranks; ties go to the lower index, as in
/// the single-process scans (strict > from the lowest index). index -1 = "no candidate" and
/// loses to any candidate. Returns the winning pair on every rank.
struct ValueIndex {
    double value;
    long long index;
};
ValueIndex argMaxOverRanks(Communicator& comm, ValueIndex local);

}  // namespace pmsc
