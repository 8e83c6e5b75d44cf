#include "pmsc/RowBlocks.h"

#include "pmsc/Errors.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>

#include <fcntl.h>
#include <unistd.h>

namespace pmsc {

RowBlocks::RowBlocks(Index points, Index channels, Index frames, Index firstPoint, Index ownedPoints,
                     Index blockPoints)
    : points_(points),
      channels_(channels),
      frames_(frames),
      firstPoint_(firstPoint),
      ownedPoints_(ownedPoints),
      blockPoints_(std::max<Index>(1, blockPoints)) {
    if (points < 1 || channels < 1 || frames < 1 || firstPoint < 0 || ownedPoints < 0 ||
        firstPoint + ownedPoints > points) {
        throw std::invalid_argument("RowBlocks: bad layout");
    }
}

PointRange pointShare(Index points, int rank, int ranks) {
    const Index first = points * rank / ranks;
    const Index last = points * (rank + 1) / ranks;
    return {first, last - first};
}

// --- in memory -----------------------------------------------------------------------------------

MatrixBlocks::MatrixBlocks(const FrameSet& frames, Index blockPoints)
    : RowBlocks(frames.points, frames.channels, frames.frames, 0, frames.points,
                blockPoints > 0 ? blockPoints : frames.points),
      values_(frames.values),
      rows_(frames.rows()),
      cols_(frames.frames) {
    centre();
}

MatrixBlocks::MatrixBlocks(FrameSet&& frames, Index blockPoints)
    : RowBlocks(frames.points, frames.channels, frames.frames, 0, frames.points,
                blockPoints > 0 ? blockPoints : frames.points),
      values_(std::move(frames.values)),
      rows_(frames.rows()),
      cols_(frames.frames) {
    frames = FrameSet();  // its values are ours now
    centre();
}

MatrixBlocks::MatrixBlocks(const Eigen::Ref<const Eigen::MatrixXd>& q, Index channels, bool centre,
                           Index blockPoints)
    : RowBlocks(q.rows() / std::max<Index>(channels, 1), channels, q.cols(), 0,
                q.rows() / std::max<Index>(channels, 1),
                blockPoints > 0 ? blockPoints : q.rows() / std::max<Index>(channels, 1)),
      values_(static_cast<std::size_t>(q.rows() * q.cols())),
      rows_(q.rows()),
      cols_(q.cols()) {
    mutableMatrix() = q;
    if (centre) {
        this->centre();
    } else {
        mean_ = Eigen::VectorXd::Zero(q.rows());
        // The values before any centring are not ours to know: "unknown", as RowBlocks says.
        smallest_ = -std::numeric_limits<double>::infinity();
    }
}

void MatrixBlocks::centre() {
    Eigen::Map<Eigen::MatrixXd> q = mutableMatrix();
    smallest_ = q.size() > 0 ? q.minCoeff() : 0.0;
    mean_ = q.rowwise().mean();
    q.colwise() -= mean_;
}

Eigen::Ref<const Eigen::MatrixXd> MatrixBlocks::block(Index b) {
    return matrix().middleRows(blockFirstRow(b), blockRows(b));
}

void MatrixBlocks::pointRows(Index point, Eigen::Ref<Eigen::MatrixXd> out) {
    out = matrix().middleRows(point * channels(), channels());
}

// --- on disk -------------------------------------------------------------------------------------

std::vector<Shot> openShots(const std::vector<std::string>& paths) {
    if (paths.empty()) throw InputError("train: no --frames file given");
    std::vector<Shot> shots;
    for (const std::string& path : paths) {
        Shot s{path, readNpyInfo(path)};
        if (!shots.empty()) {
            const NpyInfo& a = shots.front().info;
            if (s.info.points != a.points || s.info.channels != a.channels) {
                throw InputError("train: shot " + path + " has " + std::to_string(s.info.points) +
                                 " points x " + std::to_string(s.info.channels) + " channels, but " +
                                 shots.front().path + " has " + std::to_string(a.points) + " x " +
                                 std::to_string(a.channels) +
                                 " (every --frames file of a training set needs the same N and C)");
            }
        }
        shots.push_back(std::move(s));
    }
    return shots;
}

namespace {

Index totalFrames(const std::vector<Shot>& shots) {
    Index f = 0;
    for (const Shot& s : shots) f += s.info.frames;
    return f;
}

void readExactly(int fd, const std::string& path, std::uint64_t offset, unsigned char* out,
                 std::size_t bytes) {
    while (bytes > 0) {
        const ssize_t n = ::pread(fd, out, bytes, static_cast<off_t>(offset));
        if (n < 0) {
            if (errno == EINTR) continue;
            throw InputError(path + ": read failed: " + std::strerror(errno));
        }
        if (n == 0) throw InputError(path + ": unexpected end of file (was it truncated while training?)");
        out += n;
        offset += static_cast<std::uint64_t>(n);
        bytes -= static_cast<std::size_t>(n);
    }
}

std::string numberText(double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.6g", v);
    return buf;
}

}  // namespace

NpyBlocks::NpyBlocks(std::vector<Shot> shots, PointRange owned, Index blockPoints)
    : RowBlocks(shots.empty() ? 1 : shots.front().info.points,
                shots.empty() ? 1 : shots.front().info.channels, std::max<Index>(1, totalFrames(shots)),
                owned.first, owned.count,
                std::min(std::max<Index>(1, blockPoints), std::max<Index>(1, owned.count))),
      shots_(std::move(shots)) {
    if (shots_.empty()) throw InputError("train: no --frames file given");
    for (const Shot& s : shots_) {
        const int fd = ::open(s.path.c_str(), O_RDONLY | O_CLOEXEC);
        if (fd < 0) {
            const int error = errno;
            for (int open : fds_) ::close(open);
            throw InputError(s.path + ": cannot open: " + std::strerror(error));
        }
        fds_.push_back(fd);
    }
    buffer_.resize(std::min(this->blockPoints(), std::max<Index>(1, ownedPoints())) * channels(), frames());
    bytes_.resize(static_cast<std::size_t>(buffer_.rows()) * 8);
    mean_ = Eigen::VectorXd::Zero(ownedRows());
    meanKnown_.assign(static_cast<std::size_t>(blockCount()), 0);
}

NpyBlocks::~NpyBlocks() {
    for (int fd : fds_) ::close(fd);
}

void NpyBlocks::readPoints(Index point, Index count, double* meanOut) {
    const Index c = channels();
    const Index rows = count * c;
    Index column = 0;
    for (std::size_t s = 0; s < shots_.size(); ++s) {
        const NpyInfo& info = shots_[s].info;
        const std::size_t item = itemSize(info.dtype);
        const std::size_t bytes = static_cast<std::size_t>(rows) * item;
        for (Index f = 0; f < info.frames; ++f, ++column) {
            const std::uint64_t offset =
                info.dataOffset + static_cast<std::uint64_t>((f * info.points + point) * c) * item;
            readExactly(fds_[s], shots_[s].path, offset, bytes_.data(), bytes);
            double* out = buffer_.col(column).data();
            if (info.dtype == NpyDtype::Float64) {
                std::memcpy(out, bytes_.data(), bytes);
            } else {
                for (Index i = 0; i < rows; ++i) {
                    float v;
                    std::memcpy(&v, bytes_.data() + static_cast<std::size_t>(i) * 4, 4);
                    out[i] = v;
                }
            }
            for (Index i = 0; i < rows; ++i) {
                if (!std::isfinite(out[i])) {
                    throw InputError("train: " + shots_[s].path + ": frame " + std::to_string(f) +
                                     ", point " + std::to_string(point + i / c) + ", channel " +
                                     std::to_string(i % c) + " is " + numberText(out[i]));
                }
            }
        }
    }
    auto raw = buffer_.topRows(rows);
    if (meanOut && raw.size() > 0) smallest_ = std::min(smallest_, raw.minCoeff());
    const Eigen::VectorXd mean = raw.rowwise().mean();
    raw.colwise() -= mean;
    if (meanOut) Eigen::Map<Eigen::VectorXd>(meanOut, rows) = mean;
}

Eigen::Ref<const Eigen::MatrixXd> NpyBlocks::block(Index b) {
    if (b != current_) {
        current_ = -1;
        readPoints(firstPoint() + b * blockPoints(), blockRows(b) / channels(),
                   mean_.data() + blockFirstRow(b));
        meanKnown_[static_cast<std::size_t>(b)] = 1;
        current_ = b;
    }
    return buffer_.topRows(blockRows(b));
}

void NpyBlocks::pointRows(Index point, Eigen::Ref<Eigen::MatrixXd> out) {
    if (!owns(point)) throw std::out_of_range("NpyBlocks: point " + std::to_string(point) + " is not owned");
    current_ = -1;
    readPoints(point, 1, nullptr);
    out = buffer_.topRows(channels());
}

Eigen::VectorXd NpyBlocks::mean() {
    for (Index b = 0; b < blockCount(); ++b)
        if (!meanKnown_[static_cast<std::size_t>(b)]) block(b);
    return mean_;
}

double NpyBlocks::smallestValue() {
    mean();  // every block read once
    return smallest_;
}

std::uint64_t trainingMemoryBound(Index points, Index channels, Index frames, Index maxBasis, Index block,
                                  Index maxKeys, Index blockPoints, int ranks, bool rootRank) {
    // Doubles held at the peak (Training.h explains each term).
    const double f = static_cast<double>(frames);
    const double r = static_cast<double>(std::min(std::max(maxBasis, block), frames));
    const double b = static_cast<double>(block);
    const double nc = static_cast<double>(points) * static_cast<double>(channels);
    const bool inMemory = blockPoints <= 0;
    const double owned = inMemory ? nc
                                  : std::ceil(static_cast<double>(points) / std::max(1, ranks)) *
                                        static_cast<double>(channels);
    const double blockRows = inMemory ? 0.0 : static_cast<double>(std::min(blockPoints, points)) * channels;
    double doubles = 5 * f * f + 3 * r * f + 2 * owned * r + 4 * owned * b +
                     static_cast<double>(maxKeys) * channels * (f + r) + 3 * blockRows * f;
    if (inMemory) doubles += nc * f;  // the frames, centred where they were read (MatrixBlocks(FrameSet&&))
    if (rootRank) doubles += 3 * nc * (r + 1);
    return static_cast<std::uint64_t>(8 * doubles) + static_cast<std::uint64_t>(points);
}

}  // namespace pmsc
