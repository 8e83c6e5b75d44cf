#include "examples/face/FaceLocalReport.h"

#include "examples/common/LocalFailThroughReport.h"

namespace pmsc::face {

nlohmann::json localFailThroughSets(const Model& model, const PointEvaluator& evaluator,
                                    const FaceAnimation& animation, const std::vector<Index>& validationSeqs,
                                    const std::vector<Index>& novelSeqs, double percent, int threads,
                                    const std::function<void(std::string_view, double, double)>& step,
                                    Index maxFramesPerSet) {
    std::vector<Index> validationSample, mixedSeqs;
    for (size_t i = 0; i < validationSeqs.size() && i < 4; ++i) validationSample.push_back(validationSeqs[i]);
    for (Index s = 0; s < Index(animation.sequences().size()); ++s)
        if (animation.sequences()[size_t(s)].mixed) mixedSeqs.push_back(s);
    examples::LocalReportScale scale;  // its default keys are the face's: % of the head diagonal, 1%
    scale.unit = percent;
    scale.limit = 1;
    nlohmann::json local;
    local["regions"] = model.regions->regionCount();
    local["region_keys"] = model.regions->extraKeyPoints.size();
    local["feather_width_pct_bbox"] = model.regions->featherWidth / percent;
    local["max_local_fraction"] = model.regions->maxLocalFraction;
    const std::pair<const char*, const std::vector<Index>*> sets[] = {
        {"validation", &validationSample}, {"novel", &novelSeqs}, {"mixed", &mixedSeqs}};
    for (const auto& [name, seqs] : sets) {
        if (seqs->empty()) continue;
        const std::string stage = std::string("local ") + name;
        std::vector<Index> frames = animation.framesOf(*seqs);
        if (maxFramesPerSet > 0 && Index(frames.size()) > maxFramesPerSet)
            frames.resize(size_t(maxFramesPerSet));
        local[name] = examples::localFailThroughReport(model, evaluator, frames, scale, threads,
                                                       [&](double d) { step(stage, d, 1); });
    }
    return local;
}

}  // namespace pmsc::face
