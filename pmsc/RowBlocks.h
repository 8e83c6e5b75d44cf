// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"
#include "pmsc/NpyIO.h"

#include <Eigen/Core>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace pmsc {

/// Points per slab where a pass over every point of an in-memory block would otherwise form an
/// array as large as the block (the calibration folds' held-in basis and residual, the basis
/// scaled by its singular values, a shared-channel model's reconstruction of its training
/// frames): 8,192 points of 3 channels and 40 vectors are 8 MB, where the GEMMs run at full rate.
constexpr Index kSlabPoints = 8192;

/// The rows of the mean-removed training matrix Q ((N*C) x F, rows x = p*C + c, section 3) that
/// this process owns: the contiguous points [firstPoint, firstPoint + ownedPoints), handed out in
/// blocks of whole points. Training runs one algorithm over this abstraction: in memory
/// it is one block of every point; out of core, blocks are read from the .npy files on demand, so
/// only one block of F columns is in memory at a time; under MPI each rank owns its share of the
/// points and never reads another rank's rows.
///
/// The mean of a row is over all F frames of that row, so every block is centred on its own: no
/// pass over the data is needed before the first block.
class RowBlocks {
public:
    virtual ~RowBlocks() = default;

    Index points() const { return points_; }          ///< N of the whole training set
    Index channels() const { return channels_; }      ///< C
    Index frames() const { return frames_; }          ///< F (all shots)
    Index firstPoint() const { return firstPoint_; }  ///< first owned point
    Index ownedPoints() const { return ownedPoints_; }
    Index ownedRows() const { return ownedPoints_ * channels_; }
    bool owns(Index point) const { return point >= firstPoint_ && point < firstPoint_ + ownedPoints_; }

    Index blockPoints() const { return blockPoints_; }  ///< points per block (the last may be shorter)
    Index blockCount() const {
        return ownedPoints_ == 0 ? 0 : (ownedPoints_ + blockPoints_ - 1) / blockPoints_;
    }
    /// First row of block b among the owned rows (0 = the row of firstPoint()).
    Index blockFirstRow(Index b) const { return b * blockPoints_ * channels_; }
    Index blockRows(Index b) const {
        return std::min(blockPoints_, ownedPoints_ - b * blockPoints_) * channels_;
    }

    /// Mean-removed rows of block b, blockRows(b) x F. Valid until the next call of block() or
    /// pointRows(). @throws InputError for a NaN/Inf value (named by file, frame, point, channel).
    virtual Eigen::Ref<const Eigen::MatrixXd> block(Index b) = 0;
    /// Mean-removed rows of one owned point (global index), C x F.
    virtual void pointRows(Index point, Eigen::Ref<Eigen::MatrixXd> out) = 0;
    /// The owned rows' means over the F frames (the model's mean), ownedRows() values.
    virtual Eigen::VectorXd mean() = 0;
    /// The smallest value of the owned rows before centring, over every frame (what
    /// Model::nonNegative is decided from); -infinity when a source does not know it.
    virtual double smallestValue() { return -std::numeric_limits<double>::infinity(); }

protected:
    RowBlocks(Index points, Index channels, Index frames, Index firstPoint, Index ownedPoints,
              Index blockPoints);

private:
    Index points_, channels_, frames_, firstPoint_, ownedPoints_, blockPoints_;
};

/// The points rank `rank` of `ranks` owns: [first, first + count), near-equal contiguous shares.
struct PointRange {
    Index first = 0;
    Index count = 0;
};
PointRange pointShare(Index points, int rank, int ranks);

/// Q in memory: the frames are centred once (the copy training always made) and handed out as one
/// block of every point (or blocks of `blockPoints`, for tests).
class MatrixBlocks final : public RowBlocks {
public:
    /// Centres a copy of `frames` (all points, one process).
    explicit MatrixBlocks(const FrameSet& frames, Index blockPoints = 0);
    /// Takes `frames`' values and centres them where they lie: the training matrix is not copied
    /// (a caller done with its frames saves their size in memory).
    explicit MatrixBlocks(FrameSet&& frames, Index blockPoints = 0);
    /// An already prepared matrix (rows x = p*C + c); with `centre` false it is used as it is
    /// (mean() is then zero, smallestValue() unknown), which is what the per-function entry points
    /// (Calibration, KeyPointSelector) need.
    MatrixBlocks(const Eigen::Ref<const Eigen::MatrixXd>& q, Index channels, bool centre,
                 Index blockPoints = 0);

    Eigen::Ref<const Eigen::MatrixXd> block(Index b) override;
    void pointRows(Index point, Eigen::Ref<Eigen::MatrixXd> out) override;
    Eigen::VectorXd mean() override { return mean_; }
    double smallestValue() override { return smallest_; }
    /// The whole centred matrix (in-memory callers use it directly).
    Eigen::Map<const Eigen::MatrixXd> matrix() const { return {values_.data(), rows_, cols_}; }

private:
    Eigen::Map<Eigen::MatrixXd> mutableMatrix() { return {values_.data(), rows_, cols_}; }
    /// Subtracts each row's mean from the matrix in values_, keeping the means.
    void centre();

    /// The (N*C) x F matrix, column-major, aligned as Eigen's own (FrameSet's storage, taken or copied).
    decltype(FrameSet::values) values_;
    Index rows_ = 0, cols_ = 0;
    Eigen::VectorXd mean_;
    double smallest_ = 0;  ///< before centring
};

/// One shot of a training set on disk: the header of a .npy frames file.
struct Shot {
    std::string path;
    NpyInfo info;
};

/// Reads and checks the headers of the shots of one training set: every file must hold the same
/// N points and C channels (the frames are concatenated in the order given).
/// @throws InputError naming the file whose N or C differs from the first one's.
std::vector<Shot> openShots(const std::vector<std::string>& paths);

/// Q streamed from the shots' .npy files: block b is read with one pread per frame (the rows of a
/// block are contiguous in every frame), converted to double, checked for NaN/Inf and centred.
/// Nothing is memory-mapped: the address space used is the block, not the file (a mapping of the
/// whole file would count against an address-space limit like the data it holds).
class NpyBlocks final : public RowBlocks {
public:
    NpyBlocks(std::vector<Shot> shots, PointRange owned, Index blockPoints);
    ~NpyBlocks() override;
    NpyBlocks(const NpyBlocks&) = delete;
    NpyBlocks& operator=(const NpyBlocks&) = delete;

    Eigen::Ref<const Eigen::MatrixXd> block(Index b) override;
    void pointRows(Index point, Eigen::Ref<Eigen::MatrixXd> out) override;
    Eigen::VectorXd mean() override;
    /// Reads the blocks not read yet, as mean() does.
    double smallestValue() override;

private:
    /// Reads rows of `count` points from `point` (global) into buffer_'s top rows, centred; writes
    /// their means to `meanOut` when not null, and then folds their smallest value into smallest_.
    void readPoints(Index point, Index count, double* meanOut);

    std::vector<Shot> shots_;
    std::vector<int> fds_;
    Eigen::MatrixXd buffer_;
    std::vector<unsigned char> bytes_;
    Eigen::VectorXd mean_;         ///< owned rows' means, filled as blocks are read
    std::vector<char> meanKnown_;  ///< per block: mean_ filled
    double smallest_ = std::numeric_limits<double>::infinity();  ///< over the blocks whose mean is known
    Index current_ = -1;                                         ///< block in buffer_, -1 none
};

/// Bytes the shared training algorithm holds at its peak for one rank, beyond the program itself
/// (Training.h states the formula). blockPoints = 0 means in memory (one block of every point
/// plus the frames as read).
std::uint64_t trainingMemoryBound(Index points, Index channels, Index frames, Index maxBasis, Index block,
                                  Index maxKeys, Index blockPoints, int ranks, bool rootRank);

}  // namespace pmsc
