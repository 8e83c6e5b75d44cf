// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Communicator.h"

#include <memory>
#include <string>

namespace pmsc::cli {

/// The MPI world of a `pmsc` started by an MPI launcher. Decision: MPI is initialised
/// only when the environment says a launcher started this process (mpirun: OMPI_COMM_WORLD_SIZE;
/// srun --mpi=pmix or any PMIx launcher: PMIX_RANK; PMI-2 launchers: PMI_SIZE), so a plain
/// `pmsc train` never touches MPI and needs no mpirun. The implementation is MpiWorld.cpp when
/// CMake found MPI and NoMpi.cpp otherwise.
class MpiWorld : public Communicator {
public:
    /// Ends MPI (MPI_Finalize) when the last user is done.
    ~MpiWorld() override = default;
    /// Stops every rank at once (MPI_Abort) with this exit code: for an error one rank saw alone
    /// (a NaN in its rows, a failed read) while the others wait in a collective.
    [[noreturn]] virtual void abort(int code) = 0;
};

/// What the environment says about how this process was started.
struct LaunchInfo {
    bool launchedByMpi = false;  ///< an MPI launcher's variables are set
    int slurmTasks = 1;          ///< SLURM_STEP_NUM_TASKS (1 when not in a Slurm step)
    std::string launcher;        ///< "mpirun", "pmix", "pmi2" or ""
};
LaunchInfo launchInfo();

/// The MPI world if this process was started by an MPI launcher, else null (one process).
/// @throws pmsc::InputError when started as several Slurm tasks without an MPI launcher
///         (srun without --mpi=pmix: each task would train alone) or by a launcher while this
///         pmsc was built without MPI.
std::unique_ptr<MpiWorld> joinMpiIfLaunched();

/// "MPI (Open MPI 4.1.4)" or "no MPI": for --help and the summary.
std::string mpiDescription();

}  // namespace pmsc::cli
