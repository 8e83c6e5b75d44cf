#include "engine/Engine.h"

#include "nodes/Blender.h"
#include "nodes/ErrorMonitor.h"
#include "nodes/FailThroughEvaluator.h"
#include "nodes/FramePlan.h"
#include "nodes/FrameSlot.h"
#include "nodes/KeyPointEvaluator.h"
#include "nodes/Projector.h"
#include "nodes/Reconstructor.h"
#include "pmsc/Errors.h"
#include "pmsc/PointMultiplier.h"

#include <oneapi/tbb/flow_graph.h>
#include <oneapi/tbb/info.h>
#include <oneapi/tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <string>
#include <tuple>

namespace pmsc::engine {

namespace flow = tbb::flow;
using nodes::FramePlan;
using nodes::FrameSlot;
using nodes::Route;
using Clock = std::chrono::steady_clock;

namespace {

/// Node kinds whose body time the stats report, in graph order.
enum NodeId : int { kKeys, kProject, kMonitor, kReconstruct, kFailThrough, kBlend, kSink, kNodeCount };
constexpr std::array<const char*, kNodeCount> kNodeNames = {
    nodes::KeyPointEvaluator::kName, nodes::Projector::kName,
    nodes::ErrorMonitor::kName,      nodes::Reconstructor::kName,
    nodes::FailThroughEvaluator::kName, nodes::Blender::kName,
    "sink"};

/// Body time of one node kind, summed over threads. Integers, so adding from several threads
/// needs no lock and loses nothing.
struct NodeClock {
    std::atomic<long long> nanoseconds{0};
    std::atomic<Index> calls{0};
};

/// Runs `body` and adds its duration to `clock`.
template <class Body>
auto timed(NodeClock& clock, Body&& body) {
    const auto start = Clock::now();
    struct Stop {
        NodeClock& clock;
        Clock::time_point start;
        ~Stop() {
            clock.nanoseconds.fetch_add(
                std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start).count(),
                std::memory_order_relaxed);
            clock.calls.fetch_add(1, std::memory_order_relaxed);
        }
    } stop{clock, start};
    return body();
}

/// One branch of a fail-through: which frame, which chunk of its points.
struct ChunkMsg {
    FrameSlot* slot = nullptr;
    Index chunk = 0;
};

/// Decision: the automatic chunk size depends on N only, never on the thread count, so a
/// blended frame's chunked reconstruction (and so every output bit) is the same at 1 and at
/// 64 threads. About 64 branches for a large frame, none smaller than 256 points (below that
/// a branch's task overhead starts to show against a cheap evaluator).
Index automaticChunkPoints(Index outputPoints) {
    const Index target = (outputPoints + 63) / 64;
    return std::max<Index>(256, target);
}

}  // namespace

struct Engine::Impl {
    const Model& model;
    const PointEvaluator& evaluator;
    EngineOptions options;
    PointMultiplier pm;
    SoftCachePolicy policy;
    FramePlan plan;
    int threads;
    Index maxInFlight;
    tbb::task_arena arena;
    RunStats last;

    Impl(const Model& m, const PointEvaluator& e, EngineOptions o)
        : model(m),
          evaluator(e),
          options(std::move(o)),
          pm(checked(m, e, options)),
          policy(options.policy ? *options.policy : SoftCachePolicy(m.epsMin, m.epsMax)),
          plan(FramePlan::make(m, options.pointsWanted,
                               options.chunkPoints > 0
                                   ? options.chunkPoints
                                   : automaticChunkPoints(options.pointsWanted.empty()
                                                              ? m.points
                                                              : Index(options.pointsWanted.size())),
                               options.wholeFrameFailThrough)),
          threads(options.threads > 0 ? options.threads : tbb::info::default_concurrency()),
          maxInFlight(options.maxFramesInFlight > 0 ? options.maxFramesInFlight : 2 * Index(threads)),
          arena(threads) {}

    /// Validates what the members' constructors do not, before any of them runs.
    static const Model& checked(const Model& m, const PointEvaluator& e, const EngineOptions& o) {
        if (e.pointCount() != m.points || e.channelCount() != m.channels) {
            throw InputError("engine: evaluator '" + e.name() + "' has " + std::to_string(e.pointCount()) +
                             " points x " + std::to_string(e.channelCount()) + " channels, the model " +
                             std::to_string(m.points) + " x " + std::to_string(m.channels));
        }
        if (o.threads < 0) throw InputError("engine: threads must be >= 0, got " + std::to_string(o.threads));
        if (o.maxFramesInFlight < 0) {
            throw InputError("engine: frames in flight must be >= 0, got " +
                             std::to_string(o.maxFramesInFlight));
        }
        if (o.chunkPoints < 0) {
            throw InputError("engine: chunk size must be >= 0, got " + std::to_string(o.chunkPoints));
        }
        return m;
    }

    RunStats run(FrameRange range, FrameSink& sink);
};

Engine::Engine(const Model& model, const PointEvaluator& evaluator, EngineOptions options)
    : impl_(std::make_unique<Impl>(model, evaluator, std::move(options))) {}

Engine::~Engine() = default;

const RunStats& Engine::lastStats() const { return impl_->last; }
const EngineOptions& Engine::options() const { return impl_->options; }
const std::vector<Index>& Engine::outputPoints() const { return impl_->plan.outputPoints; }

RunStats Engine::run(FrameRange range, FrameSink& sink) { return impl_->run(range, sink); }

RunStats Engine::Impl::run(FrameRange range, FrameSink& sink) {
    if (range.count < 0 || range.step <= 0 || range.first < 0 ||
        (range.count > 0 && range.last() >= evaluator.frameCount())) {
        throw InputError("engine: frames " + std::to_string(range.first) + " + " +
                         std::to_string(range.count) + " x step " + std::to_string(range.step) +
                         " outside the " + std::to_string(evaluator.frameCount()) +
                         " frames of evaluator '" + evaluator.name() + "'");
    }
    last = RunStats{};
    last.framesRequested = range.count;
    last.threads = threads;
    last.maxFramesInFlight = maxInFlight;
    last.chunks = Index(plan.chunks.size());

    nodes::RunControl control(options.cancel);
    std::array<NodeClock, kNodeCount> clocks;
    const auto start = Clock::now();
    const auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };

    const auto finish = [&] {
        last.wallSeconds = seconds(Clock::now() - start);
        last.framesDelivered = control.delivered.load();
        last.hits = control.hits.load();
        last.blends = control.blends.load();
        last.misses = control.misses.load();
        last.failed = control.failed.load();
        last.forcedMisses = control.forcedMisses.load();
        last.peakFramesInFlight = control.peakInFlight();
        last.framesPerSecond = last.wallSeconds > 0 ? double(last.framesDelivered) / last.wallSeconds : 0;
        last.cancelled = control.externallyCancelled();
        last.nodes.clear();
        for (int i = 0; i < kNodeCount; ++i) {
            last.nodes.push_back({kNodeNames[size_t(i)], double(clocks[size_t(i)].nanoseconds.load()) * 1e-9,
                                  clocks[size_t(i)].calls.load()});
        }
    };
    if (range.count == 0) {
        finish();
        return last;
    }

    // The frame buffers are the tokens: maxInFlight of them, allocated once, recycled.
    std::vector<std::unique_ptr<FrameSlot>> slots;
    const Index slotCount = std::min(maxInFlight, range.count);
    for (Index i = 0; i < slotCount; ++i) {
        slots.push_back(std::make_unique<FrameSlot>(plan, model.keyCount(), model.basisSize(),
                                                    options.keepPointMultiplication));
    }

    const nodes::KeyPointEvaluator keysBody(model, evaluator);
    const nodes::Projector projectBody(pm);
    const nodes::ErrorMonitor monitorBody(pm, policy, options.keepPointMultiplication);
    const nodes::Reconstructor reconstructBody(pm, plan);
    const nodes::FailThroughEvaluator failThroughBody(evaluator, plan);
    const nodes::Blender blendBody(pm, plan);
    nodes::OrderedSink sinkBody(plan, sink, options.failurePolicy, control);
    const bool stopOnFailure = options.failurePolicy == FailurePolicy::StopRun;
    const Index chunkCount = Index(plan.chunks.size());

    const auto runGraph = [&] {
        // The graph is built inside the arena so that its tasks run on the arena's threads.
        //
        //  source ──seq──┐
        //                ├─ bind (reserving join) ─> keys ─> project ─> monitor ──hit──> reconstruct ─┐
        //  tokens ─slot──┘                                              │  │  (keepPm: │ then chunks)  │
        //    ^                                                    failed│  └─blend/miss: one message   │
        //    │                                                          │     per chunk ─┐            │
        //    │                                                          │                v            │
        //    │                                                          │   fail-through (unlimited)   │
        //    │                                                          │                v            │
        //    │                                                          │           blend (unlimited)  │
        //    │                                                          │                v            │
        //    │                                                          │   gather (last chunk sends)  │
        //    │                                                          v                v            v
        //    └──────────────── slot ── sink (serial) <── sequencer (restores order) <──────────────────┘
        //
        // tokens holds the free frame slots: a frame starts only when bind pairs a sequence
        // number with a free slot, and the slot comes back only after the sink, so at most
        // maxInFlight frames are anywhere in the graph.
        using Token = FrameSlot*;
        using MonitorNode = flow::multifunction_node<Token, std::tuple<Token, ChunkMsg, Token>>;
        using ReconstructNode = flow::multifunction_node<Token, std::tuple<Token, ChunkMsg>>;
        using GatherNode = flow::multifunction_node<ChunkMsg, std::tuple<Token>>;

        flow::graph g;
        control.setCancelHook([&g] { g.cancel(); });

        nodes::FrameSource source(range, control);
        flow::input_node<Index> sourceNode(g, [&](tbb::flow_control& fc) -> Index {
            Index seq = 0;
            if (!source.next(seq)) fc.stop();
            return seq;
        });
        flow::buffer_node<Token> tokens(g);
        flow::join_node<std::tuple<Index, Token>, flow::reserving> bind(g);

        flow::function_node<std::tuple<Index, Token>, Token> keys(
            g, flow::unlimited, [&](const std::tuple<Index, Token>& in) -> Token {
                Token slot = std::get<1>(in);
                const Index seq = std::get<0>(in);
                slot->reset(seq, range.frame(seq));
                control.frameStarted();
                if (control.cancelled()) return slot;
                timed(clocks[kKeys], [&] { keysBody(*slot); });
                if (slot->failed() && stopOnFailure) control.stopAfter(seq);
                return slot;
            });
        // Cheap bodies run as lightweight nodes: in the task of the node before them.
        flow::function_node<Token, Token, flow::queueing_lightweight> project(
            g, flow::unlimited, [&](Token slot) -> Token {
                if (!control.cancelled()) timed(clocks[kProject], [&] { projectBody(*slot); });
                return slot;
            });
        MonitorNode monitor(g, flow::unlimited, [&](Token slot, MonitorNode::output_ports_type& out) {
            if (control.cancelled()) {
                std::get<2>(out).try_put(slot);
                return;
            }
            const Route route = timed(clocks[kMonitor], [&] { return monitorBody(*slot); });
            if (route == Route::Reconstruct) {
                std::get<0>(out).try_put(slot);
            } else if (route == Route::FailThrough) {
                slot->chunksLeft.store(chunkCount, std::memory_order_relaxed);
                for (Index c = 0; c < chunkCount; ++c) std::get<1>(out).try_put(ChunkMsg{slot, c});
            } else {
                std::get<2>(out).try_put(slot);
            }
        });
        ReconstructNode reconstruct(g, flow::unlimited, [&](Token slot, ReconstructNode::output_ports_type& out) {
            if (control.cancelled()) {
                std::get<0>(out).try_put(slot);
                return;
            }
            const bool done = timed(clocks[kReconstruct], [&] { return reconstructBody(*slot); });
            if (done) {
                std::get<0>(out).try_put(slot);
            } else {
                slot->chunksLeft.store(chunkCount, std::memory_order_relaxed);
                for (Index c = 0; c < chunkCount; ++c) std::get<1>(out).try_put(ChunkMsg{slot, c});
            }
        });
        flow::function_node<ChunkMsg, ChunkMsg> failThrough(g, flow::unlimited, [&](ChunkMsg m) {
            if (!control.cancelled()) timed(clocks[kFailThrough], [&] { failThroughBody(*m.slot, m.chunk); });
            return m;
        });
        flow::function_node<ChunkMsg, ChunkMsg, flow::queueing_lightweight> blend(
            g, flow::unlimited, [&](ChunkMsg m) {
                if (m.slot->decision.state == CacheState::Blend && !control.cancelled()) {
                    timed(clocks[kBlend], [&] { blendBody(*m.slot, m.chunk); });
                }
                return m;
            });
        GatherNode gather(g, flow::unlimited, [&](ChunkMsg m, GatherNode::output_ports_type& out) {
            // acq_rel: the last branch sees every other branch's writes before the frame moves on.
            if (m.slot->chunksLeft.fetch_sub(1, std::memory_order_acq_rel) == 1) {
                if (m.slot->failed() && stopOnFailure) control.stopAfter(m.slot->sequence);
                std::get<0>(out).try_put(m.slot);
            }
        });
        flow::sequencer_node<Token> sequencer(g, [](const Token& slot) { return size_t(slot->sequence); });
        flow::function_node<Token, Token> sinkNode(g, flow::serial, [&](Token slot) -> Token {
            timed(clocks[kSink], [&] { sinkBody(*slot); });
            control.frameFinished();
            if (options.progress && !control.cancelled()) {
                Progress p;
                p.framesDone = control.delivered.load(std::memory_order_relaxed);
                p.framesTotal = range.count;
                p.hits = control.hits.load(std::memory_order_relaxed);
                p.blends = control.blends.load(std::memory_order_relaxed);
                p.misses = control.misses.load(std::memory_order_relaxed);
                p.failed = control.failed.load(std::memory_order_relaxed);
                p.elapsedSeconds = seconds(Clock::now() - start);
                options.progress(p);
            }
            return slot;
        });

        flow::make_edge(sourceNode, flow::input_port<0>(bind));
        flow::make_edge(tokens, flow::input_port<1>(bind));
        flow::make_edge(bind, keys);
        flow::make_edge(keys, project);
        flow::make_edge(project, monitor);
        flow::make_edge(flow::output_port<0>(monitor), reconstruct);
        flow::make_edge(flow::output_port<1>(monitor), failThrough);
        flow::make_edge(flow::output_port<2>(monitor), sequencer);
        flow::make_edge(flow::output_port<0>(reconstruct), sequencer);
        flow::make_edge(flow::output_port<1>(reconstruct), failThrough);
        flow::make_edge(failThrough, blend);
        flow::make_edge(blend, gather);
        flow::make_edge(flow::output_port<0>(gather), sequencer);
        flow::make_edge(sequencer, sinkNode);
        flow::make_edge(sinkNode, tokens);

        for (auto& slot : slots) tokens.try_put(slot.get());
        sourceNode.activate();
        g.wait_for_all();
    };
    try {
        arena.execute(runGraph);
    } catch (...) {
        finish();
        throw;
    }

    finish();
    if (auto error = control.abortError()) std::rethrow_exception(error);
    if (control.externallyCancelled()) {
        throw Cancelled("engine: run cancelled after " + std::to_string(last.framesDelivered) + " of " +
                        std::to_string(range.count) + " frames");
    }
    if (control.hasRunError()) throw EvaluatorError(control.runError());
    return last;
}

}  // namespace pmsc::engine
