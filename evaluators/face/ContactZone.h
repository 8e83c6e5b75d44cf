// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace pmsc::face {

/// The vertices a contact deformer moves (its zone) and, for each, the candidate triangles it
/// tests and the vertices those triangles read (so the rig knows what a key point's posing
/// needs), stored as compressed rows. Shared by LipContact and ColliderContact.
class ContactZone {
public:
    using Triangles = std::vector<std::array<std::int32_t, 3>>;

    ContactZone() = default;
    /// An empty zone over a mesh of `vertices` vertices.
    explicit ContactZone(Index vertices) : index_(static_cast<size_t>(vertices), -1) {}

    /// Adds vertex v with its candidate triangles; its inputs are their corners, ascending.
    void add(Index v, std::span<const std::int32_t> cands, const Triangles& triangles) {
        index_[static_cast<size_t>(v)] = static_cast<std::int32_t>(vertices_.size());
        vertices_.push_back(v);
        candidates_.insert(candidates_.end(), cands.begin(), cands.end());
        candidateStart_.push_back(static_cast<std::int32_t>(candidates_.size()));
        const size_t first = inputs_.size();
        for (std::int32_t t : cands)
            for (std::int32_t u : triangles[static_cast<size_t>(t)]) inputs_.push_back(u);
        std::sort(inputs_.begin() + static_cast<std::ptrdiff_t>(first), inputs_.end());
        inputs_.erase(std::unique(inputs_.begin() + static_cast<std::ptrdiff_t>(first), inputs_.end()),
                      inputs_.end());
        inputStart_.push_back(static_cast<std::int32_t>(inputs_.size()));
    }

    /// v's index among the zone's vertices, or -1 outside the zone.
    std::int32_t index(Index v) const { return index_[static_cast<size_t>(v)]; }
    bool contains(Index v) const { return index(v) >= 0; }
    Index size() const { return static_cast<Index>(vertices_.size()); }
    const std::vector<Index>& vertices() const { return vertices_; }
    /// Candidate triangles of zone vertex v.
    std::span<const std::int32_t> candidates(Index v) const { return row(candidates_, candidateStart_, v); }
    /// Vertices whose posed positions the contact of zone vertex v reads, ascending.
    std::span<const std::int32_t> inputVertices(Index v) const { return row(inputs_, inputStart_, v); }

private:
    std::span<const std::int32_t> row(const std::vector<std::int32_t>& values,
                                      const std::vector<std::int32_t>& start, Index v) const {
        const auto z = static_cast<size_t>(index(v));
        return {values.data() + start[z], static_cast<size_t>(start[z + 1] - start[z])};
    }

    std::vector<std::int32_t> index_;  // per mesh vertex: index into the zone or -1
    std::vector<Index> vertices_;
    std::vector<std::int32_t> candidateStart_{0}, candidates_;
    std::vector<std::int32_t> inputStart_{0}, inputs_;
};

}  // namespace pmsc::face
