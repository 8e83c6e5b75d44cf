// pmsc.Model: sizes, read-only views of the arrays, the .pmsc file, and section 6 on NumPy arrays.
#include "python/PyModel.h"

#include "python/Arrays.h"

#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"

#include <pybind11/numpy.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <filesystem>
#include <vector>

namespace pmsc::python {

using namespace pybind11::literals;

bool isPath(py::handle h) { return py::isinstance<py::str>(h) || py::hasattr(h, "__fspath__"); }
std::string pathOf(py::handle h) {
    return py::str(py::module_::import("os").attr("fspath")(h)).cast<std::string>();
}

namespace {

/// Key values in: (K, C), (K*C,) or a batch (F, K, C) / (F, K*C). Returns the array and the batch size
/// (-1 for a single frame).
std::pair<py::array_t<double, py::array::c_style>, py::ssize_t> keyBatch(const Model& m, py::handle keys) {
    auto a = doubleArray(keys);
    const py::ssize_t kc = static_cast<py::ssize_t>(m.keyCount() * m.channels);
    const py::ssize_t last = a.ndim() == 0 ? 0 : a.shape(a.ndim() - 1);
    const bool kByC = a.ndim() >= 2 && a.shape(a.ndim() - 2) == m.keyCount() && last == m.channels;
    if ((a.ndim() == 2 && kByC) || (a.ndim() == 1 && last == kc)) return {a, -1};
    if ((a.ndim() == 3 && kByC) || (a.ndim() == 2 && last == kc)) return {a, a.shape(0)};
    throw InputError("keys: shape " + shapeText(a) + " is not (K, C) = (" + std::to_string(m.keyCount()) +
                     ", " + std::to_string(m.channels) + "), (K*C,) or a batch (frames, K, C)");
}

std::pair<py::array_t<double, py::array::c_style>, py::ssize_t> coordBatch(const Model& m,
                                                                           py::handle coords) {
    auto a = doubleArray(coords);
    const py::ssize_t mm = static_cast<py::ssize_t>(m.coordCount());
    if (a.ndim() == 1 && a.shape(0) == mm) return {a, -1};
    if (a.ndim() == 2 && a.shape(1) == mm) return {a, a.shape(0)};
    throw InputError("coords: shape " + shapeText(a) + " is not (M,) = (" + std::to_string(mm) +
                     ",) or (frames, M) (M x C values when the channels share the basis)");
}

py::array project(const PyModel& self, py::handle keys) {
    const Model& m = self.get();
    auto [k, batch] = keyBatch(m, keys);
    const py::ssize_t frames = batch < 0 ? 1 : batch, kc = m.keyCount() * m.channels, mm = m.coordCount();
    py::array_t<double> out(batch < 0 ? std::vector<py::ssize_t>{mm} : std::vector<py::ssize_t>{batch, mm});
    const double* in = k.data();
    double* o = out.mutable_data();
    py::gil_scoped_release nogil;
    for (py::ssize_t f = 0; f < frames; ++f) self.multiplier->project(in + f * kc, o + f * mm);
    return out;
}

py::object keyError(const PyModel& self, py::handle keys, const py::object& coords) {
    const Model& m = self.get();
    auto [k, batch] = keyBatch(m, keys);
    py::array_t<double, py::array::c_style> b =
        coords.is_none() ? py::array_t<double, py::array::c_style>(project(self, k))
                         : coordBatch(m, coords).first;
    const py::ssize_t frames = batch < 0 ? 1 : batch, kc = m.keyCount() * m.channels, mm = m.coordCount();
    const py::ssize_t coordFrames = b.ndim() == 2 ? b.shape(0) : -1;
    if (coordFrames != batch || b.size() != frames * mm)
        throw InputError("key_error: " + std::to_string(frames) + " frames of keys but coords of shape " +
                         shapeText(b));
    py::array_t<double> out(frames);
    const double *in = k.data(), *bc = b.data();
    double* o = out.mutable_data();
    {
        py::gil_scoped_release nogil;
        for (py::ssize_t f = 0; f < frames; ++f) o[f] = self.multiplier->keyError(in + f * kc, bc + f * mm);
    }
    if (batch < 0) return py::float_(o[0]);
    return out;
}

py::array reconstruct(const PyModel& self, py::handle coords, const py::object& pointsArg) {
    const Model& m = self.get();
    auto [b, batch] = coordBatch(m, coords);
    const py::ssize_t frames = batch < 0 ? 1 : batch, mm = m.coordCount();
    std::vector<Index> points;
    if (!pointsArg.is_none()) {
        auto p = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(pointsArg);
        if (!p || p.ndim() != 1) throw InputError("points: expected a 1-d array of point indices");
        points.assign(p.data(), p.data() + p.size());
        for (const Index i : points)
            if (i < 0 || i >= m.points)
                throw InputError("points: index " + std::to_string(i) + " outside [0, " +
                                 std::to_string(m.points) + ")");
    }
    const py::ssize_t n = pointsArg.is_none() ? m.points : static_cast<py::ssize_t>(points.size());
    const py::ssize_t c = m.channels, values = n * c;
    py::array_t<double> out(batch < 0 ? std::vector<py::ssize_t>{n, c}
                                      : std::vector<py::ssize_t>{batch, n, c});
    const double* in = b.data();
    double* o = out.mutable_data();
    const bool all = pointsArg.is_none();
    py::gil_scoped_release nogil;
    for (py::ssize_t f = 0; f < frames; ++f) {
        if (all)
            self.multiplier->reconstruct(in + f * mm, o + f * values);
        else
            self.multiplier->reconstructPoints(in + f * mm, points, o + f * values);
    }
    return out;
}

py::dict modelInfo(const Model& m) {
    py::dict d;
    d["points"] = m.points;
    d["channels"] = m.channels;
    d["basis"] = m.basisSize();
    d["shared_channels"] = m.sharedChannels;
    d["key_points"] = m.keyCount();
    d["sentinels"] = m.sentinels ? static_cast<Index>(m.sentinels->points.size()) : Index{0};
    d["non_negative"] = m.nonNegative;
    d["train_frames"] = m.trainFrames;
    d["eps_min"] = m.epsMin;
    d["eps_max"] = m.epsMax;
    d["key_error"] = toString(m.keyErrorNorm);
    if (m.keyErrorNorm == KeyErrorNorm::Predicted) {
        py::dict parts;
        parts["rms"] = m.partEps.rms;
        parts["loo"] = m.partEps.loo;
        d["key_error_parts_eps"] = parts;  // as `pmsc inspect --json`
    }
    d["tolerance"] = m.tolerance;
    d["energy_captured"] = m.energyCaptured();
    d["train_max_point_residual"] = m.trainMaxPointResidual;
    d["selector"] = m.selector == Selector::QDeim ? "qdeim" : "teleconnection";
    d["regions"] = m.regions ? m.regions->regionCount() : 0;
    return d;
}

}  // namespace

using ModelClass = py::class_<PyModel, std::shared_ptr<PyModel>>;

namespace {

/// pmsc.Model's files and bytes: load, save, from_bytes, to_bytes, pickle.
void bindModelFiles(ModelClass& c) {
    c.def_static(
         "load",
         [](const std::filesystem::path& path) {
             Model model;
             {
                 py::gil_scoped_release nogil;
                 model = readModel(path.string());
             }
             return std::make_shared<PyModel>(std::move(model));
         },
         "path"_a, "Reads a .pmsc model (pmsc.InputError naming the file and the problem).")
        .def(
            "save",
            [](const PyModel& self, const std::filesystem::path& path) {
                py::gil_scoped_release nogil;
                writeModel(path.string(), self.get());
            },
            "path"_a, "Writes the model atomically (pmsc.IoError if it cannot).")
        .def_static(
            "from_bytes",
            [](const py::bytes& b) {
                return std::make_shared<PyModel>(decodeModel(std::string(b), "<bytes>"));
            },
            "data"_a, "A model from the bytes of a .pmsc file.")
        .def(
            "to_bytes", [](const PyModel& self) { return py::bytes(encodeModel(self.get())); },
            "The bytes of the model's .pmsc file.")
        .def(py::pickle([](const PyModel& self) { return py::bytes(encodeModel(self.get())); },
                        [](const py::bytes& b) {
                            return std::make_shared<PyModel>(decodeModel(std::string(b), "<pickle>"));
                        }));
}

/// pmsc.Model's sizes, thresholds and read-only views, and its arithmetic.
/// A copy of point indices as an int64 array.
py::array_t<std::int64_t> indexArray(const std::vector<Index>& points) {
    py::array_t<std::int64_t> out(static_cast<py::ssize_t>(points.size()));
    std::copy(points.begin(), points.end(), out.mutable_data());
    return out;
}

void bindModelViews(ModelClass& c) {
    c.def_property_readonly(
         "points", [](const PyModel& s) { return s.get().points; }, "N")
        .def_property_readonly(
            "channels", [](const PyModel& s) { return s.get().channels; }, "C")
        .def_property_readonly(
            "basis_size", [](const PyModel& s) { return s.get().basisSize(); }, "M")
        .def_property_readonly(
            "key_count", [](const PyModel& s) { return s.get().keyCount(); }, "K")
        .def_property_readonly("train_frames", [](const PyModel& s) { return s.get().trainFrames; })
        .def_property_readonly(
            "eps", [](const PyModel& s) { return py::make_tuple(s.get().epsMin, s.get().epsMax); },
            "(eps_min, eps_max): soft-cache thresholds on the key RMS error, data units")
        .def_property_readonly("tolerance", [](const PyModel& s) { return s.get().tolerance; })
        .def_property_readonly("energy_captured", [](const PyModel& s) { return s.get().energyCaptured(); })
        .def_property_readonly(
            "key_points", [](const PyModel& s) { return indexArray(s.get().keyPoints); },
            "the K key point indices, in selection order (a copy)")
        .def_property_readonly(
            "sentinel_points",
            [](const PyModel& s) {
                const Model& m = s.get();
                return indexArray(m.sentinels ? m.sentinels->points : std::vector<Index>{});
            },
            "the sentinels' point indices (computed beside every hit), in the order training chose them; "
            "empty without them (a copy)")
        .def_property_readonly(
            "mean",
            [](const py::object& self) {
                const Model& m = self.cast<const PyModel&>().get();
                return readOnlyView(m.mean.data(), {m.points, m.channels}, {m.channels, 1}, self);
            },
            "(N, C) training mean, a read-only view")
        .def_property_readonly(
            "basis",
            [](const py::object& self) {
                const Model& m = self.cast<const PyModel&>().get();
                return readOnlyView(m.basis.data(), {m.points, m.basisChannels(), m.basisSize()},
                                    {m.basisChannels(), 1, m.points * m.basisChannels()}, self);
            },
            "(N, C, M) basis vectors, a read-only view ((N, 1, M) when the channels share the basis)")
        .def_property_readonly("singular_values",
                               [](const py::object& self) {
                                   const Model& m = self.cast<const PyModel&>().get();
                                   return readOnlyView(m.singularValues.data(), {m.basisSize()}, {1}, self);
                               })
        .def_property_readonly(
            "projector",
            [](const py::object& self) {
                const Model& m = self.cast<const PyModel&>().get();
                return readOnlyView(m.projector.data(), {m.basisSize(), m.keyCount() * m.basisChannels()},
                                    {1, m.basisSize()}, self);
            },
            "(M, K*C) least-squares projector, a read-only view ((M, K) when the channels share the basis)")
        .def_property_readonly(
            "info", [](const PyModel& s) { return modelInfo(s.get()); },
            "sizes, eps, tolerance, energy, as `pmsc inspect` shows them")
        .def_property_readonly(
            "training_report", [](const PyModel& s) { return s.trainingReport; },
            "what pmsc.train() reported (warnings, seconds, ...); empty for a loaded model")
        .def("project", &project, "keys"_a,
             "Pose-space coordinates (M,) of key values (K, C), or (F, M) of a batch (F, K, C).")
        .def(
            "reconstruct", &reconstruct, "coords"_a, "points"_a = py::none(),
            "Point values (N, C) from coordinates (M,) — or (F, N, C) from (F, M); only `points` when given. "
            "Clamped at 0 when info['non_negative'] (every training value was >= 0).")
        .def("key_error", &keyError, "keys"_a, "coords"_a = py::none(),
             "The key points' RMS error (the soft cache's measure, data units) of key values (K, C) or a "
             "batch.")
        .def("__repr__", [](const PyModel& s) {
            const Model& m = s.get();
            return "<pmsc.Model N=" + std::to_string(m.points) + " C=" + std::to_string(m.channels) +
                   " M=" + std::to_string(m.basisSize()) + " K=" + std::to_string(m.keyCount()) + ">";
        });
}

}  // namespace

void bindModel(py::module_& m) {
    ModelClass c(
        m, "Model",
        "A trained model: mean, basis, key points, projector and soft-cache thresholds (a .pmsc file).");
    bindModelFiles(c);
    bindModelViews(c);
}

}  // namespace pmsc::python
