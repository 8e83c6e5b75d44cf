// pmsc.replay and pmsc.run: the engine over NumPy arrays, with C++ or Python evaluators.
#include "python/Arrays.h"
#include "python/Evaluators.h"
#include "python/PyErrors.h"
#include "python/PyModel.h"

#include "app/Replay.h"
#include "engine/Engine.h"
#include "evaluators/EvaluatorRegistry.h"
#include "evaluators/ReplayEvaluator.h"
#include "pmsc/Errors.h"

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

namespace pmsc::python {

using namespace pybind11::literals;

namespace {

py::object jsonToPython(const std::string& text) { return py::module_::import("json").attr("loads")(text); }

std::optional<std::pair<double, double>> epsOf(const py::object& eps) {
    if (eps.is_none()) return std::nullopt;
    const auto e = eps.cast<std::pair<double, double>>();
    app::checkEps(e, app::Spelling::Python);
    return e;
}

void checkMatches(const Model& m, const PointEvaluator& e, const std::string& what) {
    if (e.pointCount() != m.points || e.channelCount() != m.channels)
        throw InputError(what + ": frames have " + std::to_string(e.pointCount()) + " points x " +
                         std::to_string(e.channelCount()) + " channels, but the model was trained on " +
                         std::to_string(m.points) + " points x " + std::to_string(m.channels) + " channels");
}

py::tuple replayFrames(const PyModel& self, py::handle frames, const py::object& eps, int threads,
                       bool wholeFrame) {
    const Model& m = self.get();
    if (threads < 0)
        throw InputError("threads: must be >= 0 (0 = every core), got " + std::to_string(threads));
    std::unique_ptr<PointEvaluator> recorded;
    NpyDtype dtype = NpyDtype::Float64;
    std::string what = "frames";
    if (isPath(frames)) {
        // A .npy path: memory-mapped, exactly as `pmsc replay --frames` reads it.
        what = pathOf(frames);
        std::unique_ptr<evaluators::ReplayEvaluator> r;
        {
            py::gil_scoped_release nogil;
            r = std::make_unique<evaluators::ReplayEvaluator>(what);
        }
        dtype = r->dtype();
        recorded = std::move(r);
    } else {
        auto a = std::make_unique<ArrayEvaluator>(FrameArray(frames, "frames"));
        dtype = a->frames().dtype();
        recorded = std::move(a);
    }
    checkMatches(m, *recorded, what);

    app::ReplayOptions options;
    options.eps = epsOf(eps);
    options.threads = threads;
    options.localFailThrough = !wholeFrame;
    std::atomic<bool> cancel{false};
    options.cancel = &cancel;
    const std::size_t values = static_cast<std::size_t>(m.points * m.channels);
    py::array out = newArray(dtype, {recorded->frameCount(), m.points, m.channels});
    void* data = out.mutable_data();
    options.frameOut = [&](Index sequence, const double* v) {
        storeValues(data, dtype, static_cast<std::size_t>(sequence) * values, v, values);
    };
    app::ReplayResult result;
    std::string report;
    runReleased(cancel, [&] {
        result = app::replay(m, *recorded, options);
        report = app::replayReport(m, result).dump();
    });
    return py::make_tuple(out, jsonToPython(report));
}

/// The frames of a run: a range (step > 0), a count (range(n)), or None (every frame of the evaluator).
engine::FrameRange frameRange(const py::object& frames, Index evaluatorFrames) {
    if (frames.is_none()) {
        if (evaluatorFrames <= 0) throw InputError("frames: a Python evaluator needs frames=range(...)");
        return {0, evaluatorFrames, 1};
    }
    if (py::isinstance<py::int_>(frames)) {
        const Index n = frames.cast<Index>();
        if (n < 1) throw InputError("frames: need at least 1 frame, got " + std::to_string(n));
        return {0, n, 1};
    }
    if (!py::isinstance(frames, py::module_::import("builtins").attr("range")))
        throw InputError("frames: expected a range (first, stop, step > 0), a frame count or None");
    const Index start = frames.attr("start").cast<Index>(), step = frames.attr("step").cast<Index>();
    const Index count = py::len(frames);
    if (step < 1) throw InputError("frames: the range's step must be > 0, got " + std::to_string(step));
    if (count < 1 || start < 0) throw InputError("frames: the range is empty or starts below 0");
    return {start, count, step};
}

engine::FailurePolicy failureOf(const std::string& s) {
    if (s == "stop") return engine::FailurePolicy::StopRun;
    if (s == "continue") return engine::FailurePolicy::MarkFailedAndContinue;
    throw InputError("failure: '" + s + "' is not stop or continue");
}

/// Keeps every frame of a run in a NumPy array (written by the engine's serial sink, GIL not needed)
/// and one row per frame for the report.
class ArraySink final : public engine::FrameSink {
public:
    struct Row {
        Index frame = 0;
        CacheState state = CacheState::Hit;
        double weight = 0, keyRms = 0;
        bool failed = false, local = false;
        Index pointsEvaluated = 0;
        std::string error;
    };
    ArraySink(void* data, NpyDtype dtype, std::size_t valuesPerFrame, Index frames)
        : data_(data), dtype_(dtype), values_(valuesPerFrame), rows_(static_cast<std::size_t>(frames)) {}

    void write(const engine::FrameResult& r) override {
        Row& row = rows_[static_cast<std::size_t>(r.sequence)];
        row = {r.frame, r.state, r.weight, r.keyError, r.failed, r.local, r.pointsEvaluated, r.error};
        const std::size_t at = static_cast<std::size_t>(r.sequence) * values_;
        if (!r.failed) {
            storeValues(data_, dtype_, at, r.values.data(), values_);
        } else {
            // A failed frame (failure="continue") has no values: NaN, never stale memory.
            const std::vector<double> nan(values_, std::numeric_limits<double>::quiet_NaN());
            storeValues(data_, dtype_, at, nan.data(), values_);
        }
    }
    const std::vector<Row>& rows() const { return rows_; }

private:
    void* data_;
    NpyDtype dtype_;
    std::size_t values_;
    std::vector<Row> rows_;
};

/// The evaluator of a run and the frames it covers.
struct RunEvaluator {
    std::unique_ptr<PointEvaluator> evaluator;
    CallableEvaluator* callable = nullptr;  ///< when it is a Python callable
    engine::FrameRange range;
};

/// A spec ("replay:FILE.npy", "volume:FILE.vdb", ...: the registry the command line uses) or a
/// Python callable.
RunEvaluator makeRunEvaluator(const Model& m, const py::object& evaluator, const py::object& frames,
                              const py::object& points, bool wholeFrame, Index frameCount) {
    RunEvaluator r;
    if (py::isinstance<py::str>(evaluator)) {
        const std::string spec = evaluator.cast<std::string>();
        {
            py::gil_scoped_release nogil;
            r.evaluator = evaluators::makeEvaluator(spec);
        }
        r.range = frameRange(frames, r.evaluator->frameCount());
        return r;
    }
    if (!PyCallable_Check(evaluator.ptr()))
        throw InputError(
            "evaluator: expected a callable f(frame, point_indices) -> values or a spec 'NAME[:ARGS]' "
            "(pmsc.evaluators() lists the names)");
    r.range = frameRange(frames, 0);
    const Index needed = r.range.last() + 1;
    if (frameCount > 0 && frameCount < needed)
        throw InputError("frame_count: " + std::to_string(frameCount) + " but the range reaches frame " +
                         std::to_string(r.range.last()));
    PointEvaluator::FailThroughShape shape;
    shape.wholeFrame = wholeFrame;
    // A Python call costs tens of microseconds of interpreter time under the GIL, so a Python
    // evaluator fails through in 8 chunks per frame rather than the engine's ~64 (C++ evaluators):
    // fewer, larger calls, and still work for every thread with 2 x threads frames in flight.
    const Index outputPoints = points.is_none() ? m.points : static_cast<Index>(py::len(points));
    shape.chunkPoints = std::max<Index>(256, (outputPoints + 7) / 8);
    auto c = std::make_unique<CallableEvaluator>(evaluator, m.points, m.channels,
                                                 std::max(frameCount, needed), shape);
    r.callable = c.get();
    r.evaluator = std::move(c);
    return r;
}

NpyDtype outputDtype(const py::object& dtype) {
    if (dtype.is_none()) return NpyDtype::Float64;
    const py::dtype dt = py::dtype::from_args(dtype);
    if (dt.kind() == 'f' && dt.itemsize() == 4) return NpyDtype::Float32;
    if (dt.kind() == 'f' && dt.itemsize() == 8) return NpyDtype::Float64;
    throw InputError("dtype: pmsc writes float32 or float64");
}

py::list reportRows(const ArraySink& sink) {
    py::list rows;
    for (const auto& r : sink.rows()) {
        py::dict d("frame"_a = r.frame, "state"_a = std::string(toString(r.state)), "weight"_a = r.weight,
                   "key_rms"_a = r.keyRms, "failed"_a = r.failed);
        if (r.failed) d["error"] = r.error;
        if (r.local) d["points_evaluated"] = r.pointsEvaluated;
        rows.append(d);
    }
    return rows;
}

py::tuple runEngine(const PyModel& self, const py::object& evaluator, const py::object& frames, int threads,
                    const py::object& points, const py::object& eps, const std::string& failure,
                    bool wholeFrame, Index chunkPoints, const py::object& dtypeArg, Index maxFramesInFlight,
                    Index frameCount) {
    const Model& m = self.get();
    if (threads < 0)
        throw InputError("threads: must be >= 0 (0 = every core), got " + std::to_string(threads));
    RunEvaluator run = makeRunEvaluator(m, evaluator, frames, points, wholeFrame, frameCount);

    engine::EngineOptions o;
    o.threads = threads;
    o.failurePolicy = failureOf(failure);
    o.chunkPoints = chunkPoints;
    o.wholeFrameFailThrough = wholeFrame;
    o.maxFramesInFlight = maxFramesInFlight;
    if (const auto e = epsOf(eps)) o.policy = SoftCachePolicy(e->first, e->second);
    if (!points.is_none()) {
        auto p = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(points);
        if (!p || p.ndim() != 1) throw InputError("points: expected a 1-d array of point indices");
        o.pointsWanted.assign(p.data(), p.data() + p.size());
    }
    std::atomic<bool> cancel{false};
    o.cancel = &cancel;
    const NpyDtype dtype = outputDtype(dtypeArg);

    std::unique_ptr<engine::Engine> engine;
    {
        py::gil_scoped_release nogil;
        engine = std::make_unique<engine::Engine>(m, *run.evaluator, std::move(o));
    }
    const Index outPoints = static_cast<Index>(engine->outputPoints().size());
    py::array out = newArray(dtype, {run.range.count, outPoints, m.channels});
    ArraySink sink(out.mutable_data(), dtype, static_cast<std::size_t>(outPoints * m.channels),
                   run.range.count);
    engine::RunStats stats;
    try {
        runReleased(cancel, [&] { stats = engine->run(run.range, sink); });
    } catch (const EvaluatorError&) {
        // A Python evaluator's own exception is the cause of the one-line EvaluatorError.
        if (run.callable && !run.callable->firstError().is_none()) {
            setPythonError(std::current_exception(), run.callable->firstError());
            throw py::error_already_set();
        }
        throw;
    }
    py::dict report;
    report["summary"] = jsonToPython(stats.toJson());
    report["frames"] = reportRows(sink);
    return py::make_tuple(out, report);
}

}  // namespace

void bindRuns(py::module_& m) {
    m.def("replay", &replayFrames, "model"_a, "frames"_a, py::kw_only(), "eps"_a = py::none(),
          "threads"_a = 0, "whole_frame_fail_through"_a = false,
          "Replays recorded frames (an array (F, N, C) or a .npy path) through the model's soft cache, as "
          "`pmsc replay` does: returns (out, report), out in the frames' dtype (bit for bit `pmsc replay "
          "--out`), "
          "report the REPORT.json as a dict.");
    m.def(
        "run", &runEngine, "model"_a, "evaluator"_a, "frames"_a = py::none(), py::kw_only(), "threads"_a = 0,
        "points"_a = py::none(), "eps"_a = py::none(), "failure"_a = "stop",
        "whole_frame_fail_through"_a = false, "chunk_points"_a = 0, "dtype"_a = py::none(),
        "max_frames_in_flight"_a = 0, "frame_count"_a = 0,
        "Runs the evaluation engine over `frames` (a range, a count, or None = every frame of a spec "
        "evaluator). "
        "evaluator: a spec 'NAME[:ARGS]' (pmsc.evaluators(): replay:FILE.npy, volume:FILE.vdb, ...), or a "
        "Python callable f(frame, point_indices) -> values (P, C). Returns (out (frames, points, C), report "
        "{'summary': run stats, 'frames': rows}).");
    m.def(
        "evaluators",
        [] {
            std::vector<std::string> names;
            for (const auto& kind : evaluators::builtinRegistry().kinds()) names.push_back(kind.name);
            return names;
        },
        "The names of the evaluators run() accepts as 'NAME[:ARGS]', as `pmsc evaluators` lists them.");
}

}  // namespace pmsc::python
