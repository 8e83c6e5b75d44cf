// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"
#include "viewer/RelightScene.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace pmsc::viewer {

/// One message of the viewer protocol's `update` (docs/viewer.md): the text part as JSON and the
/// binary part's range of half floats.
struct Update {
    nlohmann::json text;  ///< {"type": "update", "seq", "target", "phase", "state", ...}
    std::uint32_t seq = 0;
    std::uint32_t first = 0;           ///< first point of the range
    std::vector<std::uint16_t> halfs;  ///< count x C half floats (count = halfs.size() / C)
    bool binaryFollows = true;         ///< false for an `error` message (text only)

    /// The binary message: "PSMV" magic, seq, first, count (uint32 LE), then the halfs.
    std::string binary(Index channels) const;
};

/// The relighting of one viewer: each request (new control values) goes through the engine, whose
/// soft cache decides hit, blend or miss; a hit sends the reconstruction, a blend or miss sends the
/// point-multiplied estimate at once and then each fail-through branch's final values as it
/// finishes, so the page converges to what the engine delivers. A newer request cancels the
/// frame in progress (EngineOptions::cancel): only the newest pending request is computed.
///
/// Threads: receive() and the destructor from the connection's thread; the work runs on the
/// session's own thread (and the engine's arena); `emit` is called from that thread and from the
/// engine's workers, one call at a time (serialized by the session), in the order the page must
/// apply the updates.
class RelightSession {
public:
    using Emit = std::function<void(Update&&)>;

    /// @param model  trained on `scene`'s points (checked: N and C)
    /// @param threads  the engine's worker threads (0: every core)
    /// @throws pmsc::InputError if the model does not match the scene.
    RelightSession(const Model& model, const RelightScene& scene, int threads, Emit emit);
    ~RelightSession();
    RelightSession(const RelightSession&) = delete;
    RelightSession& operator=(const RelightSession&) = delete;

    /// One client message (JSON text: set, mode or reference). Returns at once; the work is queued.
    /// @throws pmsc::InputError (one line) for a malformed message or a bad control; the session
    ///         goes on.
    void receive(const std::string& text);

    /// Frames answered so far, by state (for tests and the server's log).
    struct Counts {
        std::uint64_t hits = 0, blends = 0, misses = 0, full = 0, cancelled = 0;
    };
    Counts counts() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace pmsc::viewer
