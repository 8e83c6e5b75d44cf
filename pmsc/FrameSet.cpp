#include "pmsc/FrameSet.h"

#include <stdexcept>
#include <string>

namespace pmsc {

FrameSet::FrameSet(Index frameCount, Index pointCount, Index channelCount)
    : frames(frameCount), points(pointCount), channels(channelCount) {
    if (frameCount <= 0 || pointCount <= 0 || channelCount <= 0) {
        throw std::invalid_argument("FrameSet: sizes must be positive (frames=" + std::to_string(frameCount) +
                                    ", points=" + std::to_string(pointCount) +
                                    ", channels=" + std::to_string(channelCount) + ")");
    }
    values.assign(static_cast<size_t>(frameCount * pointCount * channelCount), 0.0);
}

}  // namespace pmsc
