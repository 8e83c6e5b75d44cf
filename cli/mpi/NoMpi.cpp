// The MPI entry points of a pmsc built without MPI (CMake did not find it): one process always.
#include "cli/mpi/MpiLaunch.h"
#include "pmsc/Errors.h"

namespace pmsc::cli {

std::unique_ptr<MpiWorld> joinMpiIfLaunched() {
    const LaunchInfo info = launchInfo();
    if (info.launchedByMpi || info.slurmTasks > 1) {
        throw InputError("train: started by an MPI launcher (" +
                         (info.launcher.empty() ? std::string("srun") : info.launcher) +
                         "), but this pmsc was built without MPI (install libopenmpi-dev and rebuild)");
    }
    return nullptr;
}

std::string mpiDescription() { return "built without MPI"; }

}  // namespace pmsc::cli
