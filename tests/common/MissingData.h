// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

// What a test does when the data it needs (the ICT face, Debian's assimp-testmodels) is missing:
// on a developer's machine it skips with the reason; under CI (CI set and not "false"/"0") it
// fails, so a CI machine that lost a package or a data folder cannot pass by skipping.

#include <gtest/gtest.h>

#include <cstdlib>
#include <string_view>

namespace pmsc::test {

inline bool underCi() {
    const char* ci = std::getenv("CI");
    if (ci == nullptr) return false;
    const std::string_view v(ci);
    return !v.empty() && v != "false" && v != "0";
}

}  // namespace pmsc::test

/// Use in a test body or SetUp(): fails under CI, skips elsewhere. `why` is a stream expression:
/// PMSC_MISSING_DATA("not found in " << folder).
#define PMSC_MISSING_DATA(why)                                                                    \
    do {                                                                                          \
        if (::pmsc::test::underCi()) {                                                            \
            GTEST_FAIL() << why << " (CI is set: a test whose data is missing fails, not skips)"; \
        } else {                                                                                  \
            GTEST_SKIP() << why;                                                                  \
        }                                                                                         \
    } while (0)
