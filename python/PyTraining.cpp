// pmsc.train and pmsc.learn: `pmsc train` and `pmsc learn` on NumPy arrays or .npy paths, with the same
// options (app/Train.h, app/Learn.h) and the same model bytes.
#include "app/Learn.h"
#include "app/Train.h"
#include "python/Arrays.h"
#include "python/PyErrors.h"
#include "python/PyModel.h"

#include "pmsc/Communicator.h"
#include "pmsc/Errors.h"
#include "pmsc/NpyIO.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Training.h"

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

namespace pmsc::python {

using namespace pybind11::literals;

namespace {

/// One training set from what Python hands over: an array (F, N, C), a .npy path, or a list of either
/// (shots, concatenated in order as `pmsc train --frames A --frames B` does).
struct TrainingFrames {
    std::optional<FrameArray> view;  ///< a single float64 C-order array: trained from in place
    FrameSet copy;                   ///< otherwise the frames as doubles
};

void appendShot(FrameSet& all, const FrameSet& shot, const std::string& name, const std::string& firstName) {
    if (all.frames == 0) {
        all = shot;
        return;
    }
    if (shot.points != all.points || shot.channels != all.channels)
        throw InputError(name + ": " + std::to_string(shot.points) + " points x " +
                         std::to_string(shot.channels) + " channels, but " + firstName + " has " +
                         std::to_string(all.points) + " x " + std::to_string(all.channels));
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
        const std::string name = isPath(shots[i])    ? pathOf(shots[i])
                                 : shots.size() == 1 ? "frames"
                                                     : "frames[" + std::to_string(i) + "]";
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

/// A progress hook for training or learning on this thread (where Ctrl-C is noticed): it takes the
/// GIL only to call `progress` and to check signals, a few hundred times per call at most.
class PythonProgress {
public:
    explicit PythonProgress(py::object progress) : progress_(std::move(progress)) {}
    ProgressFn function() {
        return [this](std::string_view stage, double done, double total) {
            py::gil_scoped_acquire gil;
            try {
                if (PyErr_CheckSignals() != 0) throw py::error_already_set();
                if (!progress_.is_none()) {
                    py::object r = progress_(std::string(stage), done, total);
                    if (!r.is_none() && !r.cast<bool>()) return false;
                }
                return true;
            } catch (py::error_already_set& e) {
                error_.emplace(std::move(e));
                return false;
            }
        };
    }
    /// Runs `work` (training or learning) with the GIL released; when it was cancelled by
    /// KeyboardInterrupt or by what `progress` raised, that is what propagates.
    template <class Work>
    void run(Work&& work) {
        try {
            py::gil_scoped_release nogil;
            work();
        } catch (const Cancelled&) {
            if (error_) throw std::move(*error_);
            throw;
        }
    }

private:
    py::object progress_;
    std::optional<py::error_already_set> error_;
};

/// A positions argument: a .npy path, or an array (N, 3+) or (1, N, 3+); None: an empty name.
/// Checked against N (app::positionsFromTable) once the frames are known.
struct PositionsArgument {
    FrameSet table;
    std::string name;
};

PositionsArgument positionsArgument(const py::object& positions, const std::string& command) {
    PositionsArgument out;
    if (py::isinstance<py::str>(positions)) {
        out.name = "positions " + positions.cast<std::string>();
        out.table = readPointTable(positions.cast<std::string>()).frames;
    } else if (!positions.is_none()) {
        const auto a = doubleArray(positions);
        if (a.ndim() != 2 && !(a.ndim() == 3 && a.shape(0) == 1))
            throw InputError(command + ": positions must be an array (N, 3) or (1, N, 3), got " +
                             shapeText(a));
        const Index rows = a.shape(a.ndim() - 2), cols = a.shape(a.ndim() - 1);
        out.table = FrameSet(1, rows, cols);
        std::copy(a.data(), a.data() + rows * cols, out.table.values.begin());
        out.name = "positions";
    }
    return out;
}

std::shared_ptr<PyModel> trainModel(py::handle frames, Index basis, double energy, double basisError,
                                    Index maxBasis, double maxError, Index maxKeys, Index block,
                                    std::vector<Index> fiducials, std::vector<Index> gridPoints,
                                    const std::string& selector, double tolerance, Index slices,
                                    const std::string& calibration, const py::object& coverage,
                                    const std::string& keyError, Index learnRank, unsigned seed,
                                    int powerIterations, const py::object& regions, const py::object& feather,
                                    Index regionKeys, Index regionStride, bool sharedChannels,
                                    Index sentinels, bool clamp, const py::object& positions,
                                    py::object progress) {
    // The keyword arguments into app::TrainOptions, checked by the rules `pmsc train` uses.
    constexpr app::Spelling kPython = app::Spelling::Python;
    app::TrainOptions request;
    TrainingOptions& o = request.training;
    o.basis = basis;
    o.energy = energy;
    o.basisMaxError = basisError;
    o.maxBasis = maxBasis;
    o.maxError = maxError;
    o.maxKeys = maxKeys;
    o.block = block;
    o.fiducials = std::move(fiducials);
    o.gridPoints = std::move(gridPoints);
    o.selector = app::selectorNamed(selector, kPython);
    o.tolerance = tolerance;
    o.calibrationSlices = slices;
    o.calibrationRule = app::calibrationNamed(calibration, kPython);
    if (!coverage.is_none()) request.coverage = coverage.cast<double>();
    o.keyErrorNorm = app::keyErrorNamed(keyError, kPython);
    o.learnRank = learnRank;
    o.seed = seed;
    o.powerIterations = powerIterations;
    if (py::isinstance<py::str>(regions)) {
        app::setRegions(o.regions, regions.cast<std::string>(), kPython);
    } else {
        o.regions.automatic = false;
        o.regions.count = regions.cast<Index>();
    }
    if (!feather.is_none()) {
        o.regions.featherFraction = feather.cast<double>();
        o.regions.automaticFeather = false;
    }
    o.regions.frameStride = regionStride;
    o.regions.ownKeys = regionKeys;
    o.sharedChannels = sharedChannels;
    o.sentinels = sentinels;
    o.clampAtZero = clamp;
    const PositionsArgument given = positionsArgument(positions, "train");
    const std::string& positionsName = given.name;
    request.positions = positionsName;  // validate() refuses them with a cross target
    app::validate(request, kPython);

    TrainingFrames t = trainingFrames(frames);
    if (!positionsName.empty())
        o.regions.positions =
            app::positionsFromTable(given.table, t.view ? t.view->points() : t.copy.points, positionsName);
    PythonProgress hook(progress);
    o.progress = hook.function();
    TrainingReport report;
    Model model;
    hook.run([&] {
        if (t.view && o.sharedChannels && t.view->channels() > 1) {
            // Channels sharing the basis train from a frame set in memory (the channels become frames).
            const FrameArray& a = *t.view;
            FrameSet copy(a.frames(), a.points(), a.channels());
            std::copy(a.doubles(), a.doubles() + copy.values.size(), copy.values.begin());
            model = train(copy, o, &report);
        } else if (t.view) {
            // A float64 C-order array is the training matrix Q as it lies ((N*C) x F, column-major):
            // centred straight from it, the one copy training makes anyway.
            const FrameArray& a = *t.view;
            if (a.frames() < 2)
                throw InputError("train: need at least 2 training frames, got " + std::to_string(a.frames()));
            const Eigen::Map<const Eigen::MatrixXd> q(a.doubles(), a.points() * a.channels(), a.frames());
            MatrixBlocks blocks(q, a.channels(), /*centre=*/true);
            SingleProcess one;
            model = train(blocks, one, o, &report);
        } else {
            model = train(t.copy, o, &report);
        }
    });
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

std::shared_ptr<PyModel> learnModel(const PyModel& model, py::handle frames, Index basis, double energy,
                                    Index rank, const std::string& calibration, const py::object& coverage,
                                    Index slices, const py::object& positions, bool regions,
                                    py::object progress) {
    // The keyword arguments into app::LearnOptions, checked by the rules `pmsc learn` uses.
    constexpr app::Spelling kPython = app::Spelling::Python;
    app::LearnOptions request;
    pmsc::LearnOptions& o = request.learning;
    o.basis = basis;
    o.energy = energy;
    o.maxRank = rank;
    o.rule = app::calibrationNamed(calibration, kPython);
    if (!coverage.is_none()) o.coverage = coverage.cast<double>();
    o.slices = slices;
    o.regions = regions;
    app::validate(request, kPython);
    app::checkLearnable(model.get(), "model");

    TrainingFrames t = trainingFrames(frames);
    if (t.view) {
        const FrameArray& a = *t.view;
        t.copy = FrameSet(a.frames(), a.points(), a.channels());
        std::copy(a.doubles(), a.doubles() + t.copy.values.size(), t.copy.values.begin());
    }
    app::checkFramesFit(model.get(), "model", t.copy, "frames");
    const PositionsArgument given = positionsArgument(positions, "learn");
    if (!given.name.empty())
        o.positions = app::positionsFromTable(given.table, model.get().points, given.name, "learn");
    PythonProgress hook(std::move(progress));
    o.progress = hook.function();
    LearnReport report;
    Model learned;
    hook.run([&] { learned = learn(model.get(), t.copy, o, &report); });
    auto result = std::make_shared<PyModel>(std::move(learned));
    py::dict r;
    r["warnings"] = report.warnings;
    r["new_frames"] = report.newFrames;
    r["basis_before"] = report.basisBefore;
    r["basis_after"] = report.basisAfter;
    r["keys_kept"] = report.keysKept;
    r["region_keys"] = report.regionKeys;
    r["seconds"] = report.seconds;
    r["new_frames_max_point_error"] = report.newFramesMaxPointError;
    result->trainingReport = r;
    return result;
}

}  // namespace

void bindTraining(py::module_& m) {
    m.def(
        "train", &trainModel, "frames"_a, py::kw_only(), "basis"_a = 0, "energy"_a = 0.0,
        "basis_error"_a = 0.0, "max_basis"_a = 256, "max_error"_a = 0.0, "max_keys"_a = 200, "block"_a = 16,
        "fiducials"_a = std::vector<Index>{}, "grid_points"_a = std::vector<Index>{},
        "selector"_a = "teleconnection", "tolerance"_a = 0.0, "slices"_a = 5, "calibration"_a = "",
        "coverage"_a = py::none(), "key_error"_a = "", "learn_rank"_a = 0, "seed"_a = 20070101u,
        "power_iterations"_a = 2, "regions"_a = "auto", "feather"_a = py::none(), "region_keys"_a = 4,
        "region_stride"_a = 3, "shared_channels"_a = false, "sentinels"_a = kDefaultSentinels,
        "clamp"_a = true, "positions"_a = py::none(), "progress"_a = py::none(),
        "Trains a model as `pmsc train` does (same options, same model bytes). frames: an array (F, N, C), a "
        ".npy path, or a list of them (shots). positions: the points' positions for values that are not "
        "positions (light), an array (N, 3) or (1, N, 3) or a .npy path, as --positions. clamp=False: as "
        "--no-clamp. "
        "progress(stage, "
        "done, "
        "total) may return False to cancel.");
    m.def(
        "learn", &learnModel, "model"_a, "frames"_a, py::kw_only(), "basis"_a = 0, "energy"_a = 0.0,
        "rank"_a = 0, "calibration"_a = "", "coverage"_a = py::none(), "slices"_a = 0,
        "positions"_a = py::none(), "regions"_a = true, "progress"_a = py::none(),
        "Updates a model with new frames as `pmsc learn` does (same options, same model bytes), without its "
        "training frames. frames: an array (F, N, C), a .npy path, or a list of them. Returns the learned "
        "model; its training_report says what the update did. positions: the positions the model was "
        "trained with, as train's positions (--positions). regions=False: as --no-regions.");
}

}  // namespace pmsc::python
