#include "engine/RunStats.h"

#include <nlohmann/json.hpp>

namespace pmsc::engine {

std::string RunStats::toJson(int indent) const {
    nlohmann::json j;
    j["frames_requested"] = framesRequested;
    j["frames_delivered"] = framesDelivered;
    j["hits"] = hits;
    j["blends"] = blends;
    j["misses"] = misses;
    j["failed"] = failed;
    j["forced_misses"] = forcedMisses;
    j["wall_seconds"] = wallSeconds;
    j["frames_per_second"] = framesPerSecond;
    j["threads"] = threads;
    j["max_frames_in_flight"] = maxFramesInFlight;
    j["peak_frames_in_flight"] = peakFramesInFlight;
    j["fail_through_chunks"] = chunks;
    j["cancelled"] = cancelled;
    if (!regions.empty()) {
        j["local_frames"] = localFrames;
        j["points_evaluated_fraction"] = pointsEvaluatedFraction;
        nlohmann::json r = nlohmann::json::array();
        for (const RegionCounts& c : regions)
            r.push_back({{"hits", c.hits}, {"blends", c.blends}, {"misses", c.misses}});
        j["regions"] = std::move(r);
    }
    nlohmann::json list = nlohmann::json::array();
    for (const NodeTiming& n : nodes)
        list.push_back({{"node", n.node}, {"seconds", n.seconds}, {"calls", n.calls}});
    j["nodes"] = std::move(list);
    return j.dump(indent);
}

}  // namespace pmsc::engine
