#include "pmsc/FrameSet.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace pmsc {

FrameSet::FrameSet(Index frameCount, Index pointCount, Index channelCount)
    : FrameSet(frameCount, pointCount, channelCount, Uninitialised{}) {
    std::fill(values.begin(), values.end(), 0.0);
}

FrameSet::FrameSet(Index frameCount, Index pointCount, Index channelCount, Uninitialised)
    : frames(frameCount), points(pointCount), channels(channelCount) {
    if (frameCount <= 0 || pointCount <= 0 || channelCount <= 0) {
        throw std::invalid_argument("FrameSet: sizes must be positive (frames=" + std::to_string(frameCount) +
                                    ", points=" + std::to_string(pointCount) +
                                    ", channels=" + std::to_string(channelCount) + ")");
    }
    values.resize(static_cast<size_t>(frameCount * pointCount * channelCount));
}

}  // namespace pmsc
