// libFuzzer target: the `skin:` evaluator (evaluators/SkinEvaluator) on any bytes. Assimp reads them
// as an asset of the format the first byte picks (by file extension, as a user's file would be) in
// a forked child (the evaluator's default isolate=yes), which sends back the posing arrays; the
// first and last frames are then posed at every point. The contract: an asset either loads and
// poses, or the constructor throws pmsc::InputError; nothing crashes, hangs or leaks in pmsc,
// whatever Assimp does in its child (crash, hang, tens of GB). Assimp itself is a system library,
// not instrumented: only our code's coverage guides the search.
#include "evaluators/SkinEvaluator.h"
#include "pmsc/Errors.h"

#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <unistd.h>

using namespace pmsc;

namespace {

// The formats of the seeds (Debian's assimp-testmodels) and a few more with animation or meshes.
// Not .smd: Assimp 5.2.5's SMD importer hangs (minutes in snprintf, naming every node up to the
// largest index a file gives) on a 24 KB file the fuzzer found in seconds; that is Assimp's to
// fix, and it would stop every run here (docs/fuzzing.md). Not .md5mesh: its importer dereferences
// null on assimp-testmodels' own SimpleCube.md5mesh (no .md5anim beside it) and on every mutation of
// it, so a run spends its time restarting (run-fuzzers.sh sets Assimp's own crashes aside).
constexpr const char* kExtensions[] = {".bvh", ".x", ".dae", ".gltf", ".glb", ".obj", ".ply", ".fbx"};

std::string scratchPath(const char* extension) {
    const char* dir = std::getenv("TMPDIR");
    return std::string(dir && *dir ? dir : "/tmp") + "/pmsc-fuzz-skin-" + std::to_string(::getpid()) +
           extension;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size == 0) return 0;
    const std::size_t kinds = sizeof kExtensions / sizeof kExtensions[0];
    const std::string path = scratchPath(kExtensions[data[0] % kinds]);
    {
        std::FILE* f = std::fopen(path.c_str(), "wb");
        if (!f) std::abort();
        if (size > 1 && std::fwrite(data + 1, 1, size - 1, f) != size - 1) std::abort();
        std::fclose(f);
    }
    try {
        evaluators::SkinOptions options{path, 24, ""};
        options.importTimeoutSeconds = 5;  // a hanging importer is an InputError well inside -timeout
        evaluators::SkinEvaluator skin(options);
        const Index n = skin.pointCount();
        if (n <= 0 || skin.frameCount() <= 0) std::abort();
        std::vector<Index> points(static_cast<std::size_t>(std::min<Index>(n, 4096)));
        for (std::size_t i = 0; i < points.size(); ++i) points[i] = static_cast<Index>(i);
        std::vector<double> out(points.size() * 3);
        skin.evaluate(0, points, out.data());
        skin.evaluate(skin.frameCount() - 1, points, out.data());
        for (std::int64_t t : skin.triangles())
            if (t < 0 || t >= n) std::abort();
    } catch (const InputError&) {
    }
    std::remove(path.c_str());
    return 0;
}
