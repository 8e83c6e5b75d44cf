// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

// The engine's ThreadSanitizer annotations, in their own header so Engine.cpp reads as
// the graph it builds. Private to engine/ (not installed); included by Engine.cpp only.

#include <oneapi/tbb/task_arena.h>
#include <oneapi/tbb/task_scheduler_observer.h>

#include <atomic>
#include <chrono>
#include <thread>

namespace pmsc::engine {

// ThreadSanitizer and the uninstrumented libtbb (Debian's build). TSan cannot see libtbb's
// synchronization, so (1) every hand-over of a frame slot from one node body to the next looks
// like a race, and (2) so does TBB's own bookkeeping in its headers (task objects recycled by its
// allocator, buffer nodes' arrays). Suppressing by pattern does not work: TSan matches a
// suppression against every frame of a stack, and every node body runs under TBB frames, so a
// pattern broad enough for (2) hides races in our bodies too. Instead, in TSan builds only:
//  - handOver/takeOver state the flow graph's real happens-before edges, one per message: the
//    sender releases the slot after its last write, the receiver acquires it before its first
//    read. Branches of one fail-through do NOT release the slot to each other (they meet through
//    the chunksLeft atomic), so a race between two branches is still reported.
//  - TBB's own code on the arena's threads runs with TSan's access checks off (an arena
//    observer), and every node body and sink call turns them back on (CheckedScope), so the
//    engine's and the user's code (evaluators, sinks) is checked, TBB's internals are not.
// Everything here compiles to nothing in other builds.
#if defined(__SANITIZE_THREAD__)
extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);
extern "C" void AnnotateIgnoreReadsBegin(const char* file, int line);
extern "C" void AnnotateIgnoreReadsEnd(const char* file, int line);
extern "C" void AnnotateIgnoreWritesBegin(const char* file, int line);
extern "C" void AnnotateIgnoreWritesEnd(const char* file, int line);
inline void handOver(const void* p) { __tsan_release(const_cast<void*>(p)); }
inline void takeOver(const void* p) { __tsan_acquire(const_cast<void*>(p)); }

inline thread_local bool tIgnoring = false;  // this thread's accesses are not checked (TBB code runs)
inline void setIgnoring(bool on) {
    if (on == tIgnoring) return;
    if (on) {
        AnnotateIgnoreReadsBegin(__FILE__, __LINE__);
        AnnotateIgnoreWritesBegin(__FILE__, __LINE__);
    } else {
        AnnotateIgnoreReadsEnd(__FILE__, __LINE__);
        AnnotateIgnoreWritesEnd(__FILE__, __LINE__);
    }
    tIgnoring = on;
}
/// Checks on (`checked` = true, our code) or off (TBB code) for a scope, then back as it was.
class CheckScope {
public:
    explicit CheckScope(bool checked) : before_(tIgnoring) { setIgnoring(!checked); }
    ~CheckScope() { setIgnoring(before_); }
    CheckScope(const CheckScope&) = delete;
    CheckScope& operator=(const CheckScope&) = delete;

private:
    bool before_;
};
/// Turns checks off on TBB's worker threads while they are in the engine's arena. Owned by the
/// engine; before it stops observing it waits (bounded) for the workers to leave the arena, so
/// that each gets its exit notification and no thread is left with checks off.
class TsanWorkerObserver : public tbb::task_scheduler_observer {
public:
    explicit TsanWorkerObserver(tbb::task_arena& arena) : tbb::task_scheduler_observer(arena) {
        handOver(this);  // constructed before any notification (registered inside libtbb)
        observe(true);
    }
    ~TsanWorkerObserver() override {
        for (int i = 0; i < 5000 && inside_.load() > 0; ++i)
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        observe(false);  // waits for notifications in progress (inside libtbb, so say it to TSan)
        takeOver(this);
    }
    void on_scheduler_entry(bool isWorker) override {
        takeOver(this);
        if (isWorker && !tIgnoring) {
            setIgnoring(true);
            inside_.fetch_add(1);
        }
        handOver(this);
    }
    void on_scheduler_exit(bool isWorker) override {
        takeOver(this);
        if (isWorker && tIgnoring) {
            setIgnoring(false);
            inside_.fetch_sub(1);
        }
        handOver(this);
    }

private:
    std::atomic<int> inside_{0};
};
#define PMSC_CHECKED_SCOPE CheckScope pmscChecked_(true)
#define PMSC_UNCHECKED_SCOPE CheckScope pmscUnchecked_(false)
#else
inline void handOver(const void*) {}
inline void takeOver(const void*) {}
#define PMSC_CHECKED_SCOPE
#define PMSC_UNCHECKED_SCOPE
#endif

/// Opens every node body: TSan checks on (in TSan builds), and at the end a release on
/// `done`, which the thread that waits for the graph acquires before it frees anything.
#define PMSC_NODE_BODY(done)           \
    PMSC_CHECKED_SCOPE;                \
    struct DoneOnExit {                \
        const void* p;                 \
        ~DoneOnExit() { handOver(p); } \
    } pmscDone_ {                      \
        done                           \
    }

}  // namespace pmsc::engine
