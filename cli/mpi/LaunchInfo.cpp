#include "cli/mpi/MpiLaunch.h"

#include <cstdlib>
#include <string>

namespace pmsc::cli {

LaunchInfo launchInfo() {
    LaunchInfo info;
    auto set = [](const char* name) {
        const char* v = std::getenv(name);
        return v != nullptr && *v != '\0';
    };
    if (set("OMPI_COMM_WORLD_SIZE"))
        info.launcher = "mpirun";
    else if (set("PMIX_RANK"))
        info.launcher = "pmix";
    else if (set("PMI_SIZE") || set("PMI_RANK"))
        info.launcher = "pmi2";
    info.launchedByMpi = !info.launcher.empty();
    if (const char* t = std::getenv("SLURM_STEP_NUM_TASKS")) {
        const int n = std::atoi(t);
        if (n > 0) info.slurmTasks = n;
    }
    return info;
}

}  // namespace pmsc::cli
