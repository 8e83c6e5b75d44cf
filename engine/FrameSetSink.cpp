#include "engine/FrameSetSink.h"

#include "pmsc/Errors.h"

#include <algorithm>
#include <string>

namespace pmsc::engine {

FrameSetSink::FrameSetSink(Index frames, Index outputPoints, Index channels, bool keepPm)
    : values_(frames, outputPoints, channels),
      pm_(keepPm ? FrameSet(frames, outputPoints, channels) : FrameSet()),
      keepPm_(keepPm) {
    info_.reserve(static_cast<size_t>(frames));
}

void FrameSetSink::write(const FrameResult& frame) {
    if (frame.sequence >= values_.frames) {
        throw std::out_of_range("FrameSetSink: frame " + std::to_string(frame.sequence) + " beyond the " +
                                std::to_string(values_.frames) + " frames it holds");
    }
    info_.push_back({frame.frame, frame.failed, frame.state, frame.weight, frame.keyError, frame.keysFinite});
    if (frame.failed) return;  // the frame's values stay zero
    if (static_cast<Index>(frame.values.size()) != values_.rows()) {
        throw std::invalid_argument("FrameSetSink: frame of " + std::to_string(frame.values.size()) +
                                    " values, expected " + std::to_string(values_.rows()));
    }
    std::copy(frame.values.begin(), frame.values.end(), values_.frame(frame.sequence));
    if (keepPm_ && !frame.pmValues.empty()) {
        std::copy(frame.pmValues.begin(), frame.pmValues.end(), pm_.frame(frame.sequence));
    }
}

}  // namespace pmsc::engine
