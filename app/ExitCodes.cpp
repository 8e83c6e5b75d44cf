#include "app/ExitCodes.h"

#include "pmsc/Errors.h"
#include "pmsc/Training.h"  // pmsc::Cancelled

#include <new>
#include <stdexcept>

namespace pmsc::app {

ExitReason exitReason(const std::exception_ptr& error) {
    try {
        std::rethrow_exception(error);
    } catch (const Cancelled& e) {
        return {kExitInterrupted, "interrupted", e.what(), std::string("interrupted: ") + e.what()};
    } catch (const InputError& e) {
        return {kExitBadInput, "bad input", e.what(), e.what()};
    } catch (const EvaluatorError& e) {
        return {kExitEvaluator, "evaluator failure", e.what(), std::string("evaluator failed: ") + e.what()};
    } catch (const IoError& e) {
        return {kExitIo, "io failure", e.what(), std::string("cannot write output: ") + e.what()};
    } catch (const std::invalid_argument& e) {
        return {kExitBadInput, "bad input", e.what(), e.what()};
    } catch (const std::bad_alloc& e) {
        return {kExitInternal, "internal error", e.what(), "internal error: out of memory"};
    } catch (const std::exception& e) {
        return {kExitInternal, "internal error", e.what(), std::string("internal error: ") + e.what()};
    } catch (...) {
        return {kExitInternal, "internal error", "unknown exception", "internal error: unknown exception"};
    }
}

}  // namespace pmsc::app
