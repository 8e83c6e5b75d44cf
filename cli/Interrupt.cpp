#include "cli/Interrupt.h"

#include <csignal>

namespace pmsc::cli {

namespace {

std::atomic<bool> gInterrupted{false};
static_assert(std::atomic<bool>::is_always_lock_free, "the signal handler needs a lock-free flag");

extern "C" void onSignal(int signal) {
    gInterrupted.store(true, std::memory_order_relaxed);
    std::signal(signal, SIG_DFL);
}

}  // namespace

void installInterruptHandler() {
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
}

const std::atomic<bool>& interruptFlag() { return gInterrupted; }

bool interrupted() { return gInterrupted.load(std::memory_order_relaxed); }

}  // namespace pmsc::cli
