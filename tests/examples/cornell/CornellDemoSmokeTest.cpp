// `pmsc demo cornell --quick` end to end: the real program, its report's fields and bounds, and
// OpenVDB's own vdb_print listing the lighting cache with the expected active voxel count.
#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

namespace {

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

std::string tempDir(const std::string& tag) {
    const auto d =
        std::filesystem::temp_directory_path() / ("pmsc_cornell_" + tag + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(d);
    return d.string();
}

// One test, one run of the demo (each discovered test is its own process).
TEST(CornellDemoQuick, WritesAReportWithinBoundsImagesAndVdbFilesThatVdbPrintLists) {
    const std::string dir = tempDir("quick");
    int status = -1;
    const std::string output =
        run(std::string(PMSC_BINARY) + " demo cornell --quick --quiet --out " + dir, status);
    ASSERT_EQ(status, 0) << output;
    EXPECT_NE(output.find("speedup"), std::string::npos) << output;

    std::ifstream f(dir + "/report.json");
    const nlohmann::json r = nlohmann::json::parse(f);
    for (const char* key :
         {"points", "key_points", "basis", "train_frames", "test_frames", "samples_per_point",
          "full_seconds_per_frame", "pmsc_seconds_per_frame", "speedup", "rms_rel_error", "hit_rate",
          "reference_rms_rel_error_full", "reference_rms_rel_error_pm"})
        ASSERT_TRUE(r.contains(key)) << key;
    EXPECT_NEAR(r["points"].get<double>(), 6000, 120);
    EXPECT_EQ(r["key_points"].get<int>(), 200);
    EXPECT_EQ(r["basis"].get<int>(), 32);
    EXPECT_EQ(r["train_frames"].get<int>(), 144);
    EXPECT_EQ(r["test_frames"].get<int>(), 8 + 60);
    EXPECT_EQ(r["samples_per_point"].get<int>(), 32);
    EXPECT_GT(r["full_seconds_per_frame"].get<double>(), 0);
    EXPECT_GT(r["pmsc_seconds_per_frame"].get<double>(), 0);
    // No speed assertion (a timed test on a loaded machine proves nothing; bench/ has the ratios).
    EXPECT_LT(r["rms_rel_error"].get<double>(), 0.06);
    EXPECT_GE(r["hit_rate"].get<double>(), 0.5);
    const double refFull = r["reference_rms_rel_error_full"].get<double>();
    const double refPm = r["reference_rms_rel_error_pm"].get<double>();
    EXPECT_GT(refFull, 0);
    EXPECT_LT(refFull, 0.3);
    EXPECT_GT(refPm, 0);
    EXPECT_LT(refPm, 0.3);
    EXPECT_EQ(r["images"].size(), 3u);
    for (const auto& img : r["images"]) {
        EXPECT_TRUE(std::filesystem::exists(dir + "/" + img["png"].get<std::string>()));
        EXPECT_TRUE(std::filesystem::exists(dir + "/" + img["pfm"].get<std::string>()));
    }

#ifdef PMSC_VDB_PRINT
    ASSERT_FALSE(r["vdb_files"].empty());
    for (const auto& name : r["vdb_files"]) {
        const std::string listing =
            run(std::string(PMSC_VDB_PRINT) + " -l " + dir + "/" + name.get<std::string>(), status);
        ASSERT_EQ(status, 0) << listing;
        EXPECT_NE(listing.find("Name: indirect"), std::string::npos) << listing;
        EXPECT_NE(listing.find("vec3s"), std::string::npos) << listing;
        // "Number of active voxels:       6,002" (with thousands separators); "indirect" is listed first.
        const auto at = listing.find("Number of active voxels:");
        ASSERT_NE(at, std::string::npos) << listing;
        std::string digits;
        for (std::size_t i = at + 24; i < listing.size() && listing[i] != '\n'; ++i)
            if (std::isdigit(static_cast<unsigned char>(listing[i]))) digits += listing[i];
        EXPECT_EQ(digits, std::to_string(r["points"].get<long>())) << listing;
        EXPECT_NE(listing.find("cache_state"), std::string::npos) << listing;
        EXPECT_NE(listing.find("light_position_mm"), std::string::npos) << listing;
    }
#endif
    std::filesystem::remove_all(dir);
}

// Local fail-through at --quick: the scattered lights stay hits both ways; the local change (a cube training
// never saw) moves the full gather by more than the tolerance, fails some frames as a whole, and
// every one of them is routed locally: fewer points gathered than a whole-frame fail-through, and
// no frame over the tolerance.
TEST(CornellDemoQuick, LocalChangeMissesAsAWholeFrameIsRoutedLocallyAndStaysUnderTheTolerance) {
    const std::string dir = tempDir("local");
    int status = -1;
    const std::string output =
        run(std::string(PMSC_BINARY) + " demo cornell --quick --quiet --out " + dir, status);
    ASSERT_EQ(status, 0) << output;
    EXPECT_NE(output.find("local_change local"), std::string::npos) << output;
    std::ifstream f(dir + "/report.json");
    const nlohmann::json r = nlohmann::json::parse(f);
    ASSERT_TRUE(r.contains("local_fail_through")) << r.dump(1);
    const nlohmann::json& l = r.at("local_fail_through");
    EXPECT_EQ(l.at("regions").get<int>(), 48);
    EXPECT_DOUBLE_EQ(l.at("tolerance").get<double>(), r.at("tolerance").get<double>());

    const nlohmann::json& v = l.at("validation");
    EXPECT_EQ(v.at("frames").get<int>(), 8);
    for (const char* way : {"local", "whole_frame"}) {
        EXPECT_LT(v.at(way).at("soft_max_error_over_tolerance").get<double>(), 1) << way;
        EXPECT_EQ(v.at(way).at("frames_over_tolerance").get<int>(), 0) << way;
    }

    const nlohmann::json& c = l.at("local_change");
    EXPECT_EQ(c.at("frames").get<int>(), 8);
    EXPECT_GT(c.at("points_covered").get<int>(), 0);
    EXPECT_GT(c.at("change_max_over_tolerance").get<double>(), 1) << "the change must matter";
    const int nonHit = c.at("non_hit_frames").get<int>();
    EXPECT_GE(nonHit, 1) << "no frame of the local change missed as a whole";
    EXPECT_TRUE(c.at("local_fail_through").get<bool>());
    const nlohmann::json& local = c.at("local");
    const nlohmann::json& whole = c.at("whole_frame");
    // Every frame that missed as a whole went local; a hit the hit check (HitCheck) refused is
    // computed whole by design (nodes/ErrorMonitor.cpp).
    EXPECT_EQ(local.at("local_frames").get<int>() + local.at("refused_hits").get<int>(), nonHit)
        << "a frame failed through whole";
    EXPECT_GE(local.at("local_frames").get<int>(), 1);
    EXPECT_GT(local.at("points_evaluated_fraction_non_hit_mean").get<double>(), 0);
    EXPECT_LT(local.at("points_evaluated_fraction_non_hit_mean").get<double>(), 0.6);
    EXPECT_DOUBLE_EQ(whole.at("points_evaluated_fraction_non_hit_mean").get<double>(), 1.0);
    EXPECT_LT(local.at("points_evaluated_fraction_mean").get<double>(),
              whole.at("points_evaluated_fraction_mean").get<double>());
    EXPECT_LT(local.at("soft_max_error_over_tolerance").get<double>(), 1);
    EXPECT_EQ(local.at("frames_over_tolerance").get<int>(), 0);
    EXPECT_GT(c.at("speedup_local").get<double>(), 0);  // no speed ratio asserted (loaded machines)
    // The experiment: regions decide every frame, so every frame goes their way (local or whole).
    for (const nlohmann::json* set : {&v, &c}) {
        const nlohmann::json& e = set->at("regions_every_frame");
        EXPECT_LE(e.at("frames_without_gathers").get<int>(), e.at("local_frames").get<int>());
        EXPECT_GT(e.at("points_evaluated_fraction_mean").get<double>(), 0);
        EXPECT_LT(e.at("soft_max_error_over_tolerance").get<double>(), 1);
    }
    std::filesystem::remove_all(dir);
}

// The default size leaves the local fail-through experiment to --full (or --local-change MM), so
// the demo's first result comes in minutes; the model still has its regions either way. At 1,000
// points and 4 samples the default settings run in about a second.
TEST(CornellDemoQuick, TheLocalFailThroughExperimentRunsWithFullOrALocalChangeOnly) {
    const std::string dir = tempDir("full");
    for (const std::string flags : {"", "--full", "--local-change 50"}) {
        std::filesystem::remove_all(dir);
        int status = -1;
        const std::string out =
            run(std::string(PMSC_BINARY) + " demo cornell --points 1000 --samples 4 --quiet --out " + dir +
                    " " + flags,
                status);
        ASSERT_EQ(status, 0) << flags << ": " << out;
        std::ifstream f(dir + "/report.json");
        const nlohmann::json r = nlohmann::json::parse(f);
        const bool full = !flags.empty();
        EXPECT_EQ(r.at("full").get<bool>(), full) << flags;
        EXPECT_EQ(r.contains("local_fail_through"), full) << flags;
        if (full) {
            EXPECT_TRUE(r["local_fail_through"].contains("local_change")) << flags;  // 100 mm or 50 mm
        }
        EXPECT_EQ(out.find("local fail-through") != std::string::npos, full) << flags << ": " << out;
    }
    std::filesystem::remove_all(dir);
}

// Each bad value of the local fail-through options is one line and exit code 2, before any work.
TEST(CornellDemoQuick, BadLocalFailThroughOptionsAreOneLineAndExitCode2) {
    const std::string dir = tempDir("badlocal");
    for (const std::string bad : {"--local-change 5", "--local-change 151", "--local-change x",
                                  "--regions -1", "--regions 0 --local-change 50", "--feather 60"}) {
        int status = -1;
        const std::string out =
            run(std::string(PMSC_BINARY) + " demo cornell --quick --out " + dir + " " + bad, status);
        EXPECT_EQ(WEXITSTATUS(status), 2) << bad << ": " << out;
        EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << bad << ": " << out;
        EXPECT_FALSE(std::filesystem::exists(dir + "/report.json")) << bad;
    }
    std::filesystem::remove_all(dir);
}

TEST(CornellDemoQuick, BadOptionsAreOneLineAndExitCode2) {
    const std::string dir = tempDir("bad");
    int status = -1;
    const std::string out =
        run(std::string(PMSC_BINARY) + " demo cornell --quick --out " + dir + " --points ten", status);
    EXPECT_EQ(WEXITSTATUS(status), 2) << out;
    EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
    EXPECT_FALSE(std::filesystem::exists(dir + "/report.json"));
}
#endif

}  // namespace
