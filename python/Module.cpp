// The Python module `pmsc`: training, the model, replay and the evaluation engine from Python,
// with NumPy arrays in and out. Every long call releases the GIL; errors are the command line's one-line
// messages as Python exceptions (pmsc.InputError, pmsc.EvaluatorError, pmsc.IoError, pmsc.Cancelled).
//   PyErrors.cpp    exceptions, running with the GIL released   PyModel.cpp  pmsc.Model
//   PyTraining.cpp  pmsc.train (app/Train.h's options)          Runs.cpp     pmsc.replay, pmsc.run
//   Arrays.cpp    frames arrays read in place                   Evaluators.cpp  array and Python evaluators
#include "python/PyErrors.h"
#include "python/PyModel.h"

#include <pybind11/pybind11.h>

namespace pmsc::python {
void bindTraining(py::module_& m);
void bindRuns(py::module_& m);
}  // namespace pmsc::python

PYBIND11_MODULE(pmsc, m) {
    using namespace pmsc::python;
    m.doc() =
        "Point Multiplication and Soft Caching (Meyer & Anderson, Pixar): train a model from NumPy frames, "
        "replay recorded frames through its soft cache, and run the evaluation engine with a C++ or a "
        "Python evaluator. Frames are arrays of shape (frames, points, channels), float32 or float64.";
    registerErrors(m);
    m.attr("__version__") = "0.1.0";
    bindModel(m);
    bindTraining(m);
    bindRuns(m);
}
