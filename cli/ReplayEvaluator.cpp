#include "cli/ReplayEvaluator.h"

#include <algorithm>
#include <stdexcept>
#include <utility>

namespace pmsc::cli {

ReplayEvaluator::ReplayEvaluator(const std::string& path) : file_(readFrames(path)), source_(path) {}

ReplayEvaluator::ReplayEvaluator(FrameFile frames, std::string source)
    : file_(std::move(frames)), source_(std::move(source)) {}

void ReplayEvaluator::checkFrame(Index frame) const {
    if (frame < 0 || frame >= frameCount())
        throw std::out_of_range("replay: frame " + std::to_string(frame) + " outside the " +
                                std::to_string(frameCount()) + " frames of " + source_);
}

void ReplayEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    checkFrame(frame);
    const Index c = channelCount();
    const double* values = file_.frames.frame(frame);
    for (std::size_t i = 0; i < points.size(); ++i) {
        const Index p = points[i];
        if (p < 0 || p >= pointCount())
            throw std::out_of_range("replay: point " + std::to_string(p) + " outside [0, " +
                                    std::to_string(pointCount()) + ")");
        std::copy_n(values + p * c, c, out + static_cast<Index>(i) * c);
    }
}

void ReplayEvaluator::evaluateAll(Index frame, double* out) const {
    checkFrame(frame);
    std::copy_n(file_.frames.frame(frame), file_.frames.rows(), out);
}

}  // namespace pmsc::cli
