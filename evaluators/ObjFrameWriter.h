// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameWriter.h"

#include <cstdint>
#include <vector>

namespace pmsc::evaluators {

/// One posed frame of a triangle mesh as Wavefront .obj: a comment line
/// naming the frame, N `v x y z` lines (shortest decimal that reads back to
/// the same double, so the file holds the evaluator's values exactly), then
/// the triangles as 1-based `f a b c` lines. Byte-identical for identical
/// values, which is what lets a farm compare outputs of different runs.
///
/// Thread safety: const, stateless apart from the mesh it refers to.
class ObjFrameWriter final : public FrameWriter {
public:
    /// @param[in] points    N, vertices per frame (values carry 3 channels).
    /// @param[in] triangles 3 point indices per triangle; must outlive the writer.
    ObjFrameWriter(Index points, const std::vector<std::int64_t>* triangles);

    std::string extension() const override { return ".obj"; }
    void write(const std::string& path, Index frame, const double* values) const override;
    /// Parses the whole file: exactly N finite vertices and the mesh's
    /// triangle count with indices in range.
    bool isValid(const std::string& path) const override;

private:
    Index points_;
    const std::vector<std::int64_t>* triangles_;
};

}  // namespace pmsc::evaluators
