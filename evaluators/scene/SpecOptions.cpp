#include "evaluators/scene/SpecOptions.h"

#include "pmsc/Errors.h"

#include <exception>

namespace pmsc::scene {

long integerOption(const std::string& evaluator, const std::string& key, const std::string& value, long lo,
                   long hi) {
    std::size_t used = 0;
    long v = 0;
    try {
        v = std::stol(value, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (value.empty() || used != value.size() || v < lo || v > hi)
        throw InputError("evaluator '" + evaluator + "': " + key + "='" + value + "' is not an integer in [" +
                         std::to_string(lo) + ", " + std::to_string(hi) + "]");
    return v;
}

}  // namespace pmsc::scene
