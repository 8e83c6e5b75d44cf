// `pmsc demo volume --quick` end to end (the real program, its report, OpenVDB's own vdb_print on
// a cache file) and the volume evaluator's bad inputs through the command line: one line, exit 2.
#include "evaluators/volume/DensityVolume.h"
#include "examples/volume/VolumeDemo.h"
#include "tests/common/MissingData.h"
#include "tests/evaluators/volume/VdbFixtures.h"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <string>

namespace {

/// F frames of N voxels x RGB whose mean-removed (voxel, frame-channel) matrix has rank r: r
/// spatial patterns, each weighted per frame and channel, energies falling by 2 per pattern.
pmsc::FrameSet rankFrames(pmsc::Index frames, pmsc::Index points, int rank) {
    std::mt19937 rng(7);
    std::normal_distribution<double> g(0, 1);
    pmsc::FrameSet q(frames, points, 3);
    std::vector<std::vector<double>> patterns(static_cast<std::size_t>(rank), std::vector<double>(points));
    for (auto& p : patterns)
        for (double& v : p) v = g(rng);
    for (pmsc::Index f = 0; f < frames; ++f)
        for (int k = 0; k < rank; ++k)
            for (int c = 0; c < 3; ++c) {
                const double w = g(rng) * std::pow(0.8, k);
                for (pmsc::Index i = 0; i < points; ++i)
                    q.frame(f)[3 * i + c] +=
                        10 + w * patterns[static_cast<std::size_t>(k)][static_cast<std::size_t>(i)];
            }
    return q;
}

TEST(VolumeDemoModelSize, TheBasisFollowsTheFramesEnergyAndTheKeysTheBasis) {
    pmsc::volume::VolumeDemoOptions o;  // the defaults: M by energy, K = 6.25 M, grid keys K / 5
    auto s = pmsc::volume::chooseModelSize(o, rankFrames(40, 2000, 7));
    EXPECT_EQ(s.basis, 7);  // all of a rank-7 set's energy, nothing beyond it
    EXPECT_EQ(s.keys, 44);
    EXPECT_EQ(s.gridKeys, 8);
    EXPECT_GT(s.energy, 0.9998);
    s = pmsc::volume::chooseModelSize(o, rankFrames(40, 2000, 12));
    EXPECT_EQ(s.basis, 12);
    EXPECT_EQ(s.keys, 75);
    o.maxBasis = 5;  // the cap holds, and the keys follow the capped basis
    s = pmsc::volume::chooseModelSize(o, rankFrames(40, 2000, 12));
    EXPECT_EQ(s.basis, 5);
    EXPECT_EQ(s.keys, 31);
    EXPECT_LT(s.energy, 0.9998);
    o.basis = 9;  // explicit sizes win
    o.keys = 100;
    o.gridKeys = 0;
    s = pmsc::volume::chooseModelSize(o, rankFrames(40, 300, 12));
    EXPECT_EQ(s.basis, 9);
    EXPECT_EQ(s.keys, 100);
    EXPECT_EQ(s.gridKeys, 0);
    o.keys = 0;  // K at most a tenth of the voxels
    EXPECT_EQ(pmsc::volume::chooseModelSize(o, rankFrames(40, 300, 12)).keys, 30);
}

#ifdef PMSC_BINARY
std::string run(const std::string& command, int& status) {
    std::string out;
    std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen((command + " 2>&1").c_str(), "r"), pclose);
    if (!pipe) {
        status = -1;
        return out;
    }
    std::array<char, 4096> buf{};
    while (std::fgets(buf.data(), static_cast<int>(buf.size()), pipe.get())) out += buf.data();
    status = pclose(pipe.release());
    return out;
}

TEST(VolumeDemoQuick, WritesAReportWithinBoundsImagesAndCachesThatVdbPrintLists) {
    if (pmsc::volume::test::testMesh().empty()) {
        PMSC_MISSING_DATA("assimp-testmodels not installed");
    }
    const std::string dir = pmsc::volume::test::tempDir("quick");
    int status = -1;
    const std::string output =
        run(std::string(PMSC_BINARY) + " demo volume --quick --quiet --out " + dir, status);
    ASSERT_EQ(status, 0) << output;
    EXPECT_NE(output.find("speedup"), std::string::npos) << output;
    std::ifstream f(dir + "/report.json");
    const nlohmann::json r = nlohmann::json::parse(f);
    for (const char* key :
         {"points", "key_points", "basis", "train_frames", "test_frames", "full_seconds_per_frame",
          "pmsc_seconds_per_frame", "speedup", "rms_rel_error", "hit_rate", "reference_rms_rel_error_full",
          "reference_rms_rel_error_pm", "peak_rss_mb", "seconds"})
        ASSERT_TRUE(r.contains(key)) << key;
    EXPECT_NEAR(r["points"].get<double>(), 12000, 12000 * 0.06);
    EXPECT_EQ(r["train_frames"].get<int>(), 24);
    EXPECT_EQ(r["train_full_calculations"].get<int>(), 24);
    EXPECT_EQ(r["test_frames"].get<int>(), 4 + 16);
    EXPECT_LT(r["rms_rel_error"].get<double>(), 0.10);
    EXPECT_GE(r["hit_rate"].get<double>(), 0.5);
    EXPECT_GT(r["reference_rms_rel_error_full"].get<double>(), 0);
    EXPECT_LT(r["reference_rms_rel_error_pm"].get<double>(), 0.2);
    // The orthogonal projection onto the basis is the best any reconstruction from it can do
    // (PM's lies in the same subspace), and the reference is closer to a finer one than the full
    // calculation is to it (else it would not be a converged reference).
    EXPECT_GT(r["projection_rel_error"].get<double>(), 0);
    EXPECT_LE(r["projection_rel_error"].get<double>(), r["rms_rel_error"].get<double>() * (1 + 1e-9));
    EXPECT_GE(r["train_projection_rel_error"].get<double>(), 0);
    EXPECT_LT(r["reference_self_rel_error"].get<double>(),
              0.5 * r["reference_rms_rel_error_full"].get<double>());
    EXPECT_EQ(r["between_nearest_training_deg"].size(), 4u);
    EXPECT_EQ(r["images"].size(), 3u);
    for (const auto& img : r["images"])
        EXPECT_TRUE(std::filesystem::exists(dir + "/" + img["png"].get<std::string>()));
    EXPECT_TRUE(std::filesystem::exists(dir + "/density.vdb"));
#ifdef PMSC_VDB_PRINT
    ASSERT_FALSE(r["vdb_files"].empty());
    for (const auto& name : r["vdb_files"]) {
        const std::string listing =
            run(std::string(PMSC_VDB_PRINT) + " -l " + dir + "/" + name.get<std::string>(), status);
        ASSERT_EQ(status, 0) << listing;
        EXPECT_NE(listing.find("Name: inscatter"), std::string::npos) << listing;
        EXPECT_NE(listing.find("vec3s"), std::string::npos) << listing;
        const auto at = listing.find("Number of active voxels:");
        ASSERT_NE(at, std::string::npos) << listing;
        std::string digits;
        for (std::size_t i = at + 24; i < listing.size() && listing[i] != '\n'; ++i)
            if (std::isdigit(static_cast<unsigned char>(listing[i]))) digits += listing[i];
        EXPECT_EQ(digits, std::to_string(r["points"].get<long>())) << listing;
        EXPECT_NE(listing.find("light_kelvin"), std::string::npos) << listing;
    }
#endif
    std::filesystem::remove_all(dir);
}

TEST(VolumeEvaluatorCli, ExportTrainAndRunWriteCacheFilesWithTheDensityTopology) {
    const std::string dir = pmsc::volume::test::tempDir("run");
    pmsc::volume::test::writeDensityBox(dir + "/box.vdb", "density", 0.3, 0.05, 0.8f);  // 13^3 voxels
    const std::string bin = PMSC_BINARY;
    int status = -1;
    std::string out =
        run(bin + " export-frames volume:" + dir + "/box.vdb:lights=training --quiet --out " + dir + "/t.npy",
            status);
    ASSERT_EQ(status, 0) << out;
    out = run(bin + " train --frames " + dir + "/t.npy --out " + dir + "/m.pmsc --basis 8 --max-keys 40",
              status);
    ASSERT_EQ(status, 0) << out;
    // `pmsc run --format vdb` with MODEL writes caches of the density's topology into FOLDER.
    const auto runWritesCaches = [&](const std::string& model, const std::string& folder) {
        int runStatus = -1;
        const std::string runOut =
            run(bin + " run --model " + dir + "/" + model + " --evaluator volume:" + dir +
                    "/box.vdb --frames 64-66 --out " + dir + "/" + folder + " --format vdb --quiet",
                runStatus);
        ASSERT_EQ(runStatus, 0) << runOut;
        for (int f = 64; f <= 66; ++f) {
            const auto cache = pmsc::volume::ScatterCache::read(dir + "/" + folder + "/frame.0000" +
                                                                std::to_string(f) + ".vdb");
            EXPECT_EQ(cache.activeVoxelCount(), 13 * 13 * 13);
            EXPECT_EQ(cache.info().frame, f);
            EXPECT_EQ(cache.info().state, "soft-cached");
        }
    };
    runWritesCaches("m.pmsc", "frames");
    // The same with red, green and blue sharing one basis (the volume demo's default).
    out = run(bin + " train --frames " + dir + "/t.npy --out " + dir +
                  "/s.pmsc --basis 8 --max-keys 40 --shared-channels --quiet",
              status);
    ASSERT_EQ(status, 0) << out;
    out = run(bin + " inspect " + dir + "/s.pmsc", status);
    ASSERT_EQ(status, 0) << out;
    EXPECT_NE(out.find("channels C = 3 (sharing one basis)"), std::string::npos) << out;
    runWritesCaches("s.pmsc", "shared");
    // pmsc learn refuses the shared model with one line.
    out = run(bin + " learn --model " + dir + "/s.pmsc --frames " + dir + "/t.npy --out " + dir +
                  "/learned.pmsc --quiet",
              status);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << out;
    EXPECT_NE(out.find("shares one basis among its channels"), std::string::npos) << out;
    EXPECT_FALSE(std::filesystem::exists(dir + "/learned.pmsc"));
    // What shared channels do not combine with: one line, exit code 2, no model written.
    for (const char* extra : {"--regions 2", "--learn-rank 10", "--out-of-core"}) {
        out = run(
            bin + " train --frames " + dir + "/t.npy --out " + dir + "/bad.pmsc --shared-channels " + extra,
            status);
        EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << extra << ": " << out;
        EXPECT_NE(out.find("does not combine with --shared-channels"), std::string::npos) << out;
        EXPECT_FALSE(std::filesystem::exists(dir + "/bad.pmsc"));
    }
    std::filesystem::remove_all(dir);
}

TEST(VolumeEvaluatorCli, MissingFileNoFloatGridAndWrongGridNameAreOneLineAndExitCode2) {
    const std::string dir = pmsc::volume::test::tempDir("cli");
    pmsc::volume::test::writeVectorOnly(dir + "/vectors.vdb");
    pmsc::volume::test::writeDensityBox(dir + "/box.vdb", "smoke", 0.2, 0.1, 1.0f);
    pmsc::volume::test::writeFloatGrids(dir + "/two.vdb", {"heat", "smoke"}, 0.2, 0.1);
    pmsc::volume::test::writeEmptyFloatGrid(dir + "/empty.vdb", "fog");
    const std::pair<std::string, std::string> cases[] = {
        {"volume:" + dir + "/two.vdb", "2 float grids"},
        {"volume:" + dir + "/two.vdb", "and none named 'density': name one (--grid NAME, or grid=NAME"},
        {"volume:" + dir + "/empty.vdb", "the grid has no active voxels"},
        {"volume:" + dir + "/missing.vdb", "no such file"},
        {"volume:" + dir + "/vectors.vdb", "has no float grid"},
        {"volume:" + dir + "/box.vdb:grid=density", "no grid named 'density'"},
        {"volume", "needs FILE.vdb"},
    };
    for (const auto& [spec, what] : cases) {
        int status = -1;
        const std::string out = run(
            std::string(PMSC_BINARY) + " export-frames " + spec + " --quiet --out " + dir + "/f.npy", status);
        EXPECT_EQ(WEXITSTATUS(status), 2) << spec << ": " << out;
        EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
        EXPECT_EQ(out.rfind("pmsc: ", 0), 0u) << out;
        EXPECT_NE(out.find(what), std::string::npos) << out;
        EXPECT_FALSE(std::filesystem::exists(dir + "/f.npy"));
    }
    for (const char* bad :
         {"--voxels ten", "--elevations 30,95", "--elevations 30,x", "--spiral -1", "--colours 0",
          "--kelvin 6500,4000", "--kelvin 500,6500", "--kelvin 5000", "--kelvin 4000,5000,6000",
          "--fog-floor 1.5", "--fog-density 0", "--fog-exponent x", "--density d.vdb --fog-density 2"}) {
        int status = -1;
        const std::string out =
            run(std::string(PMSC_BINARY) + " demo volume --quick --out " + dir + "/d " + bad, status);
        EXPECT_EQ(WEXITSTATUS(status), 2) << bad << ": " << out;
        EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << bad << ": " << out;
        EXPECT_FALSE(std::filesystem::exists(dir + "/d/report.json")) << bad;
    }
    std::filesystem::remove_all(dir);
}
#endif

}  // namespace
