// Shared by the face tests: where the ICT face is, and one rig built once per test program.
#pragma once

#include "evaluators/face/FaceRig.h"
#include "evaluators/face/IctFace.h"
#include "tests/common/MissingData.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <string>

namespace pmsc::face::test {

/// The ICT-FaceKit folder CMake was configured with (PMSC_ICT_FACEKIT_DIR).
inline std::string ictFolder() { return PMSC_ICT_FACEKIT_DIR; }
inline bool haveIct() { return std::filesystem::exists(ictFolder() + "/generic_neutral_mesh.obj"); }

/// The loaded face and its rig, built on first use (about a second).
struct FaceFixture {
    IctFace face;
    std::unique_ptr<FaceRig> rig;
};
inline const FaceFixture& fixture() {
    static const FaceFixture f = [] {
        FaceFixture x;
        x.face = loadIctFace(ictFolder());
        x.rig = std::make_unique<FaceRig>(x.face);
        return x;
    }();
    return f;
}

}  // namespace pmsc::face::test

/// Skips a test (with the reason) when the ICT data are not where CMake said; fails under CI.
#define PMSC_REQUIRE_ICT()                                                                         \
    do {                                                                                           \
        if (!::pmsc::face::test::haveIct())                                                        \
            PMSC_MISSING_DATA("ICT-FaceKit not found in " << ::pmsc::face::test::ictFolder()       \
                                                          << " (set -DPMSC_ICT_FACEKIT_DIR=...)"); \
    } while (0)
