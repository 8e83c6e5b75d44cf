// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameWriter.h"

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <utility>

namespace pmsc::scene {

/// One frame of a scene's lighting cache as a .vdb file (`pmsc run --format vdb`). The scene says
/// how to write its grids and how many active voxels a file holds; both touch OpenVDB in the
/// scene's own .cpp, so this header stays free of it.
class VdbFrameWriter final : public FrameWriter {
public:
    /// Writes frame `frame`'s N*C values to `path`. @throws pmsc::IoError.
    using Write = std::function<void(const std::string& path, Index frame, const double* values)>;
    /// The active voxels of the scene's grid in a file. @throws for a missing or foreign file.
    using ActiveVoxels = std::function<std::int64_t(const std::string& path)>;

    VdbFrameWriter(std::int64_t voxelCount, Write write, ActiveVoxels activeVoxels)
        : voxelCount_(voxelCount), write_(std::move(write)), activeVoxels_(std::move(activeVoxels)) {}

    std::string extension() const override { return ".vdb"; }
    void write(const std::string& path, Index frame, const double* values) const override {
        write_(path, frame, values);
    }
    bool isValid(const std::string& path) const override {
        try {
            return std::filesystem::is_regular_file(path) && activeVoxels_(path) == voxelCount_;
        } catch (...) {
            return false;
        }
    }

private:
    std::int64_t voxelCount_;
    Write write_;
    ActiveVoxels activeVoxels_;
};

}  // namespace pmsc::scene
