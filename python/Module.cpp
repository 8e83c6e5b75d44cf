// The Python module `pmsc` (issue 13): training, the model, replay and the evaluation engine from Python,
// with NumPy arrays in and out. Every long call releases the GIL; errors are the command line's one-line
// messages as Python exceptions (pmsc.InputError, pmsc.EvaluatorError, pmsc.IoError, pmsc.Cancelled).
#include "python/Arrays.h"
#include "python/Evaluators.h"

#include "cli/ExitCodes.h"
#include "cli/Replay.h"
#include "engine/Engine.h"
#include "evaluators/EvaluatorRegistry.h"
#include "evaluators/ReplayEvaluator.h"
#include "pmsc/Communicator.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Training.h"

#include <pybind11/eval.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <condition_variable>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

namespace py = pybind11;
using namespace pybind11::literals;

namespace pmsc::python {
namespace {

// --- errors -----------------------------------------------------------------------------------------

/// The exception classes, made once at import (Python code, so they subclass the builtins naturally).
const char* kExceptions = R"(
class Error(Exception):
    """A pmsc failure; str(e) is the line `pmsc` prints after "pmsc: ", e.exit_code its exit code."""
    exit_code = 1
class InputError(Error, ValueError):
    """Bad input: a file, an array's shape/dtype/values, an option, sizes that disagree (exit code 2)."""
    exit_code = 2
class EvaluatorError(Error, RuntimeError):
    """A point evaluator failed; a Python evaluator's own exception is the __cause__ (exit code 3)."""
    exit_code = 3
class IoError(Error, OSError):
    """An output could not be written (exit code 4)."""
    exit_code = 4
class Cancelled(Error):
    """A run or a training was cancelled (exit code 130)."""
    exit_code = 130
)";

py::object exceptionClass(const char* name) { return py::module_::import("pmsc").attr(name); }

/// Sets the Python error for a pmsc exception: the class by kind, the message exactly as the command
/// line prints it after "pmsc: " (cli::exitReason), and an optional cause.
void setPythonError(std::exception_ptr error, py::object cause = py::none()) {
    const cli::ExitReason reason = cli::exitReason(error);
    const char* name = "Error";
    switch (reason.code) {
        case cli::kExitBadInput: name = "InputError"; break;
        case cli::kExitEvaluator: name = "EvaluatorError"; break;
        case cli::kExitIo: name = "IoError"; break;
        case cli::kExitInterrupted: name = "Cancelled"; break;
        default: break;
    }
    py::object type = exceptionClass(name);
    py::object value = type(reason.message);
    if (!cause.is_none()) PyException_SetCause(value.ptr(), cause.inc_ref().ptr());
    PyErr_SetObject(type.ptr(), value.ptr());
}

void translate(std::exception_ptr p) {
    try {
        std::rethrow_exception(p);
    } catch (const InputError&) {
        setPythonError(p);
    } catch (const EvaluatorError&) {
        setPythonError(p);
    } catch (const IoError&) {
        setPythonError(p);
    } catch (const Cancelled&) {
        setPythonError(p);
    } catch (const std::invalid_argument&) {
        setPythonError(p);  // bad options: exit code 2 on the command line too
    }
    // Anything else goes on to pybind11's own translators.
}

// --- running with the GIL released, interruptible ---------------------------------------------------------

/// Runs fn() on a worker thread with the GIL released while this thread waits, checking Python's
/// signals every 50 ms: Ctrl-C sets `cancel` (the engine then stops within a node body's time) and
/// raises KeyboardInterrupt once the worker has stopped. The engine's threads, and a Python evaluator's
/// calls, never wait for this thread.
template <class Fn>
void runReleased(std::atomic<bool>& cancel, Fn&& fn) {
    std::mutex mutex;
    std::condition_variable finished;
    bool done = false;
    std::exception_ptr error;
    std::optional<py::error_already_set> interrupt;
    {
        py::gil_scoped_release nogil;
        std::thread worker([&] {
            try {
                // A Python thread state for this thread while it works (released at once): the
                // evaluator's calls on it reuse it, and it is deleted when the run ends.
                py::gil_scoped_acquire state;
                py::gil_scoped_release released;
                fn();
            } catch (...) {
                error = std::current_exception();
            }
            std::lock_guard lock(mutex);
            done = true;
            finished.notify_all();
        });
        for (;;) {
            {
                std::unique_lock lock(mutex);
                if (finished.wait_for(lock, std::chrono::milliseconds(50), [&] { return done; })) break;
            }
            py::gil_scoped_acquire gil;
            if (!interrupt && PyErr_CheckSignals() != 0) {
                interrupt.emplace();  // fetches KeyboardInterrupt (or whatever the handler raised)
                cancel = true;
            }
        }
        worker.join();
    }
    if (interrupt) {
        error = nullptr;
        throw std::move(*interrupt);
    }
    if (error) std::rethrow_exception(error);
}

// --- the model ----------------------------------------------------------------------------------------------

/// A model plus its runtime (PointMultiplier) and, after pmsc.train(), what training reported.
struct PyModel {
    std::shared_ptr<const Model> model;
    std::unique_ptr<PointMultiplier> multiplier;
    py::dict trainingReport;

    explicit PyModel(Model m) : model(std::make_shared<const Model>(std::move(m))), multiplier(new PointMultiplier(*model)) {}
    const Model& get() const { return *model; }
};

/// Key values in: (K, C), (K*C,) or a batch (F, K, C) / (F, K*C). Returns the array and the batch size
/// (-1 for a single frame).
std::pair<py::array_t<double, py::array::c_style>, py::ssize_t> keyBatch(const Model& m, py::handle keys) {
    auto a = doubleArray(keys);
    const py::ssize_t kc = static_cast<py::ssize_t>(m.keyCount() * m.channels);
    const py::ssize_t last = a.ndim() == 0 ? 0 : a.shape(a.ndim() - 1);
    const bool kByC = a.ndim() >= 2 && a.shape(a.ndim() - 2) == m.keyCount() && last == m.channels;
    if ((a.ndim() == 2 && kByC) || (a.ndim() == 1 && last == kc)) return {a, -1};
    if ((a.ndim() == 3 && kByC) || (a.ndim() == 2 && last == kc)) return {a, a.shape(0)};
    throw InputError("keys: shape " + shapeText(a) + " is not (K, C) = (" + std::to_string(m.keyCount()) + ", " +
                     std::to_string(m.channels) + "), (K*C,) or a batch (frames, K, C)");
}

std::pair<py::array_t<double, py::array::c_style>, py::ssize_t> coordBatch(const Model& m, py::handle coords) {
    auto a = doubleArray(coords);
    const py::ssize_t mm = static_cast<py::ssize_t>(m.basisSize());
    if (a.ndim() == 1 && a.shape(0) == mm) return {a, -1};
    if (a.ndim() == 2 && a.shape(1) == mm) return {a, a.shape(0)};
    throw InputError("coords: shape " + shapeText(a) + " is not (M,) = (" + std::to_string(mm) + ",) or (frames, M)");
}

py::array project(const PyModel& self, py::handle keys) {
    const Model& m = self.get();
    auto [k, batch] = keyBatch(m, keys);
    const py::ssize_t frames = batch < 0 ? 1 : batch, kc = m.keyCount() * m.channels, mm = m.basisSize();
    py::array_t<double> out(batch < 0 ? std::vector<py::ssize_t>{mm} : std::vector<py::ssize_t>{batch, mm});
    const double* in = k.data();
    double* o = out.mutable_data();
    py::gil_scoped_release nogil;
    for (py::ssize_t f = 0; f < frames; ++f) self.multiplier->project(in + f * kc, o + f * mm);
    return out;
}

py::object keyError(const PyModel& self, py::handle keys, py::object coords) {
    const Model& m = self.get();
    auto [k, batch] = keyBatch(m, keys);
    py::array_t<double, py::array::c_style> b = coords.is_none() ? py::array_t<double, py::array::c_style>(project(self, k))
                                                                 : coordBatch(m, coords).first;
    const py::ssize_t frames = batch < 0 ? 1 : batch, kc = m.keyCount() * m.channels, mm = m.basisSize();
    const py::ssize_t coordFrames = b.ndim() == 2 ? b.shape(0) : -1;
    if (coordFrames != batch || b.size() != frames * mm)
        throw InputError("key_error: " + std::to_string(frames) + " frames of keys but coords of shape " + shapeText(b));
    py::array_t<double> out(frames);
    const double *in = k.data(), *bc = b.data();
    double* o = out.mutable_data();
    {
        py::gil_scoped_release nogil;
        for (py::ssize_t f = 0; f < frames; ++f) o[f] = self.multiplier->keyRmsError(in + f * kc, bc + f * mm);
    }
    if (batch < 0) return py::float_(o[0]);
    return out;
}

py::array reconstruct(const PyModel& self, py::handle coords, py::object pointsArg) {
    const Model& m = self.get();
    auto [b, batch] = coordBatch(m, coords);
    const py::ssize_t frames = batch < 0 ? 1 : batch, mm = m.basisSize();
    std::vector<Index> points;
    if (!pointsArg.is_none()) {
        auto p = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(pointsArg);
        if (!p || p.ndim() != 1) throw InputError("points: expected a 1-d array of point indices");
        points.assign(p.data(), p.data() + p.size());
        for (const Index i : points)
            if (i < 0 || i >= m.points)
                throw InputError("points: index " + std::to_string(i) + " outside [0, " + std::to_string(m.points) + ")");
    }
    const py::ssize_t n = pointsArg.is_none() ? m.points : static_cast<py::ssize_t>(points.size());
    const py::ssize_t c = m.channels, values = n * c;
    py::array_t<double> out(batch < 0 ? std::vector<py::ssize_t>{n, c} : std::vector<py::ssize_t>{batch, n, c});
    const double* in = b.data();
    double* o = out.mutable_data();
    const bool all = pointsArg.is_none();
    py::gil_scoped_release nogil;
    for (py::ssize_t f = 0; f < frames; ++f) {
        if (all) self.multiplier->reconstruct(in + f * mm, o + f * values);
        else self.multiplier->reconstructPoints(in + f * mm, points, o + f * values);
    }
    return out;
}

py::dict modelInfo(const Model& m) {
    py::dict d;
    d["points"] = m.points;
    d["channels"] = m.channels;
    d["basis"] = m.basisSize();
    d["key_points"] = m.keyCount();
    d["train_frames"] = m.trainFrames;
    d["eps_min"] = m.epsMin;
    d["eps_max"] = m.epsMax;
    d["tolerance"] = m.tolerance;
    d["energy_captured"] = m.energyCaptured();
    d["train_max_point_residual"] = m.trainMaxPointResidual;
    d["selector"] = m.selector == Selector::QDeim ? "qdeim" : "teleconnection";
    d["regions"] = m.regions ? m.regions->regionCount() : 0;
    return d;
}

// --- training ------------------------------------------------------------------------------------------------

/// One training set from what Python hands over: an array (F, N, C), a .npy path, or a list of either
/// (shots, concatenated in order as `pmsc train --frames A --frames B` does).
struct TrainingFrames {
    std::optional<FrameArray> view;  ///< a single float64 C-order array: trained from in place
    FrameSet copy;                   ///< otherwise the frames as doubles
};

bool isPath(py::handle h) { return py::isinstance<py::str>(h) || py::hasattr(h, "__fspath__"); }
std::string pathOf(py::handle h) { return py::str(py::module_::import("os").attr("fspath")(h)).cast<std::string>(); }

void appendShot(FrameSet& all, const FrameSet& shot, const std::string& name, const std::string& firstName) {
    if (all.frames == 0) {
        all = shot;
        return;
    }
    if (shot.points != all.points || shot.channels != all.channels)
        throw InputError(name + ": " + std::to_string(shot.points) + " points x " + std::to_string(shot.channels) +
                         " channels, but " + firstName + " has " + std::to_string(all.points) + " x " +
                         std::to_string(all.channels));
    all.values.insert(all.values.end(), shot.values.begin(), shot.values.end());
    all.frames += shot.frames;
}

TrainingFrames trainingFrames(py::handle frames) {
    TrainingFrames t;
    std::vector<py::handle> shots;
    if (py::isinstance<py::list>(frames) || py::isinstance<py::tuple>(frames)) {
        for (py::handle h : frames) shots.push_back(h);
        if (shots.empty()) throw InputError("train: no frames given");
    } else {
        shots.push_back(frames);
    }
    std::string firstName;
    for (std::size_t i = 0; i < shots.size(); ++i) {
        const std::string name = isPath(shots[i]) ? pathOf(shots[i]) : shots.size() == 1 ? "frames" : "frames[" + std::to_string(i) + "]";
        if (i == 0) firstName = name;
        if (isPath(shots[i])) {
            FrameFile f;
            {
                py::gil_scoped_release nogil;
                f = readFrames(name);
            }
            appendShot(t.copy, f.frames, name, firstName);
            continue;
        }
        FrameArray a(shots[i], name);
        if (shots.size() == 1 && a.doubles()) {
            t.view.emplace(std::move(a));
            return t;
        }
        FrameSet s(a.frames(), a.points(), a.channels());
        {
            py::gil_scoped_release nogil;
            for (Index f = 0; f < a.frames(); ++f) a.readFrame(f, s.frame(f));
        }
        appendShot(t.copy, s, name, firstName);
    }
    return t;
}

Selector selectorOf(const std::string& s) {
    if (s == "teleconnection") return Selector::Teleconnection;
    if (s == "qdeim") return Selector::QDeim;
    throw InputError("selector: '" + s + "' is not teleconnection or qdeim");
}

CalibrationRule ruleOf(const std::string& s) {
    if (s == "max") return CalibrationRule::MaxRatio;
    if (s == "conformal") return CalibrationRule::Conformal;
    throw InputError("calibration: '" + s + "' is not max or conformal");
}

std::shared_ptr<PyModel> trainModel(py::handle frames, Index basis, double energy, double basisError, Index maxBasis,
                                    double maxError, Index maxKeys, Index block, std::vector<Index> fiducials,
                                    std::vector<Index> gridPoints, const std::string& selector, double tolerance,
                                    Index slices, const std::string& calibration, double coverage, Index learnRank,
                                    unsigned seed, int powerIterations, Index regions, double feather,
                                    py::object progress) {
    TrainingOptions o;
    o.basis = basis;
    o.energy = energy;
    o.basisMaxError = basisError;
    o.maxBasis = maxBasis;
    o.maxError = maxError;
    o.maxKeys = maxKeys;
    o.block = block;
    o.fiducials = std::move(fiducials);
    o.gridPoints = std::move(gridPoints);
    o.selector = selectorOf(selector);
    o.tolerance = tolerance;
    o.calibrationSlices = slices;
    o.calibrationRule = ruleOf(calibration);
    o.calibrationCoverage = coverage;
    o.learnRank = learnRank;
    o.seed = seed;
    o.powerIterations = powerIterations;
    o.regions.count = regions;
    o.regions.featherFraction = feather;
    if (regions < 0) throw InputError("regions: must be >= 0 (0 = none), got " + std::to_string(regions));
    if (!(feather >= 0 && feather <= 0.5)) throw InputError("feather: must be in [0, 0.5], got " + std::to_string(feather));
    if (calibration != "max" && !(tolerance > 0)) throw InputError("calibration and coverage need a tolerance");

    TrainingFrames t = trainingFrames(frames);
    // Training runs on this thread (its progress hook is where Ctrl-C is noticed); the hook takes the
    // GIL only to call `progress` and to check signals, a few hundred times per training at most.
    std::optional<py::error_already_set> pythonError;
    o.progress = [&](std::string_view stage, double done, double total) {
        py::gil_scoped_acquire gil;
        try {
            if (PyErr_CheckSignals() != 0) throw py::error_already_set();
            if (!progress.is_none()) {
                py::object r = progress(std::string(stage), done, total);
                if (!r.is_none() && !r.cast<bool>()) return false;
            }
            return true;
        } catch (py::error_already_set& e) {
            pythonError.emplace(std::move(e));
            return false;
        }
    };
    TrainingReport report;
    Model model;
    try {
        py::gil_scoped_release nogil;
        if (t.view) {
            // A float64 C-order array is the training matrix Q as it lies ((N*C) x F, column-major):
            // centred straight from it, the one copy training makes anyway.
            const FrameArray& a = *t.view;
            if (a.frames() < 2) throw InputError("train: need at least 2 training frames, got " + std::to_string(a.frames()));
            const Eigen::Map<const Eigen::MatrixXd> q(a.doubles(), a.points() * a.channels(), a.frames());
            MatrixBlocks blocks(q, a.channels(), /*centre=*/true);
            SingleProcess one;
            model = train(blocks, one, o, &report);
        } else {
            model = train(t.copy, o, &report);
        }
    } catch (const Cancelled&) {
        if (pythonError) throw std::move(*pythonError);  // KeyboardInterrupt, or what `progress` raised
        throw;
    }
    auto result = std::make_shared<PyModel>(std::move(model));
    py::dict r;
    r["warnings"] = report.warnings;
    r["requested_basis"] = report.requestedBasis;
    r["iterations"] = report.iterations;
    r["seconds"] = report.seconds;
    r["residual_per_round"] = report.residualPerRound;
    r["calibration_ratio"] = report.calibration.ratio;
    result->trainingReport = r;
    return result;
}

// --- replay and run ---------------------------------------------------------------------------------------------

py::object jsonToPython(const std::string& text) { return py::module_::import("json").attr("loads")(text); }

std::optional<std::pair<double, double>> epsOf(py::object eps) {
    if (eps.is_none()) return std::nullopt;
    const auto e = eps.cast<std::pair<double, double>>();
    if (!(e.first >= 0 && e.first <= e.second && std::isfinite(e.second)))
        throw InputError("eps: need 0 <= MIN <= MAX, got (" + std::to_string(e.first) + ", " + std::to_string(e.second) + ")");
    return e;
}

void checkMatches(const Model& m, const PointEvaluator& e, const std::string& what) {
    if (e.pointCount() != m.points || e.channelCount() != m.channels)
        throw InputError(what + ": frames have " + std::to_string(e.pointCount()) + " points x " +
                         std::to_string(e.channelCount()) + " channels, but the model was trained on " +
                         std::to_string(m.points) + " points x " + std::to_string(m.channels) + " channels");
}

py::tuple replayFrames(const PyModel& self, py::handle frames, py::object eps, int threads, bool wholeFrame) {
    const Model& m = self.get();
    if (threads < 0) throw InputError("threads: must be >= 0 (0 = every core), got " + std::to_string(threads));
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

    cli::ReplayOptions options;
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
    cli::ReplayResult result;
    std::string report;
    runReleased(cancel, [&] {
        result = cli::replay(m, *recorded, options);
        report = cli::replayReport(m, result).dump();
    });
    return py::make_tuple(out, jsonToPython(report));
}

/// The frames of a run: a range (step > 0), a count (range(n)), or None (every frame of the evaluator).
engine::FrameRange frameRange(py::object frames, Index evaluatorFrames) {
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
        row = {r.frame, r.state, r.weight, r.keyRmsError, r.failed, r.local, r.pointsEvaluated, r.error};
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

py::tuple runEngine(const PyModel& self, py::object evaluator, py::object frames, int threads, py::object points,
                    py::object eps, const std::string& failure, bool wholeFrame, Index chunkPoints, py::object dtypeArg,
                    Index maxFramesInFlight, Index frameCount) {
    const Model& m = self.get();
    if (threads < 0) throw InputError("threads: must be >= 0 (0 = every core), got " + std::to_string(threads));
    std::unique_ptr<PointEvaluator> owned;
    CallableEvaluator* callable = nullptr;
    engine::FrameRange range;
    if (py::isinstance<py::str>(evaluator)) {
        const std::string spec = evaluator.cast<std::string>();
        {
            py::gil_scoped_release nogil;
            owned = evaluators::EvaluatorRegistry::withBuiltins().make(spec);
        }
        range = frameRange(frames, owned->frameCount());
    } else if (PyCallable_Check(evaluator.ptr())) {
        range = frameRange(frames, 0);
        const Index needed = range.last() + 1;
        if (frameCount > 0 && frameCount < needed)
            throw InputError("frame_count: " + std::to_string(frameCount) + " but the range reaches frame " +
                             std::to_string(range.last()));
        PointEvaluator::FailThroughShape shape;
        shape.wholeFrame = wholeFrame;
        // A Python call costs tens of microseconds of interpreter time under the GIL, so a Python
        // evaluator fails through in 8 chunks per frame rather than the engine's ~64 (C++ evaluators):
        // fewer, larger calls, and still work for every thread with 2 x threads frames in flight.
        const Index outputPoints = points.is_none() ? m.points : static_cast<Index>(py::len(points));
        shape.chunkPoints = std::max<Index>(256, (outputPoints + 7) / 8);
        auto c = std::make_unique<CallableEvaluator>(evaluator, m.points, m.channels, std::max(frameCount, needed), shape);
        callable = c.get();
        owned = std::move(c);
    } else {
        throw InputError("evaluator: expected a callable f(frame, point_indices) -> values or a spec 'NAME:ARGS' "
                         "(replay:FILE.npy, skin:ASSET)");
    }

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
    NpyDtype dtype = NpyDtype::Float64;
    if (!dtypeArg.is_none()) {
        const py::dtype dt = py::dtype::from_args(dtypeArg);
        if (dt.kind() == 'f' && dt.itemsize() == 4) dtype = NpyDtype::Float32;
        else if (!(dt.kind() == 'f' && dt.itemsize() == 8)) throw InputError("dtype: pmsc writes float32 or float64");
    }

    std::unique_ptr<engine::Engine> engine;
    {
        py::gil_scoped_release nogil;
        engine = std::make_unique<engine::Engine>(m, *owned, std::move(o));
    }
    const Index outPoints = static_cast<Index>(engine->outputPoints().size());
    py::array out = newArray(dtype, {range.count, outPoints, m.channels});
    ArraySink sink(out.mutable_data(), dtype, static_cast<std::size_t>(outPoints * m.channels), range.count);
    engine::RunStats stats;
    try {
        runReleased(cancel, [&] { stats = engine->run(range, sink); });
    } catch (const EvaluatorError&) {
        // A Python evaluator's own exception is the cause of the one-line EvaluatorError.
        if (callable && !callable->firstError().is_none()) {
            setPythonError(std::current_exception(), callable->firstError());
            throw py::error_already_set();
        }
        throw;
    }
    py::list rows;
    for (const auto& r : sink.rows()) {
        py::dict d("frame"_a = r.frame, "state"_a = std::string(toString(r.state)), "weight"_a = r.weight,
                   "key_rms"_a = r.keyRms, "failed"_a = r.failed);
        if (r.failed) d["error"] = r.error;
        if (r.local) d["points_evaluated"] = r.pointsEvaluated;
        rows.append(d);
    }
    py::dict report;
    report["summary"] = jsonToPython(stats.toJson());
    report["frames"] = rows;
    return py::make_tuple(out, report);
}

}  // namespace
}  // namespace pmsc::python

PYBIND11_MODULE(pmsc, m) {
    using namespace pmsc;
    using namespace pmsc::python;
    m.doc() = "Point Multiplication and Soft Caching (Meyer & Anderson, Pixar): train a model from NumPy frames, "
              "replay recorded frames through its soft cache, and run the evaluation engine with a C++ or a "
              "Python evaluator. Frames are arrays of shape (frames, points, channels), float32 or float64.";
    py::exec(kExceptions, m.attr("__dict__"));
    py::register_exception_translator(&translate);
    m.attr("__version__") = "0.1.0";

    py::class_<PyModel, std::shared_ptr<PyModel>>(m, "Model",
        "A trained model: mean, basis, key points, projector and soft-cache thresholds (a .pmsc file).")
        .def_static("load", [](const std::filesystem::path& path) {
            Model model;
            { py::gil_scoped_release nogil; model = readModel(path.string()); }
            return std::make_shared<PyModel>(std::move(model));
        }, "path"_a, "Reads a .pmsc model (pmsc.InputError naming the file and the problem).")
        .def("save", [](const PyModel& self, const std::filesystem::path& path) {
            py::gil_scoped_release nogil;
            writeModel(path.string(), self.get());
        }, "path"_a, "Writes the model atomically (pmsc.IoError if it cannot).")
        .def_static("from_bytes", [](py::bytes b) {
            return std::make_shared<PyModel>(decodeModel(std::string(b), "<bytes>"));
        }, "data"_a, "A model from the bytes of a .pmsc file.")
        .def("to_bytes", [](const PyModel& self) { return py::bytes(encodeModel(self.get())); },
             "The bytes of the model's .pmsc file.")
        .def(py::pickle([](const PyModel& self) { return py::bytes(encodeModel(self.get())); },
                        [](py::bytes b) { return std::make_shared<PyModel>(decodeModel(std::string(b), "<pickle>")); }))
        .def_property_readonly("points", [](const PyModel& s) { return s.get().points; }, "N")
        .def_property_readonly("channels", [](const PyModel& s) { return s.get().channels; }, "C")
        .def_property_readonly("basis_size", [](const PyModel& s) { return s.get().basisSize(); }, "M")
        .def_property_readonly("key_count", [](const PyModel& s) { return s.get().keyCount(); }, "K")
        .def_property_readonly("train_frames", [](const PyModel& s) { return s.get().trainFrames; })
        .def_property_readonly("eps", [](const PyModel& s) { return py::make_tuple(s.get().epsMin, s.get().epsMax); },
                               "(eps_min, eps_max): soft-cache thresholds on the key RMS error, data units")
        .def_property_readonly("tolerance", [](const PyModel& s) { return s.get().tolerance; })
        .def_property_readonly("energy_captured", [](const PyModel& s) { return s.get().energyCaptured(); })
        .def_property_readonly("key_points", [](const PyModel& s) {
            py::array_t<std::int64_t> k(s.get().keyCount());
            std::copy(s.get().keyPoints.begin(), s.get().keyPoints.end(), k.mutable_data());
            return k;
        }, "the K key point indices, in selection order (a copy)")
        .def_property_readonly("mean", [](py::object self) {
            const Model& m = self.cast<const PyModel&>().get();
            return readOnlyView(m.mean.data(), {m.points, m.channels}, {m.channels, 1}, self);
        }, "(N, C) training mean, a read-only view")
        .def_property_readonly("basis", [](py::object self) {
            const Model& m = self.cast<const PyModel&>().get();
            return readOnlyView(m.basis.data(), {m.points, m.channels, m.basisSize()},
                                {m.channels, 1, m.points * m.channels}, self);
        }, "(N, C, M) basis vectors, a read-only view")
        .def_property_readonly("singular_values", [](py::object self) {
            const Model& m = self.cast<const PyModel&>().get();
            return readOnlyView(m.singularValues.data(), {m.basisSize()}, {1}, self);
        })
        .def_property_readonly("projector", [](py::object self) {
            const Model& m = self.cast<const PyModel&>().get();
            return readOnlyView(m.projector.data(), {m.basisSize(), m.keyCount() * m.channels},
                                {1, m.basisSize()}, self);
        }, "(M, K*C) least-squares projector, a read-only view")
        .def_property_readonly("info", [](const PyModel& s) { return modelInfo(s.get()); },
                               "sizes, eps, tolerance, energy, as `pmsc inspect` shows them")
        .def_property_readonly("training_report", [](const PyModel& s) { return s.trainingReport; },
                               "what pmsc.train() reported (warnings, seconds, ...); empty for a loaded model")
        .def("project", &project, "keys"_a,
             "Pose-space coordinates (M,) of key values (K, C), or (F, M) of a batch (F, K, C).")
        .def("reconstruct", &reconstruct, "coords"_a, "points"_a = py::none(),
             "Point values (N, C) from coordinates (M,) — or (F, N, C) from (F, M); only `points` when given.")
        .def("key_error", &keyError, "keys"_a, "coords"_a = py::none(),
             "The key points' RMS error (the soft cache's measure, data units) of key values (K, C) or a batch.")
        .def("__repr__", [](const PyModel& s) {
            const Model& m = s.get();
            return "<pmsc.Model N=" + std::to_string(m.points) + " C=" + std::to_string(m.channels) + " M=" +
                   std::to_string(m.basisSize()) + " K=" + std::to_string(m.keyCount()) + ">";
        });

    m.def("train", &trainModel, "frames"_a, py::kw_only(), "basis"_a = 0, "energy"_a = 0.0, "basis_error"_a = 0.0,
          "max_basis"_a = 256, "max_error"_a = 0.0, "max_keys"_a = 200, "block"_a = 16,
          "fiducials"_a = std::vector<Index>{}, "grid_points"_a = std::vector<Index>{},
          "selector"_a = "teleconnection", "tolerance"_a = 0.0, "slices"_a = 5, "calibration"_a = "max",
          "coverage"_a = 0.9, "learn_rank"_a = 0, "seed"_a = 20070101u, "power_iterations"_a = 2,
          "regions"_a = 0, "feather"_a = 0.03, "progress"_a = py::none(),
          "Trains a model as `pmsc train` does (same options, same model bytes). frames: an array (F, N, C), a "
          ".npy path, or a list of them (shots). progress(stage, done, total) may return False to cancel.");
    m.def("replay", &replayFrames, "model"_a, "frames"_a, py::kw_only(), "eps"_a = py::none(), "threads"_a = 0,
          "whole_frame_fail_through"_a = false,
          "Replays recorded frames (an array (F, N, C) or a .npy path) through the model's soft cache, as "
          "`pmsc replay` does: returns (out, report), out in the frames' dtype (bit for bit `pmsc replay --out`), "
          "report the REPORT.json as a dict.");
    m.def("run", &runEngine, "model"_a, "evaluator"_a, "frames"_a = py::none(), py::kw_only(), "threads"_a = 0,
          "points"_a = py::none(), "eps"_a = py::none(), "failure"_a = "stop", "whole_frame_fail_through"_a = false,
          "chunk_points"_a = 0, "dtype"_a = py::none(), "max_frames_in_flight"_a = 0, "frame_count"_a = 0,
          "Runs the evaluation engine over `frames` (a range, a count, or None = every frame of a spec evaluator). "
          "evaluator: a spec 'replay:FILE.npy' / 'skin:ASSET', or a Python callable f(frame, point_indices) -> "
          "values (P, C). Returns (out (frames, points, C), report {'summary': run stats, 'frames': rows}).");
}
