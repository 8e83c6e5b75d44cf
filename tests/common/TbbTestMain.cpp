// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// The engine tests' main: runs every test, then waits for oneTBB's worker threads to end before
// the program does. Without the wait a worker whose scheduler was released by a test's last
// thread ends while the main thread is already inside exit(), running libtbb's and
// ThreadSanitizer's exit handlers; ThreadSanitizer (which cannot see into the uninstrumented
// libtbb) then now and then reports that worker as "finished with ignores enabled" and fails a
// test that passed. Ending the workers here, in a program still running normally, is oneTBB's
// documented way to shut the scheduler down (tbb::finalize).
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstdio>
#include <new>

int main(int argc, char** argv) {
    tbb::task_scheduler_handle scheduler{tbb::attach{}};
    ::testing::InitGoogleTest(&argc, argv);
    const int result = RUN_ALL_TESTS();
    if (!tbb::finalize(scheduler, std::nothrow))
        std::fprintf(stderr, "pmsc_engine_tests: oneTBB's workers were still busy at exit\n");
    return result;
}
