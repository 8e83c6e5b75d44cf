// `pmsc demo cornell --quick` end to end: the real program, its report's fields and bounds, and
// OpenVDB's own vdb_print listing the lighting cache with the expected active voxel count.
#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <array>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <algorithm>
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
    const auto d = std::filesystem::temp_directory_path() / ("pmsc_cornell_" + tag + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(d);
    return d.string();
}

// One test, one run of the demo (each discovered test is its own process).
TEST(CornellDemoQuick, WritesAReportWithinBoundsImagesAndVdbFilesThatVdbPrintLists) {
    const std::string dir = tempDir("quick");
    int status = -1;
    const std::string output = run(std::string(PMSC_BINARY) + " demo cornell --quick --quiet --out " + dir, status);
    ASSERT_EQ(status, 0) << output;
    EXPECT_NE(output.find("speedup"), std::string::npos) << output;

    std::ifstream f(dir + "/report.json");
    const nlohmann::json r = nlohmann::json::parse(f);
    for (const char* key : {"points", "key_points", "basis", "train_frames", "test_frames", "samples_per_point",
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
        const std::string listing = run(std::string(PMSC_VDB_PRINT) + " -l " + dir + "/" + name.get<std::string>(), status);
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

TEST(CornellDemoQuick, BadOptionsAreOneLineAndExitCode2) {
    const std::string dir = tempDir("bad");
    int status = -1;
    const std::string out = run(std::string(PMSC_BINARY) + " demo cornell --quick --out " + dir + " --points ten", status);
    EXPECT_EQ(WEXITSTATUS(status), 2) << out;
    EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
    EXPECT_FALSE(std::filesystem::exists(dir + "/report.json"));
}
#endif

}  // namespace
