// The MPI Communicator: the only translation unit that includes mpi.h.
#include "cli/mpi/MpiLaunch.h"
#include "pmsc/Errors.h"

#include <mpi.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

namespace pmsc::cli {

namespace {

void check(int status, const char* what) {
    if (status != MPI_SUCCESS) {
        char text[MPI_MAX_ERROR_STRING];
        int length = 0;
        MPI_Error_string(status, text, &length);
        throw std::runtime_error(std::string("MPI: ") + what +
                                 " failed: " + std::string(text, static_cast<std::size_t>(length)));
    }
}

int asInt(std::size_t count) {
    if (count > static_cast<std::size_t>(INT32_MAX))
        throw std::runtime_error("MPI: message of more than 2^31 values");
    return static_cast<int>(count);
}

class World final : public MpiWorld {
public:
    World() {
        int provided = 0;
        check(MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided), "MPI_Init_thread");
        MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
        MPI_Comm_size(MPI_COMM_WORLD, &size_);
    }
    ~World() override { MPI_Finalize(); }
    int rank() const override { return rank_; }
    int size() const override { return size_; }

    void sum(double* values, std::size_t count) override {
        if (count == 0) return;
        // Reduced on rank 0, then broadcast: the same bits on every rank (Communicator.h).
        std::vector<double> total(rank_ == 0 ? count : 0);
        check(MPI_Reduce(values, rank_ == 0 ? total.data() : nullptr, asInt(count), MPI_DOUBLE, MPI_SUM, 0,
                         MPI_COMM_WORLD),
              "MPI_Reduce");
        if (rank_ == 0) std::copy(total.begin(), total.end(), values);
        broadcast(values, count, 0);
    }
    void allGather(const double* local, std::size_t count, std::vector<double>& all) override {
        all.resize(count * static_cast<std::size_t>(size_));
        check(MPI_Allgather(local, asInt(count), MPI_DOUBLE, all.data(), asInt(count), MPI_DOUBLE,
                            MPI_COMM_WORLD),
              "MPI_Allgather");
    }
    void broadcast(double* values, std::size_t count, int root) override {
        if (count == 0) return;
        check(MPI_Bcast(values, asInt(count), MPI_DOUBLE, root, MPI_COMM_WORLD), "MPI_Bcast");
    }
    void gather(const double* local, std::size_t count, std::vector<double>& all, int root) override {
        int mine = asInt(count);
        std::vector<int> counts(rank_ == root ? static_cast<std::size_t>(size_) : 0);
        check(MPI_Gather(&mine, 1, MPI_INT, counts.data(), 1, MPI_INT, root, MPI_COMM_WORLD), "MPI_Gather");
        std::vector<int> offsets(counts.size());
        std::size_t total = 0;
        for (std::size_t r = 0; r < counts.size(); ++r) {
            offsets[r] = asInt(total);
            total += static_cast<std::size_t>(counts[r]);
        }
        all.assign(rank_ == root ? total : 0, 0.0);
        check(MPI_Gatherv(local, mine, MPI_DOUBLE, all.data(), counts.data(), offsets.data(), MPI_DOUBLE,
                          root, MPI_COMM_WORLD),
              "MPI_Gatherv");
    }
    [[noreturn]] void abort(int code) override {
        std::fflush(stdout);
        std::fflush(stderr);
        MPI_Abort(MPI_COMM_WORLD, code);
        std::_Exit(code);
    }

private:
    int rank_ = 0;
    int size_ = 1;
};

}  // namespace

std::unique_ptr<MpiWorld> joinMpiIfLaunched() {
    const LaunchInfo info = launchInfo();
    if (!info.launchedByMpi) {
        if (info.slurmTasks > 1) {
            throw InputError("train: started as " + std::to_string(info.slurmTasks) +
                             " Slurm tasks without an MPI launcher: each would train alone; use "
                             "'srun --mpi=pmix' or mpirun inside the allocation");
        }
        return nullptr;
    }
    return std::make_unique<World>();
}

std::string mpiDescription() {
    char version[MPI_MAX_LIBRARY_VERSION_STRING];
    int length = 0;
    MPI_Get_library_version(version, &length);
    std::string text(version, static_cast<std::size_t>(length));
    const auto comma = text.find(',');
    return "MPI (" + text.substr(0, comma) + ")";
}

}  // namespace pmsc::cli
