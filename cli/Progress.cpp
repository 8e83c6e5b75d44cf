#include "cli/Progress.h"

#include "cli/Interrupt.h"

#include <algorithm>
#include <cmath>

#include <unistd.h>

namespace pmsc::cli {

Progress::Progress(std::string label, bool enabled, double logSeconds)
    : label_(std::move(label)),
      enabled_(enabled),
      terminal_(::isatty(STDERR_FILENO) == 1),
      logSeconds_(logSeconds),
      start_(Clock::now()),
      lastDraw_(start_) {}

Progress::~Progress() { finish(); }

bool Progress::update(std::string_view stage, double done, double total) {
    if (interrupted()) return false;
    if (!enabled_) return true;
    const auto now = Clock::now();
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    const double sinceDraw = std::chrono::duration<double>(now - lastDraw_).count();
    const double fraction = total > 0 ? std::clamp(done / total, 0.0, 1.0) : 0.0;
    const bool newStage = stage != lastStage_;
    if (terminal_) {
        if (!newStage && sinceDraw < 0.1 && fraction < 1.0) return true;
        constexpr int kWidth = 24;
        const int filled = static_cast<int>(std::lround(fraction * kWidth));
        std::fprintf(stderr, "\r\033[K%s  %-14.*s [%s%s] %3d%%  %.1f s", label_.c_str(),
                     static_cast<int>(stage.size()), stage.data(),
                     std::string(static_cast<std::size_t>(filled), '#').c_str(),
                     std::string(static_cast<std::size_t>(kWidth - filled), '.').c_str(),
                     static_cast<int>(std::floor(fraction * 100)), elapsed);
        std::fflush(stderr);
        drawn_ = true;
    } else {
        if (elapsed < logSeconds_ || sinceDraw < logSeconds_) return true;
        std::fprintf(stderr, "pmsc %s: %.*s %d%% (%.1f s)\n", label_.c_str(), static_cast<int>(stage.size()),
                     stage.data(), static_cast<int>(std::floor(fraction * 100)), elapsed);
    }
    lastStage_.assign(stage);
    lastDraw_ = now;
    return true;
}

void Progress::finish() {
    if (terminal_ && drawn_) {
        std::fprintf(stderr, "\r\033[K");
        std::fflush(stderr);
        drawn_ = false;
    }
}

}  // namespace pmsc::cli
