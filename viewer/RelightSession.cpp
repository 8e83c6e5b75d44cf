#include "viewer/RelightSession.h"

#include "engine/Engine.h"
#include "pmsc/Errors.h"
#include "viewer/HalfCache.h"
#include "viewer/SceneBytes.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <thread>

namespace pmsc::viewer {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

/// The frames of a viewer: frame f is the full calculation for the f-th request's controls. The
/// engine sees one evaluator whose frames grow as the lighter moves the light; only the newest
/// few are kept (a frame is evaluated only while its request runs).
class LightFrames : public PointEvaluator {
public:
    explicit LightFrames(const std::shared_ptr<const PointEvaluator>& first) : first_(first) {
        frames_.push_back(first);
    }

    Index append(std::shared_ptr<const PointEvaluator> e) {
        std::lock_guard<std::mutex> lock(mutex_);
        frames_.push_back(std::move(e));
        const size_t n = frames_.size();
        if (n > kKept) frames_[n - kKept - 1].reset();
        return Index(n) - 1;
    }

    std::string name() const override { return first_->name(); }
    Index pointCount() const override { return first_->pointCount(); }
    Index channelCount() const override { return first_->channelCount(); }
    Index frameCount() const override {
        std::lock_guard<std::mutex> lock(mutex_);
        return Index(frames_.size());
    }
    FailThroughShape failThroughShape() const override { return first_->failThroughShape(); }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        at(frame)->evaluate(0, points, out);
    }
    void evaluateAll(Index frame, double* out) const override { at(frame)->evaluateAll(0, out); }

private:
    static constexpr size_t kKept = 4;

    std::shared_ptr<const PointEvaluator> at(Index frame) const {
        std::lock_guard<std::mutex> lock(mutex_);
        if (frame < 0 || size_t(frame) >= frames_.size() || !frames_[size_t(frame)])
            throw std::runtime_error("viewer frame " + std::to_string(frame) + " is no longer held");
        return frames_[size_t(frame)];
    }

    std::shared_ptr<const PointEvaluator> first_;
    mutable std::mutex mutex_;
    std::vector<std::shared_ptr<const PointEvaluator>> frames_;
};

std::string stateName(CacheState s) { return std::string(toString(s)); }

/// A client's request: new control values (for the cache or the full calculation) or the
/// reference (the full calculation for the difference view).
struct Request {
    enum class Kind { Relight, Reference } kind = Kind::Relight;
    std::uint32_t seq = 0;
    Controls controls;
    bool full = false;  ///< answer with the full calculation (the page's "full" view)
    Clock::time_point received;
    double receivedUnixMs = 0;  ///< the same moment by the system clock, ms since 1970 (UTC)
};

std::uint32_t sequenceOf(const nlohmann::json& msg) {
    const auto it = msg.find("seq");
    if (it == msg.end() || !it->is_number_integer() || it->get<std::int64_t>() < 0 ||
        it->get<std::int64_t>() > std::int64_t(UINT32_MAX))
        throw InputError("message '" + msg.value("type", std::string()) +
                         "' needs \"seq\": an integer in [0, 2^32)");
    return it->get<std::uint32_t>();
}

Controls controlsOf(const nlohmann::json& msg) {
    const auto it = msg.find("controls");
    if (it == msg.end() || !it->is_object())
        throw InputError("message 'set' needs \"controls\": an object of numbers");
    Controls c;
    for (const auto& [name, value] : it->items()) {
        if (!value.is_number()) throw InputError("control '" + name + "' is not a number");
        c[name] = value.get<double>();
    }
    return c;
}

}  // namespace

std::string Update::binary(Index channels) const {
    std::string out;
    out.reserve(16 + halfs.size() * 2);
    appendBytes(out, std::uint32_t(0x564d5350));  // "PSMV"
    appendBytes(out, seq);
    appendBytes(out, first);
    appendBytes(out, std::uint32_t(halfs.size() / size_t(channels)));
    out.append(reinterpret_cast<const char*>(halfs.data()), halfs.size() * sizeof(std::uint16_t));
    return out;
}

struct RelightSession::Impl : engine::FrameSink {
    const Model& model;
    const RelightScene& scene;
    Emit emit;
    const Index points, channels;
    LightFrames frames;
    std::atomic<bool> cancel{false};
    std::unique_ptr<engine::Engine> engine;      ///< the soft cache
    std::unique_ptr<engine::Engine> fullEngine;  ///< every frame a miss: the full view, the reference
    HalfCache* target = nullptr;                 ///< what the running request updates
    const char* targetName = "cache";
    bool fullRun = false;  ///< the running request is a full calculation

    // What the page holds, updated in the order the updates are emitted (under emitMutex).
    std::mutex emitMutex;
    HalfCache cache, reference;
    Index pointsDone = 0;
    bool estimateSent = false;  ///< the running request's estimate is in the page's cache
    double encodeMs = 0;

    // The request being answered (set by the worker before a run; read by the engine's callbacks).
    Request current;
    nlohmann::json currentLight;
    CacheState deliveredState = CacheState::Hit;
    double deliveredWeight = 0, deliveredKeyError = 0;

    // The queue: only the newest request of each kind waits.
    mutable std::mutex queueMutex;
    std::condition_variable wake;
    std::optional<Request> pendingRelight, pendingReference;
    Controls lastControls;
    bool fullView = false, running = false, stopping = false;
    Counts counts;
    std::thread worker;

    Impl(const Model& m, const RelightScene& s, int threads, Emit e)
        : model(m),
          scene(s),
          emit(std::move(e)),
          points(s.pointCount()),
          channels(m.channels),
          frames(s.evaluator(s.defaults())),
          cache(s.pointCount(), m.channels),
          reference(s.pointCount(), m.channels),
          lastControls(s.defaults()) {
        if (m.points != points || m.channels != frames.channelCount()) {
            throw InputError("the model has " + std::to_string(m.points) + " points x " +
                             std::to_string(m.channels) + " channels, the " + s.kind() + " scene " +
                             std::to_string(points) + " x " + std::to_string(frames.channelCount()) +
                             ": train it on this scene's frames (pmsc demo " + s.kind() +
                             " --out DIR writes DIR/model.pmsc and DIR/scene.txt)");
        }
        engine::EngineOptions o;
        o.threads = threads;
        o.maxFramesInFlight = 1;
        // Every branch of a fail-through is a range the page can show as it arrives.
        o.localFailThrough = false;
        // One frame at a time, every core on it: the keys and a hit's check points in pieces (volume:
        // 250 keys in 8, 1,024 sentinels in 32). The check keeps every core too. Computing it in
        // one call would leave a core to a page on the same machine while it draws the hit's
        // image, but on 2 cores that gave no faster first image and a later checked one
        // (docs/results/viewer.md).
        o.keyPiecePoints = 32;
        // The page shows half floats: a float basis halves the memory a hit's reconstruction
        // reads (volume: 81 MB of doubles) and changes no half by more than its last bit.
        o.basisPrecision = BasisPrecision::Single;
        // A hit's image goes out before its check (the 1,024 sentinels: on the volume 11 ms of a
        // hit's 21 ms in the server), as a miss's estimate goes out before its branches: the
        // light moves on the keys' time. The final update says whether the check let it stand.
        o.estimateBeforeCheck = true;
        o.cancel = &cancel;
        o.onEstimate = [this](const engine::FrameEstimate& f) { sendEstimate(f); };
        o.onChunk = [this](const engine::ChunkFinished& c) { sendChunk(c); };
        engine = std::make_unique<engine::Engine>(model, frames, o);  // checks N and C
        // The full calculation in the same branches, cancelled the same way: no estimate to show.
        o.onEstimate = nullptr;
        o.estimateBeforeCheck = false;
        o.policy = SoftCachePolicy::alwaysMiss();
        fullEngine = std::make_unique<engine::Engine>(model, frames, std::move(o));
        worker = std::thread([this] { loop(); });
    }

    ~Impl() override {
        {
            std::lock_guard<std::mutex> lock(queueMutex);
            stopping = true;
            cancel = true;
        }
        wake.notify_all();
        worker.join();
    }

    nlohmann::json header(const char* target, const char* phase, const std::string& state) const {
        return {{"type", "update"},        {"seq", current.seq},
                {"target", target},        {"phase", phase},
                {"state", state},          {"eps_min", model.epsMin},
                {"eps_max", model.epsMax}, {"light", currentLight},
                {"points_total", points},  {"received_unix_ms", current.receivedUnixMs}};
    }

    /// Writes values into `target`, and emits them. Caller holds emitMutex.
    void sendRange(HalfCache& target, nlohmann::json text, Index first, std::span<const double> values,
                   bool withChecksum) {
        const auto t = Clock::now();
        Update u;
        u.seq = current.seq;
        u.first = std::uint32_t(first);
        const auto h = target.write(first, values);
        u.halfs.assign(h.begin(), h.end());
        text["checksum"] = withChecksum ? target.checksum() : std::string();
        encodeMs += msSince(t);
        text["points_done"] = pointsDone;
        text["converged"] = false;
        text["timing_ms"] = {{"since_request", msSince(current.received)}};
        u.text = std::move(text);
        emit(std::move(u));
    }

    void sendEstimate(const engine::FrameEstimate& f) {
        std::lock_guard<std::mutex> lock(emitMutex);
        nlohmann::json text = header("cache", "estimate", stateName(f.state));
        text["weight"] = f.weight;
        text["key_error"] = f.keyError;
        sendRange(cache, std::move(text), 0, f.values, true);
        estimateSent = true;
    }

    void sendChunk(const engine::ChunkFinished& c) {
        std::lock_guard<std::mutex> lock(emitMutex);
        pointsDone += Index(c.values.size()) / channels;
        nlohmann::json text = header(targetName, "chunk", fullRun ? "full" : stateName(c.state));
        text["weight"] = c.weight;
        // The whole array's checksum costs about a millisecond per 250,000 points: only the
        // estimate and the final carry one.
        sendRange(*target, std::move(text), c.firstOutput, c.values, false);
    }

    // engine::FrameSink: the frame the engine delivers (a hit's reconstruction lands here).
    void write(const engine::FrameResult& r) override {
        std::lock_guard<std::mutex> lock(emitMutex);
        deliveredState = r.state;
        deliveredWeight = r.weight;
        deliveredKeyError = r.keyError;
        if (r.state == CacheState::Hit && !fullRun && !estimateSent) {  // else the cache holds it
            const auto t = Clock::now();
            cache.write(0, r.values);
            encodeMs += msSince(t);
        }
    }

    /// The final update of a request: for a hit the whole cache, else only the convergence.
    void sendFinal(HalfCache& target, const char* targetName, const std::string& state, bool withValues,
                   nlohmann::json timing) {
        std::lock_guard<std::mutex> lock(emitMutex);
        const auto t = Clock::now();
        Update u;
        u.seq = current.seq;
        if (withValues) u.halfs.assign(target.values().begin(), target.values().end());
        nlohmann::json text = header(targetName, "final", state);
        text["checksum"] = target.checksum();
        encodeMs += msSince(t);
        text["points_done"] = points;
        text["converged"] = true;
        timing["encode"] = encodeMs;
        timing["since_request"] = msSince(current.received);
        text["timing_ms"] = std::move(timing);
        if (state != "full") {
            text["weight"] = deliveredWeight;
            text["key_error"] = deliveredKeyError;
        }
        u.text = std::move(text);
        emit(std::move(u));
    }

    void error(const std::string& message) {
        std::lock_guard<std::mutex> lock(emitMutex);
        Update u;
        u.text = {{"type", "error"}, {"message", message}};
        u.binaryFollows = false;
        emit(std::move(u));
    }

    void loop() {
        for (;;) {
            Request r;
            {
                std::unique_lock<std::mutex> lock(queueMutex);
                wake.wait(lock, [&] { return stopping || pendingRelight || pendingReference; });
                if (stopping) return;
                if (pendingRelight) {
                    r = *pendingRelight;
                    pendingRelight.reset();
                } else {
                    r = *pendingReference;
                    pendingReference.reset();
                }
                cancel = false;
                running = true;
            }
            answer(r);
            std::lock_guard<std::mutex> lock(queueMutex);
            running = false;
        }
    }

    void answer(const Request& r) {
        try {
            {
                std::lock_guard<std::mutex> lock(emitMutex);
                current = r;
                currentLight = scene.light(r.controls);
                pointsDone = 0;
                encodeMs = 0;
                estimateSent = false;
                const bool toReference = r.kind == Request::Kind::Reference;
                target = toReference ? &reference : &cache;
                targetName = toReference ? "reference" : "cache";
                fullRun = toReference || r.full;
            }
            run(r);
        } catch (const Cancelled&) {
            std::lock_guard<std::mutex> lock(queueMutex);
            ++counts.cancelled;
        } catch (const std::exception& e) {
            error(std::string("frame ") + std::to_string(r.seq) + ": " + e.what());
        }
    }

    /// One request through the engine: the soft cache (keys, projection, the error monitor's
    /// decision, then the reconstruction or the fail-through branches, streamed by the callbacks),
    /// or for the full view and the reference the same graph with every frame a miss.
    void run(const Request& r) {
        const Index frame = frames.append(scene.evaluator(r.controls));
        engine::Engine& e = fullRun ? *fullEngine : *engine;
        e.run(engine::FrameRange{frame, 1, 1}, *this);
        const engine::RunStats& stats = e.lastStats();
        nlohmann::json timing;
        for (const auto& n : stats.nodes) {
            std::string name = n.node;
            std::replace(name.begin(), name.end(), '-', '_');
            if (n.calls > 0) timing[name] = n.seconds * 1e3;
        }
        timing["engine_wall"] = stats.wallSeconds * 1e3;
        std::string state = fullRun ? "full" : stateName(deliveredState);
        {
            std::lock_guard<std::mutex> lock(queueMutex);
            if (fullRun)
                ++counts.full;
            else if (deliveredState == CacheState::Hit)
                ++counts.hits;
            else if (deliveredState == CacheState::Blend)
                ++counts.blends;
            else
                ++counts.misses;
        }
        bool withValues = false;
        {
            std::lock_guard<std::mutex> lock(emitMutex);
            withValues = !fullRun && deliveredState == CacheState::Hit && !estimateSent;
        }
        sendFinal(*target, targetName, state, withValues, std::move(timing));
    }

    void receive(const std::string& text) {
        nlohmann::json msg;
        try {
            msg = nlohmann::json::parse(text);
        } catch (const nlohmann::json::exception&) {
            throw InputError("malformed message: not JSON");
        }
        if (!msg.is_object() || !msg.contains("type") || !msg["type"].is_string())
            throw InputError("malformed message: needs \"type\": set, mode or reference");
        const std::string type = msg["type"];
        Request r;
        r.received = Clock::now();
        r.receivedUnixMs =
            std::chrono::duration<double, std::milli>(std::chrono::system_clock::now().time_since_epoch())
                .count();
        if (type == "set") {
            r.seq = sequenceOf(msg);
            r.controls = scene.resolve(controlsOf(msg));
        } else if (type == "reference") {
            r.seq = sequenceOf(msg);
            r.kind = Request::Kind::Reference;
        } else if (type == "mode") {
            const std::string view = msg.value("view", std::string());
            if (view != "cache" && view != "full")
                throw InputError("message 'mode' needs \"view\": cache or full");
            std::lock_guard<std::mutex> lock(queueMutex);
            fullView = view == "full";
            return;
        } else {
            throw InputError("unknown message type '" + type + "' (set, mode or reference)");
        }
        {
            std::lock_guard<std::mutex> lock(queueMutex);
            if (r.kind == Request::Kind::Relight) {
                r.full = fullView;
                lastControls = r.controls;
                pendingRelight = r;
            } else {
                r.controls = lastControls;
                pendingReference = r;
            }
            // New controls make the frame in progress out of date; a reference waits for it.
            if (running && r.kind == Request::Kind::Relight) cancel = true;
        }
        wake.notify_one();
    }
};

RelightSession::RelightSession(const Model& model, const RelightScene& scene, int threads, Emit emit)
    : impl_(std::make_unique<Impl>(model, scene, threads, std::move(emit))) {}

RelightSession::~RelightSession() = default;

void RelightSession::receive(const std::string& text) { impl_->receive(text); }

RelightSession::Counts RelightSession::counts() const {
    std::lock_guard<std::mutex> lock(impl_->queueMutex);
    return impl_->counts;
}

}  // namespace pmsc::viewer
