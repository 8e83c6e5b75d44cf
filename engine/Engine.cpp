#include "engine/Engine.h"
#include "engine/TsanAnnotations.h"

#include "nodes/Blender.h"
#include "nodes/ErrorMonitor.h"
#include "nodes/FailThroughEvaluator.h"
#include "nodes/FramePlan.h"
#include "nodes/FrameSlot.h"
#include "nodes/FrameSource.h"
#include "nodes/KeyPointEvaluator.h"
#include "nodes/LocalBranch.h"
#include "nodes/OrderedSink.h"
#include "nodes/Projector.h"
#include "nodes/Reconstructor.h"
#include "nodes/RunControl.h"
#include "pmsc/Errors.h"
#include "pmsc/HitCheck.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/RegionMultiplier.h"

#include <oneapi/tbb/flow_graph.h>
#include <oneapi/tbb/info.h>
#include <oneapi/tbb/task_arena.h>
#include <oneapi/tbb/task_scheduler_observer.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <tuple>

namespace pmsc::engine {

namespace flow = tbb::flow;
using nodes::FramePlan;
using nodes::FrameSlot;
using nodes::Route;
using Clock = std::chrono::steady_clock;

namespace {

/// Node kinds whose body time the stats report, in graph order.
enum NodeId : int {
    kKeys,
    kProject,
    kMonitor,
    kReconstruct,
    kFailThrough,
    kBlend,
    kLocal,
    kFeather,
    kSink,
    kNodeCount
};
constexpr std::array<const char*, kNodeCount> kNodeNames = {nodes::KeyPointEvaluator::kName,
                                                            nodes::Projector::kName,
                                                            nodes::ErrorMonitor::kName,
                                                            nodes::Reconstructor::kName,
                                                            nodes::FailThroughEvaluator::kName,
                                                            nodes::Blender::kName,
                                                            nodes::LocalBranch::kName,
                                                            nodes::LocalCombiner::kName,
                                                            "sink"};

/// Body time of one node kind, summed over threads. Integers, so adding from several threads
/// needs no lock and loses nothing.
struct NodeClock {
    std::atomic<long long> nanoseconds{0};
    std::atomic<Index> calls{0};
};

/// Runs `body` and adds its duration to `clock` (and a call, unless `call` is false: the second
/// part of a node's call).
template <class Body>
auto timed(NodeClock& clock, Body&& body, bool call = true) {
    const auto start = Clock::now();
    struct Stop {
        NodeClock& clock;
        Clock::time_point start;
        bool call;
        ~Stop() {
            clock.nanoseconds.fetch_add(
                std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start).count(),
                std::memory_order_relaxed);
            if (call) clock.calls.fetch_add(1, std::memory_order_relaxed);
        }
    } stop{clock, start, call};
    return body();
}

/// One branch of a fail-through: which frame, which chunk of its points.
struct ChunkMsg {
    FrameSlot* slot = nullptr;
    Index chunk = 0;
};

/// Decision: about 64 branches for a large frame, none smaller than 256 points (below that a
/// branch's task overhead starts to show against a cheap evaluator). The size depends on N only,
/// never on the thread count; the output would not depend on it either way (a blended frame's
/// chunked reconstruction is the whole frame's, bit for bit: Engine and SharedChannels tests).
Index automaticChunkPoints(Index outputPoints) {
    const Index target = (outputPoints + 63) / 64;
    return std::max<Index>(256, target);
}

/// Decision: an evaluator whose every call pays a set-up (FailThroughShape::callSetUp) fails
/// through in one chunk per thread. The 64 automatic chunks pay that set-up 64 times a frame: on
/// Blender's four cubes (docs/blender.md, one thread) 30 path frames made 740 bakes in them and 77
/// in one chunk per thread, and `pmsc run` took 10% longer. One chunk per thread still keeps every
/// thread on one missed frame. The values are the same at any
/// chunking (an evaluator's point does not depend on the points asked with it, and the
/// reconstruction of a range is the whole frame's, bit for bit), so the output stays identical at
/// any thread count.
Index chunkPointsOf(const EngineOptions& options, const PointEvaluator::FailThroughShape& shape,
                    Index outputPoints, int threads) {
    if (options.chunkPoints > 0) return options.chunkPoints;
    if (shape.chunkPoints > 0) return shape.chunkPoints;
    if (shape.callSetUp) return std::max<Index>(1, (outputPoints + threads - 1) / threads);
    return automaticChunkPoints(outputPoints);
}

/// The engine's threads: options.threads, or every core when it is 0.
int threadCount(const EngineOptions& options) {
    return options.threads > 0 ? options.threads : tbb::info::default_concurrency();
}

}  // namespace

struct Engine::Impl {
    const Model& model;
    const PointEvaluator& evaluator;
    EngineOptions options;
    PointEvaluator::FailThroughShape shape;
    /// The sentinels the key node computes in the keys' call (sentinelsWithTheKeys), or empty.
    std::vector<Index> keySentinels;
    PointMultiplier pm;
    SoftCachePolicy policy;
    Index chunkPoints;  ///< points per fail-through chunk (and per piece of a local frame)
    FramePlan plan;
    std::optional<RegionMultiplier> regions;  ///< set when frames are routed region by region
    int threads;
    Index maxInFlight;
    std::uint64_t slotBytes = 0;  ///< FrameSlot::bytes() of one slot
    tbb::task_arena arena;
    std::vector<std::unique_ptr<FrameSlot>> pool;  ///< frame slots, reused run after run
#if defined(__SANITIZE_THREAD__)
    TsanWorkerObserver tsanObserver{arena};
#endif
    RunStats last;

    Impl(const Model& m, const PointEvaluator& e, EngineOptions o)
        : model(m),
          evaluator(e),
          options(std::move(o)),
          shape(e.failThroughShape()),
          keySentinels(sentinelsWithTheKeys() ? HitCheck::sentinelsOf(m) : std::vector<Index>{}),
          pm(checked(m, e, options), options.basisPrecision),
          policy(options.policy ? *options.policy : SoftCachePolicy(m.epsMin, m.epsMax)),
          chunkPoints(chunkPointsOf(
              options, shape, options.pointsWanted.empty() ? m.points : Index(options.pointsWanted.size()),
              threadCount(options))),
          plan(FramePlan::make(m, options.pointsWanted, chunkPoints,
                               options.wholeFrameFailThrough || shape.wholeFrame, keySentinels)),
          threads(threadCount(options)),
          maxInFlight(options.maxFramesInFlight > 0 ? options.maxFramesInFlight : 2 * Index(threads)),
          arena(threads) {
        // A client of onEstimate wants the point multiplication of misses too.
        if (options.onEstimate) options.keepPointMultiplication = true;
        if (m.regions && options.localFailThrough && plan.allPoints && shape.cheapSubsets) regions.emplace(m);
        // The first frame's buffers are made now, to measure what a frame in flight costs.
        takeSlots(1);
        slotBytes = pool.front()->bytes();
        if (options.memoryLimit > 0) fitFramesInFlight();
    }

    /// Points per piece of the keys and of a hit's check: options.keyPiecePoints where a subset
    /// is cheap and a call has no set-up of its own, else 0 (one call each).
    Index keyPiecePoints() const {
        return shape.cheapSubsets && !shape.callSetUp ? options.keyPiecePoints : 0;
    }

    /// Decision: an evaluator whose calls share work between their points (a whole-frame rig, whose
    /// subsets pose through a shared dependency closure and set up the pose per call; a child
    /// process or renderer that pays a set-up per call) computes a hit's sentinels in the keys'
    /// call. Why: every hit of a model with sentinels computes them, and one call of both costs
    /// less than two (the face demo: 5.4-5.6x against 4.9-5.0x, alternated runs, docs/face.md). A frame that
    /// does not hit uses them as it uses the keys: its fail-through's chunks copy them in (a
    /// whole-frame evaluateAll() computes them again; a local frame checks with them). Not with
    /// keyPiecePoints (the pieces already run at once) nor with estimateBeforeCheck (the client
    /// wants the keys' estimate before the check). The values are the same either way: an
    /// evaluator's point does not depend on the points asked with it.
    bool sentinelsWithTheKeys() const {
        return (shape.wholeFrame || shape.callSetUp) && keyPiecePoints() == 0 &&
               !options.estimateBeforeCheck && model.sentinels.has_value();
    }

    /// Cuts maxInFlight to the frame buffers options.memoryLimit holds.
    void fitFramesInFlight() {
        const auto fit = static_cast<Index>(options.memoryLimit / slotBytes);
        if (fit < 1) {
            char text[200];
            std::snprintf(
                text, sizeof text,
                "engine: %.1f MiB for frame buffers cannot hold one frame in flight (%.1f MiB: %lld "
                "points x %lld channels and their workspace); give the task more memory",
                static_cast<double>(options.memoryLimit) / 1048576.0,
                static_cast<double>(slotBytes) / 1048576.0, static_cast<long long>(plan.outputCount()),
                static_cast<long long>(model.channels));
            throw InputError(text);
        }
        maxInFlight = std::min(maxInFlight, fit);
    }

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
        if (o.estimateBeforeCheck && !o.onEstimate)
            throw InputError("engine: estimateBeforeCheck needs onEstimate, which it calls");
        return m;
    }

    using Clocks = std::array<NodeClock, kNodeCount>;

    // run() in named steps: check, take slots, run the graph, collect, report.
    RunStats run(FrameRange range, FrameSink& sink);
    void checkRange(FrameRange range) const;
    /// The frame slots of a run of `frames` frames: the pool grown to what the run can use.
    std::span<const std::unique_ptr<FrameSlot>> takeSlots(Index frames);
    struct Bodies;  ///< one run's node bodies
    struct Graph;   ///< one run's flow graph
    /// Builds the flow graph in the arena, streams `range` through it, and waits.
    void runGraph(FrameRange range, FrameSink& sink, nodes::RunControl& control, Clocks& clocks,
                  std::span<const std::unique_ptr<FrameSlot>> slots, Clock::time_point start);
    /// `last` from the run's counters and clocks.
    void collectStats(const nodes::RunControl& control, const Clocks& clocks, Clock::time_point start);
};

Engine::Engine(const Model& model, const PointEvaluator& evaluator, EngineOptions options)
    : impl_(std::make_unique<Impl>(model, evaluator, std::move(options))) {}

Engine::~Engine() = default;

const RunStats& Engine::lastStats() const { return impl_->last; }
const EngineOptions& Engine::options() const { return impl_->options; }
std::uint64_t Engine::frameBytes() const { return impl_->slotBytes; }
const std::vector<Index>& Engine::outputPoints() const { return impl_->plan.outputPoints; }
bool Engine::localFailThrough() const { return impl_->regions.has_value(); }

const PointMultiplier& Engine::pointMultiplier() const { return impl_->pm; }

RunStats Engine::run(FrameRange range, FrameSink& sink) { return impl_->run(range, sink); }

void Engine::Impl::checkRange(FrameRange range) const {
    if (range.count < 0 || range.step <= 0 || range.first < 0 ||
        (range.count > 0 && range.last() >= evaluator.frameCount())) {
        throw InputError("engine: frames " + std::to_string(range.first) + " + " +
                         std::to_string(range.count) + " x step " + std::to_string(range.step) +
                         " outside the " + std::to_string(evaluator.frameCount()) + " frames of evaluator '" +
                         evaluator.name() + "'");
    }
}

std::span<const std::unique_ptr<FrameSlot>> Engine::Impl::takeSlots(Index frames) {
    // The frame buffers are the tokens: at most maxInFlight of them, allocated on the first run
    // that needs them and kept by the engine, so repeated runs (a render farm's chunks) neither
    // allocate nor page-fault frame buffers again.
    const Index slotCount = std::min(maxInFlight, frames);
    while (Index(pool.size()) < slotCount) {
        pool.push_back(std::make_unique<FrameSlot>(plan, model.keyCount(), model.coordCount(),
                                                   options.keepPointMultiplication));
        if (regions) pool.back()->enableRegions(*regions, model.points, model.channels);
        if (!keySentinels.empty()) pool.back()->enableSentinels(Index(keySentinels.size()), model.channels);
    }
    return {pool.data(), size_t(slotCount)};
}

void Engine::Impl::collectStats(const nodes::RunControl& control, const Clocks& clocks,
                                Clock::time_point start) {
    last.wallSeconds = std::chrono::duration<double>(Clock::now() - start).count();
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
    last.regions.clear();
    if (model.regions) last.regions.resize(size_t(model.regions->regionCount()));
    for (size_t r = 0; r < control.regionStates.size() && r < last.regions.size(); ++r) {
        last.regions[r].hits = control.regionStates[r][0];
        last.regions[r].blends = control.regionStates[r][1];
        last.regions[r].misses = control.regionStates[r][2];
    }
    last.localFrames = control.localFrames;
    const Index counted = last.framesDelivered - last.failed;
    last.pointsEvaluatedFraction = counted > 0 ? control.pointsEvaluatedFractionSum / double(counted) : 0;
}

RunStats Engine::Impl::run(FrameRange range, FrameSink& sink) {
    checkRange(range);
    last = RunStats{};
    last.framesRequested = range.count;
    last.threads = threads;
    last.maxFramesInFlight = maxInFlight;
    last.chunks = Index(plan.chunks.size());

    nodes::RunControl control(options.cancel);
    Clocks clocks;
    const auto start = Clock::now();
    if (range.count == 0) {
        collectStats(control, clocks, start);
        return last;
    }
    const auto slots = takeSlots(range.count);
    try {
        arena.execute([&] { runGraph(range, sink, control, clocks, slots, start); });
    } catch (...) {
        collectStats(control, clocks, start);
        throw;
    }
    collectStats(control, clocks, start);
    if (auto error = control.abortError()) std::rethrow_exception(error);
    if (control.externallyCancelled()) {
        throw Cancelled("engine: run cancelled after " + std::to_string(last.framesDelivered) + " of " +
                        std::to_string(range.count) + " frames");
    }
    if (control.hasRunError()) throw EvaluatorError(control.runError());
    return last;
}

/// The node bodies of one run: each stage's work on a frame slot, built from the engine's state.
struct Engine::Impl::Bodies {
    const nodes::KeyPointEvaluator keys;
    const nodes::Projector project;
    const nodes::ErrorMonitor monitor;
    const nodes::Reconstructor reconstruct;
    const nodes::FailThroughEvaluator failThrough;
    const nodes::Blender blend;
    std::optional<nodes::LocalBranch> local;      ///< set when frames are routed region by region
    std::optional<nodes::LocalCombiner> feather;  ///< set when frames are routed region by region
    nodes::OrderedSink sink;

    Bodies(Impl& impl, FrameSink& frames, nodes::RunControl& control);
    /// The local fail-through's branch body, when the engine routes frames region by region.
    static std::optional<nodes::LocalBranch> localBranchOf(Impl& impl);
    /// The local fail-through's feathered blend, when the engine routes frames region by region.
    static std::optional<nodes::LocalCombiner> featherOf(const Impl& impl);
};

Engine::Impl::Bodies::Bodies(Impl& impl, FrameSink& frames, nodes::RunControl& control)
    : keys(impl.model, impl.evaluator, impl.keyPiecePoints(), impl.keySentinels),
      project(impl.pm),
      monitor(impl.pm, impl.policy, impl.options.keepPointMultiplication,
              impl.regions ? &*impl.regions : nullptr, &impl.evaluator, impl.keyPiecePoints()),
      reconstruct(impl.pm, impl.plan),
      failThrough(impl.evaluator, impl.plan),
      blend(impl.pm, impl.plan),
      local(localBranchOf(impl)),
      feather(featherOf(impl)),
      sink(impl.plan, frames, impl.options.failurePolicy, control) {}

std::optional<nodes::LocalBranch> Engine::Impl::Bodies::localBranchOf(Impl& impl) {
    if (!impl.regions) return std::nullopt;
    // The local frame's full evaluation: one call when the evaluator is failed through
    // whole (its subset poses share work), one piece per thread when its calls pay a set-up,
    // else pieces of the fail-through's chunk size.
    return std::optional<nodes::LocalBranch>(
        std::in_place, impl.evaluator, *impl.regions, impl.model.channels,
        impl.shape.wholeFrame ? 0 : impl.chunkPoints,
        impl.shape.callSetUp && !impl.shape.wholeFrame ? impl.threads : 0);
}

std::optional<nodes::LocalCombiner> Engine::Impl::Bodies::featherOf(const Impl& impl) {
    if (!impl.regions) return std::nullopt;
    return std::optional<nodes::LocalCombiner>(std::in_place, impl.model.channels, impl.model.tolerance);
}

/// One run's flow graph: its nodes (members, in the order they are built) and the bodies'
/// shared state. The graph is built inside the arena so that its tasks run on the arena's threads.
//
//  source ──seq──┐
//                ├─ bind (reserving join) ─> keys ─> project ─> monitor ──hit──> reconstruct ─┐
//  tokens ─slot──┘                                              │  │  (keepPm: │ then chunks)  │
//    ^                                                    failed│  └─blend/miss: one message   │
//    │                                                          │     per chunk ─┐            │
//    │                                                          │                v            │
//    │                                                          │   fail-through (unlimited)   │
//    │                                                          │                v            │
//    │                                                          │     blend (same task)        │
//    │                                                          │                v            │
//    │                                                          │  gather (the last branch     │
//    │                                                          │   sends the frame on)        │
//    │               monitor ──local: one message per region, then one per piece           │
//    │                 of the failing points ──> local (unlimited: region PM, or a piece of   │
//    │                                            the failing regions' fail sets' union) ─>   │
//    │                                            local gather (the last branch runs the      │
//    │                                            feathered blend, sends the frame on) ─────┐ │
//    │                                                          v                v          v v
//    └──────────────── slot ── sink (serial) <── sequencer (restores order) <──────────────────┘
//
// tokens holds the free frame slots: a frame starts only when bind pairs a sequence
// number with a free slot, and the slot comes back only after the sink, so at most
// maxInFlight frames are anywhere in the graph.
struct Engine::Impl::Graph {
    using Token = FrameSlot*;
    using MonitorNode = flow::multifunction_node<Token, std::tuple<Token, ChunkMsg, Token, ChunkMsg>,
                                                 flow::queueing_lightweight>;
    using ReconstructNode = flow::multifunction_node<Token, std::tuple<Token, ChunkMsg>>;
    using GatherNode = flow::multifunction_node<ChunkMsg, std::tuple<Token>, flow::queueing_lightweight>;

    Bodies& bodies;
    nodes::RunControl& control;
    Clocks& clocks;
    const EngineOptions& options;
    const FrameRange range;
    const Clock::time_point start;
    const bool stopOnFailure;
    const Index chunkCount;
    const nodes::FramePlan& plan;

    flow::graph g;
    const char runDone = 0;  // sync object only (TSan): every body's end -> after wait_for_all
    nodes::FrameSource source;
    flow::input_node<Index> sourceNode;
    flow::buffer_node<Token> tokens;
    flow::join_node<std::tuple<Index, Token>, flow::reserving> bind;
    flow::function_node<std::tuple<Index, Token>, Token> keys;
    // Cheap bodies run as lightweight nodes: in the task of the node before them.
    flow::function_node<Token, Token, flow::queueing_lightweight> project;
    MonitorNode monitor;
    ReconstructNode reconstruct;
    flow::function_node<ChunkMsg, ChunkMsg> failThrough;
    flow::function_node<ChunkMsg, ChunkMsg, flow::queueing_lightweight> blend;
    GatherNode gather;
    // Local fail-through: one branch per region, the feathered blend in the last one's task.
    flow::function_node<ChunkMsg, ChunkMsg> localBranch;
    GatherNode localGather;
    flow::sequencer_node<Token> sequencer;
    flow::function_node<Token, Token> sinkNode;

    Graph(const Impl& impl, Bodies& bodies, FrameRange range, nodes::RunControl& control, Clocks& clocks,
          Clock::time_point start);
    /// Hands a frame's point multiplication to EngineOptions::onEstimate (once per frame).
    void reportEstimate(FrameSlot& slot) const;
    /// Hands a finished fail-through branch to EngineOptions::onChunk.
    void reportChunk(const ChunkMsg& m) const;
    /// Connects the nodes as drawn above.
    void wire();
    /// Puts the free slots in `tokens`, activates the source last, and waits for the graph.
    void run(std::span<const std::unique_ptr<FrameSlot>> slots);

    // The nodes' bodies, one per node (the stage's work is in `bodies`).
    Index sourceStep(tbb::flow_control& fc);
    Token keysStep(const std::tuple<Index, Token>& in);
    Token projectStep(Token slot);
    void monitorStep(Token slot, MonitorNode::output_ports_type& out);
    void reconstructStep(Token slot, ReconstructNode::output_ports_type& out);
    ChunkMsg failThroughStep(ChunkMsg m);
    ChunkMsg blendStep(ChunkMsg m);
    void gatherStep(ChunkMsg m, GatherNode::output_ports_type& out);
    ChunkMsg localBranchStep(ChunkMsg m);
    void localGatherStep(ChunkMsg m, GatherNode::output_ports_type& out);
    Token sinkStep(Token slot);

    /// A multifunction body's output: the slot's happens-before edge first (TSan builds), then
    /// TBB's try_put, unchecked.
    template <class Port, class Message>
    static void send(Token slot, Port& port, const Message& message) {
        handOver(slot);
        PMSC_UNCHECKED_SCOPE;
        port.try_put(message);
    }
    /// A frame for the fail-through branches goes out as one message per chunk.
    template <class Port>
    void sendChunks(Token slot, Port& port) const {
        slot->chunksLeft.store(chunkCount, std::memory_order_relaxed);
        for (Index c = 0; c < chunkCount; ++c) send(slot, port, ChunkMsg{slot, c});
    }
};

Engine::Impl::Graph::Graph(const Impl& impl, Bodies& runBodies, FrameRange runRange,
                           nodes::RunControl& runControl, Clocks& runClocks, Clock::time_point runStart)
    : bodies(runBodies),
      control(runControl),
      clocks(runClocks),
      options(impl.options),
      range(runRange),
      start(runStart),
      stopOnFailure(impl.options.failurePolicy == FailurePolicy::StopRun),
      chunkCount(Index(impl.plan.chunks.size())),
      plan(impl.plan),
      source(runRange, runControl),
      sourceNode(g, [this](tbb::flow_control& fc) -> Index { return sourceStep(fc); }),
      tokens(g),
      bind(g),
      keys(g, flow::unlimited, [this](const std::tuple<Index, Token>& in) -> Token { return keysStep(in); }),
      project(g, flow::unlimited, [this](Token slot) -> Token { return projectStep(slot); }),
      monitor(g, flow::unlimited,
              [this](Token slot, MonitorNode::output_ports_type& out) { monitorStep(slot, out); }),
      reconstruct(
          g, flow::unlimited,
          [this](Token slot, ReconstructNode::output_ports_type& out) { reconstructStep(slot, out); }),
      failThrough(g, flow::unlimited, [this](ChunkMsg m) { return failThroughStep(m); }),
      blend(g, flow::unlimited, [this](ChunkMsg m) { return blendStep(m); }),
      gather(g, flow::unlimited,
             [this](ChunkMsg m, GatherNode::output_ports_type& out) { gatherStep(m, out); }),
      localBranch(g, flow::unlimited, [this](ChunkMsg m) { return localBranchStep(m); }),
      localGather(g, flow::unlimited,
                  [this](ChunkMsg m, GatherNode::output_ports_type& out) { localGatherStep(m, out); }),
      sequencer(g, [](const Token& slot) { return size_t(slot->sequence); }),
      sinkNode(g, flow::serial, [this](Token slot) -> Token { return sinkStep(slot); }) {
    // Nothing runs before run() puts the tokens and activates the source, so the hook may be
    // set once every node is built.
    runControl.setCancelHook([this] {
        PMSC_UNCHECKED_SCOPE;  // TBB's code, called from inside a node body
        g.cancel();
    });
}

Index Engine::Impl::Graph::sourceStep(tbb::flow_control& fc) {
    PMSC_NODE_BODY(&runDone);
    takeOver(&source);
    Index seq = 0;
    if (!source.next(seq)) fc.stop();
    handOver(&source);
    return seq;
}

Engine::Impl::Graph::Token Engine::Impl::Graph::keysStep(const std::tuple<Index, Token>& in) {
    PMSC_NODE_BODY(&runDone);
    Token slot = std::get<1>(in);
    takeOver(slot);
    const Index seq = std::get<0>(in);
    slot->reset(seq, range.frame(seq));
    control.frameStarted();
    if (!control.cancelled()) timed(clocks[kKeys], [&] { bodies.keys(*slot); });
    if (slot->failed() && stopOnFailure) control.stopAfter(seq);
    handOver(slot);
    return slot;
}

Engine::Impl::Graph::Token Engine::Impl::Graph::projectStep(Token slot) {
    PMSC_NODE_BODY(&runDone);
    takeOver(slot);
    if (!control.cancelled()) timed(clocks[kProject], [&] { bodies.project(*slot); });
    handOver(slot);
    return slot;
}

void Engine::Impl::Graph::monitorStep(Token slot, MonitorNode::output_ports_type& out) {
    PMSC_NODE_BODY(&runDone);
    takeOver(slot);
    if (control.cancelled()) {
        send(slot, std::get<2>(out), slot);
        return;
    }
    Route route = timed(clocks[kMonitor], [&] { return bodies.monitor.decide(*slot); });
    if (route == Route::Check) {
        // A hit whose check points are computed next: an interactive client sees its image first.
        if (options.estimateBeforeCheck && !control.cancelled()) {
            timed(
                clocks[kReconstruct], [&] { bodies.reconstruct.estimate(*slot); }, false);
            reportEstimate(*slot);
        }
        // A run cancelled meanwhile (a client that moved on from the estimate) skips the check.
        route = control.cancelled()
                    ? Route::Done
                    : timed(
                          clocks[kMonitor], [&] { return bodies.monitor.check(*slot); }, false);
    }
    if (route == Route::Reconstruct) {
        send(slot, std::get<0>(out), slot);
    } else if (route == Route::FailThrough) {
        sendChunks(slot, std::get<1>(out));
    } else if (route == Route::Local) {
        const Index messages = bodies.local->messages(*slot);
        slot->chunksLeft.store(messages, std::memory_order_relaxed);
        for (Index i = 0; i < messages; ++i) send(slot, std::get<3>(out), ChunkMsg{slot, i});
    } else {
        send(slot, std::get<2>(out), slot);
    }
}

void Engine::Impl::Graph::reconstructStep(Token slot, ReconstructNode::output_ports_type& out) {
    PMSC_NODE_BODY(&runDone);
    takeOver(slot);
    if (control.cancelled()) {
        send(slot, std::get<0>(out), slot);
        return;
    }
    const bool done = timed(clocks[kReconstruct], [&] { return bodies.reconstruct(*slot); });
    if (done) {
        send(slot, std::get<0>(out), slot);
    } else {
        if (options.onEstimate && slot->pmValid && !slot->estimated) reportEstimate(*slot);
        sendChunks(slot, std::get<1>(out));
    }
}

ChunkMsg Engine::Impl::Graph::failThroughStep(ChunkMsg m) {
    PMSC_NODE_BODY(&runDone);
    takeOver(m.slot);
    if (!control.cancelled()) timed(clocks[kFailThrough], [&] { bodies.failThrough(*m.slot, m.chunk); });
    return m;
}

ChunkMsg Engine::Impl::Graph::blendStep(ChunkMsg m) {
    PMSC_NODE_BODY(&runDone);
    if (m.slot->decision.state == CacheState::Blend && !control.cancelled()) {
        timed(clocks[kBlend], [&] { bodies.blend(*m.slot, m.chunk); });
    }
    if (options.onChunk && !control.cancelled() && !m.slot->failed()) reportChunk(m);
    return m;
}

void Engine::Impl::Graph::reportEstimate(FrameSlot& slot) const {
    slot.estimated = true;
    FrameEstimate e;
    e.sequence = slot.sequence;
    e.frame = slot.frame;
    e.state = slot.decision.state;
    e.weight = slot.decision.weight;
    e.keyError = slot.keyError;
    e.points = plan.outputPoints;
    e.values =
        std::span<const double>(slot.pmValues.data(), plan.outputPoints.size() * size_t(plan.channels));
    options.onEstimate(e);
}

void Engine::Impl::Graph::reportChunk(const ChunkMsg& m) const {
    const nodes::FramePlan::Chunk& chunk = plan.chunks[size_t(m.chunk)];
    ChunkFinished c;
    c.sequence = m.slot->sequence;
    c.frame = m.slot->frame;
    c.state = m.slot->decision.state;
    c.weight = m.slot->decision.weight;
    c.chunk = m.chunk;
    c.chunks = chunkCount;
    c.firstOutput = chunk.firstOutput;
    c.values = std::span<const double>(m.slot->values.data() + chunk.firstOutput * plan.channels,
                                       size_t(chunk.outputCount * plan.channels));
    options.onChunk(c);
}

void Engine::Impl::Graph::gatherStep(ChunkMsg m, GatherNode::output_ports_type& out) {
    PMSC_NODE_BODY(&runDone);
    // acq_rel: the last branch sees every other branch's writes before the frame moves on.
    if (m.slot->chunksLeft.fetch_sub(1, std::memory_order_acq_rel) == 1) {
        if (m.slot->failed() && stopOnFailure) control.stopAfter(m.slot->sequence);
        send(m.slot, std::get<0>(out), m.slot);
    }
}

ChunkMsg Engine::Impl::Graph::localBranchStep(ChunkMsg m) {
    PMSC_NODE_BODY(&runDone);
    takeOver(m.slot);
    if (!control.cancelled()) timed(clocks[kLocal], [&] { (*bodies.local)(*m.slot, m.chunk); });
    return m;
}

void Engine::Impl::Graph::localGatherStep(ChunkMsg m, GatherNode::output_ports_type& out) {
    PMSC_NODE_BODY(&runDone);
    // acq_rel: the last branch sees every other branch's writes before it blends.
    if (m.slot->chunksLeft.fetch_sub(1, std::memory_order_acq_rel) == 1) {
        if (!control.cancelled()) timed(clocks[kFeather], [&] { (*bodies.feather)(*m.slot); });
        if (m.slot->failed() && stopOnFailure) control.stopAfter(m.slot->sequence);
        send(m.slot, std::get<0>(out), m.slot);
    }
}

Engine::Impl::Graph::Token Engine::Impl::Graph::sinkStep(Token slot) {
    PMSC_NODE_BODY(&runDone);
    takeOver(slot);
    takeOver(&bodies.sink);  // the serial sink's calls follow one another
    timed(clocks[kSink], [&] { bodies.sink(*slot); });
    control.frameFinished();
    if (options.progress && !control.cancelled()) {
        Progress p;
        p.framesDone = control.delivered.load(std::memory_order_relaxed);
        p.framesTotal = range.count;
        p.hits = control.hits.load(std::memory_order_relaxed);
        p.blends = control.blends.load(std::memory_order_relaxed);
        p.misses = control.misses.load(std::memory_order_relaxed);
        p.failed = control.failed.load(std::memory_order_relaxed);
        p.elapsedSeconds = std::chrono::duration<double>(Clock::now() - start).count();
        options.progress(p);
    }
    handOver(&bodies.sink);
    handOver(slot);
    return slot;
}

void Engine::Impl::Graph::wire() {
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
    flow::make_edge(flow::output_port<3>(monitor), localBranch);
    flow::make_edge(localBranch, localGather);
    flow::make_edge(flow::output_port<0>(localGather), sequencer);
    flow::make_edge(sequencer, sinkNode);
    flow::make_edge(sinkNode, tokens);
}

void Engine::Impl::Graph::run(std::span<const std::unique_ptr<FrameSlot>> slots) {
    for (auto& slot : slots) {
        handOver(slot.get());
        tokens.try_put(slot.get());
    }
    handOver(&source);
    sourceNode.activate();
    g.wait_for_all();
    // Everything the graph's threads wrote is visible after wait_for_all().
    for (auto& slot : slots) takeOver(slot.get());
    takeOver(&bodies.sink);
    takeOver(&source);
    takeOver(&runDone);
}

void Engine::Impl::runGraph(FrameRange range, FrameSink& sink, nodes::RunControl& control, Clocks& clocks,
                            std::span<const std::unique_ptr<FrameSlot>> slots, Clock::time_point start) {
    Bodies bodies(*this, sink, control);
#if defined(__SANITIZE_THREAD__)
    // Declared before the graph, so it runs after the graph is destroyed: this thread leaves
    // with checks back on.
    struct ChecksBackOn {
        ~ChecksBackOn() { setIgnoring(false); }
    } checksBackOn;
    setIgnoring(true);  // from here this thread runs TBB's code too (building, waiting, destroying)
#endif
    Graph graph(*this, bodies, range, control, clocks, start);
    graph.wire();
    graph.run(slots);
}

}  // namespace pmsc::engine
