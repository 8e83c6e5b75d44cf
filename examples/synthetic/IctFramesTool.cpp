// pmsc_ict_frames --data DIR --out F.npy --frames N --seed S [--dtype float32|float64]
//                 [--without SHAPE,SHAPE...] [--hold SHAPE=W,SHAPE=W... [--hold ...]]
//
// --without holds blendshapes at 0 (a control the training set never moves); --hold holds them at
// the weight W in [0, 1] in every frame (that control moved at a chosen amplitude, for test sets).
// Given more than once, each --hold is a segment of N frames of the same take (its frames 0 to
// N - 1), written one after another: a test set of many held controls comes from one load of the
// rig (loading it is most of the time of a short set).
//
// Poses the ICT FaceKit meshes (blendshapes + a rotational jaw, IctFrames.h) into a frames file
// for `pmsc train` / `pmsc replay`. The folder is always an argument: users clone ICT-FaceKit
// wherever they like.
#include "examples/synthetic/IctFrames.h"
#include "pmsc/Errors.h"
#include "pmsc/NpyIO.h"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <utility>
#include <vector>

namespace {

/// "a,b,c" -> {"a", "b", "c"}
std::vector<std::string> splitCommas(const std::string& v) {
    std::vector<std::string> items;
    for (std::size_t start = 0;;) {
        const auto comma = v.find(',', start);
        items.push_back(v.substr(start, comma - start));
        if (comma == std::string::npos) return items;
        start = comma + 1;
    }
}

int usage(const char* why) {
    std::fprintf(
        stderr,
        "pmsc_ict_frames: %s\nusage: pmsc_ict_frames --data ICT_FACEKIT_DIR --out FRAMES.npy --frames N "
        "--seed S [--dtype float32|float64] [--without SHAPE,...] [--hold SHAPE=W,... [--hold ...]]\n",
        why);
    return 2;
}

}  // namespace

int main(int argc, char** argv) {
    std::string data, out, dtype = "float32";
    std::vector<std::string> without;
    std::vector<std::vector<std::pair<std::string, double>>> holds;  // one per segment
    long frames = 0;
    long long seed = -1;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--help" || a == "-h") {
            usage("pose the ICT FaceKit face into frames");
            return 0;
        }
        if (i + 1 >= argc) return usage(("missing value for " + a).c_str());
        const std::string v = argv[++i];
        char* end = nullptr;
        if (a == "--data") {
            data = v;
        } else if (a == "--out") {
            out = v;
        } else if (a == "--without") {
            for (std::string& name : splitCommas(v)) without.push_back(std::move(name));
        } else if (a == "--hold") {
            auto& hold = holds.emplace_back();
            for (const std::string& item : splitCommas(v)) {
                const auto eq = item.find('=');
                if (eq == std::string::npos || eq == 0) return usage("--hold takes SHAPE=W,...");
                const std::string w = item.substr(eq + 1);
                const double weight = std::strtod(w.c_str(), &end);
                if (w.empty() || *end || !(weight >= 0 && weight <= 1))
                    return usage(
                        ("--hold: the weight of " + item.substr(0, eq) + " must be in [0, 1]").c_str());
                hold.emplace_back(item.substr(0, eq), weight);
            }
        } else if (a == "--dtype") {
            dtype = v;
        } else if (a == "--frames") {
            frames = std::strtol(v.c_str(), &end, 10);
            if (*end || frames < 1) return usage("--frames must be a positive integer");
        } else if (a == "--seed") {
            seed = std::strtoll(v.c_str(), &end, 10);
            if (*end || seed < 0 || seed > 0xffffffffll)
                return usage("--seed must be an integer in [0, 2^32)");
        } else {
            return usage(("unknown option " + a).c_str());
        }
    }
    if (data.empty() || out.empty() || frames < 1 || seed < 0)
        return usage("--data, --out, --frames and --seed are required");
    if (dtype != "float32" && dtype != "float64") return usage("--dtype must be float32 or float64");
    try {
        const auto start = std::chrono::steady_clock::now();
        const auto rig = pmsc::synthetic::loadIctRig(data);
        if (holds.empty()) holds.emplace_back();
        const auto set =
            pmsc::synthetic::poseIctSegments(rig, frames, static_cast<unsigned>(seed), without, holds);
        pmsc::writeFrames(out, set, dtype == "float32" ? pmsc::NpyDtype::Float32 : pmsc::NpyDtype::Float64);
        const double seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        std::printf(
            "wrote %s: %lld frames x %lld points x 3 (%s), %zu blendshapes + jaw hinge (%.3f rad at "
            "jawOpen=1, "
            "%zu jaw vertices), in %.1f s\n",
            out.c_str(), static_cast<long long>(set.frames), static_cast<long long>(rig.points),
            dtype.c_str(), rig.shapes.size(), rig.jawAngle, rig.jawVertices.size(), seconds);
        std::printf("head bounding-box diagonal %.6g (0.5%% = %.6g, 1%% = %.6g)\n", rig.bboxDiagonal,
                    0.005 * rig.bboxDiagonal, 0.01 * rig.bboxDiagonal);
        return 0;
    } catch (const pmsc::InputError& e) {
        std::fprintf(stderr, "pmsc_ict_frames: %s\n", e.what());
        return 2;
    } catch (const pmsc::IoError& e) {
        std::fprintf(stderr, "pmsc_ict_frames: cannot write output: %s\n", e.what());
        return 4;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pmsc_ict_frames: internal error: %s\n", e.what());
        return 1;
    }
}
