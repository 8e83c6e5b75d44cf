#include "examples/common/DemoSetup.h"

#include "pmsc/Errors.h"

#include <ctime>
#include <filesystem>
#include <system_error>
#include <utility>

namespace pmsc::examples {

double secondsSince(DemoClock::time_point t) {
    return std::chrono::duration<double>(DemoClock::now() - t).count();
}

double threadCpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

void createOutputFolder(const std::string& dir, FolderErrorWording wording) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (!ec && std::filesystem::is_directory(dir)) return;
    if (wording == FolderErrorWording::CannotCreate)
        throw IoError("cannot create " + dir + ": " + (ec ? ec.message() : "not a directory"));
    throw IoError(dir + ": cannot create the output folder: " + (ec ? ec.message() : "not a folder"));
}

DemoSetup::DemoSetup(int threads, const DemoProgress& hook, std::string cancelMessage,
                     DemoClock::time_point start)
    : start(start), threads(threads), arena(threads), hook_(hook), cancelMessage_(std::move(cancelMessage)) {}

void DemoSetup::progress(std::string_view stage, double done, double total) const {
    if (hook_ && !hook_(stage, done, total)) throw Cancelled(cancelMessage_);
}

double DemoSetup::lap(const std::string& stage, DemoClock::time_point t) {
    const double s = secondsSince(t);
    timings[stage] = s;
    return s;
}

const nlohmann::json& DemoSetup::finish() {
    timings["total"] = secondsSince(start);
    return timings;
}

}  // namespace pmsc::examples
