// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <string>

namespace pmsc::scene {

/// The integer value of an evaluator spec's option (`samples=160` in "volume:F.vdb:samples=160"):
/// the whole of `value`, in [lo, hi].
/// @throws pmsc::InputError "evaluator 'NAME': KEY='VALUE' is not an integer in [LO, HI]".
long integerOption(const std::string& evaluator, const std::string& key, const std::string& value, long lo,
                   long hi);

}  // namespace pmsc::scene
