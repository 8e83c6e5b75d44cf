#include "cli/Interrupt.h"

#include <csignal>
#include <ctime>

namespace pmsc::cli {

namespace {

std::atomic<bool> gInterrupted{false};
std::atomic<long long> gFirstSignalNs{0};
static_assert(std::atomic<bool>::is_always_lock_free, "the signal handler needs a lock-free flag");
static_assert(std::atomic<long long>::is_always_lock_free, "the signal handler needs a lock-free clock");

// A stop request often arrives twice at once: `timeout`, and supervisors that signal the
// whole process group, send the signal to the child and then to its group. Only a second
// signal at least this long after the first is someone insisting (a second Ctrl-C).
constexpr long long kRepeatNs = 1'000'000'000;

long long monotonicNs() {
    timespec t{};
    ::clock_gettime(CLOCK_MONOTONIC, &t);  // async-signal-safe
    return static_cast<long long>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

extern "C" void onSignal(int signal) {
    const long long now = monotonicNs();
    if (!gInterrupted.exchange(true)) {  // the first request: stop at the next progress check
        gFirstSignalNs.store(now);
        return;
    }
    if (now - gFirstSignalNs.load() < kRepeatNs) return;  // the same request delivered twice
    std::signal(signal, SIG_DFL);                         // asked again: stop now
    std::raise(signal);
}

}  // namespace

void installInterruptHandler() {
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
}

const std::atomic<bool>& interruptFlag() { return gInterrupted; }

bool interrupted() { return gInterrupted.load(std::memory_order_relaxed); }

}  // namespace pmsc::cli
