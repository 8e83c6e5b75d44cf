// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
// pmsc.Model: a trained model as the Python module holds it.
#pragma once

#include "pmsc/Model.h"
#include "pmsc/PointMultiplier.h"

#include <pybind11/pybind11.h>

#include <memory>
#include <string>

namespace pmsc::python {

namespace py = pybind11;

/// A model plus its runtime (PointMultiplier) and, after pmsc.train(), what training reported.
struct PyModel {
    std::shared_ptr<const Model> model;
    std::unique_ptr<PointMultiplier> multiplier;
    py::dict trainingReport;

    explicit PyModel(Model m)
        : model(std::make_shared<const Model>(std::move(m))), multiplier(new PointMultiplier(*model)) {}
    const Model& get() const { return *model; }
};

/// Defines pmsc.Model: load/save/bytes/pickle, read-only views, project, reconstruct, key_error.
void bindModel(py::module_& m);

/// A str or an os.PathLike, and its path.
bool isPath(py::handle h);
std::string pathOf(py::handle h);

}  // namespace pmsc::python
