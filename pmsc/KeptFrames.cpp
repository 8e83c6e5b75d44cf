#include "pmsc/KeptFrames.h"

#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace pmsc {

namespace {

constexpr const char* kHeader = "# pmsc kept frames: frame\tstate\tkey_rms\tsource\n";

std::string readText(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in)
        throw InputError(path + ": cannot read the kept-frames sidecar (it must exist next to its .npy)");
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

}  // namespace

std::vector<Index> readKeptFrameNumbers(const std::string& npyPath) {
    const std::string side = KeptFrames::sidecarPath(npyPath);
    std::istringstream in(readText(side));
    std::vector<Index> frames;
    std::string line;
    Index lineNumber = 0;
    while (std::getline(in, line)) {
        ++lineNumber;
        if (line.empty() || line[0] == '#') continue;
        long long frame = -1;
        char state[16] = {};
        double keyRms = 0;
        if (std::sscanf(line.c_str(), "%lld\t%15[a-z]\t%lf", &frame, state, &keyRms) != 3 || frame < 0) {
            throw InputError(side + ": line " + std::to_string(lineNumber) +
                             " is not 'frame<TAB>state<TAB>key_rms<TAB>source'");
        }
        frames.push_back(static_cast<Index>(frame));
    }
    return frames;
}

KeptFrames::KeptFrames(std::string path, Index points, Index channels, NpyDtype dtype, std::string source)
    : path_(std::move(path)),
      points_(points),
      channels_(channels),
      dtype_(dtype),
      source_(std::move(source)) {
    for (char& c : source_)
        if (c == '\t' || c == '\n' || c == '\r') c = ' ';
    std::error_code ec;
    if (!std::filesystem::exists(path_, ec)) {
        if (std::filesystem::exists(sidecarPath(path_), ec)) {
            throw InputError(path_ + ": missing, but its sidecar " + sidecarPath(path_) +
                             " exists; remove the sidecar or restore the frames");
        }
        return;
    }
    const NpyInfo info = readNpyInfo(path_);
    if (static_cast<Index>(info.points) != points_ || static_cast<Index>(info.channels) != channels_) {
        throw InputError(path_ + ": kept frames have " + std::to_string(info.points) + " points x " +
                         std::to_string(info.channels) + " channels, these frames " +
                         std::to_string(points_) + " x " + std::to_string(channels_) +
                         "; keep them in another file");
    }
    if (info.dtype != dtype_) {
        throw InputError(path_ + ": kept frames are " + std::string(toString(info.dtype)) +
                         ", this run writes " + std::string(toString(dtype_)) +
                         "; keep them in another file");
    }
    before_ = static_cast<Index>(info.frames);
    const Index listed = static_cast<Index>(readKeptFrameNumbers(path_).size());
    if (listed != before_) {
        throw InputError(sidecarPath(path_) + ": lists " + std::to_string(listed) + " frames, " + path_ +
                         " holds " + std::to_string(before_));
    }
}

void KeptFrames::add(Index frame, CacheState state, double keyRms, const double* values) {
    frames_.push_back(frame);
    char line[64];
    std::snprintf(line, sizeof line, "%lld\t%s\t%.9g\t", static_cast<long long>(frame),
                  std::string(toString(state)).c_str(), keyRms);
    lines_.push_back(line + source_ + "\n");
    values_.insert(values_.end(), values, values + points_ * channels_);
}

void KeptFrames::commit() {
    if (frames_.empty()) return;
    const Index values = points_ * channels_;
    std::string sidecar = kHeader;
    {
        NpyFrameWriter out(path_, before_ + count(), points_, channels_, dtype_);
        if (before_ > 0) {
            const MappedFrames old(path_);
            std::vector<double> frame(static_cast<size_t>(values));
            for (Index f = 0; f < before_; ++f) {
                old.readFrame(f, frame.data());
                out.writeFrame(f, frame.data());
            }
            const std::string text = readText(sidecarPath(path_));
            std::istringstream in(text);
            std::string line;
            while (std::getline(in, line))
                if (!line.empty() && line[0] != '#') sidecar += line + "\n";
        }
        for (Index i = 0; i < count(); ++i) out.writeFrame(before_ + i, values_.data() + i * values);
        out.commit();
    }
    for (const auto& l : lines_) sidecar += l;
    writeFileAtomically(sidecarPath(path_), sidecar);
}

}  // namespace pmsc
