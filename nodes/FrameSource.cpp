#include "nodes/FrameSource.h"

namespace pmsc::nodes {

bool FrameSource::next(Index& sequence) {
    if (next_ >= range_.count || next_ > control_.stopSequence() || control_.cancelled()) return false;
    sequence = next_++;
    return true;
}

}  // namespace pmsc::nodes
