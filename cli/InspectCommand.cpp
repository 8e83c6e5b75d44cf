// `pmsc inspect`: what a model file holds.
#include "app/ExitCodes.h"
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/Format.h"
#include "pmsc/ModelIO.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>

namespace pmsc::cli {

namespace {

/// Fraction of the training energy captured by the first m basis vectors.
double capturedBy(const Model& model, Index m) {
    if (!(model.totalEnergy > 0)) return 1.0;
    return model.singularValues.head(m).squaredNorm() / model.totalEnergy;
}

/// What `pmsc inspect` was asked.
struct InspectArgs {
    std::string modelPath;
    bool json = false;
};

/// Declares the options and parses them; std::nullopt when --help was asked for.
std::optional<InspectArgs> parseInspectArgs(const std::vector<std::string>& args) {
    InspectArgs a;
    ArgParser parser("inspect", "MODEL.pmsc [--json]",
                     "Shows a model file: sizes, key point indices, the basis energy (captured fraction and\n"
                     "singular values), the soft-cache thresholds and the calibration tolerance.");
    parser.positional("MODEL.pmsc", "model file", a.modelPath);
    parser.flag("--json", "print one JSON object instead of text", a.json);
    if (!parser.parse(args)) return std::nullopt;
    return a;
}

/// What is shown beside the model itself: the file, its format version and size, the selector's name.
struct ModelFileFacts {
    std::string path;
    unsigned version = 0;
    std::uintmax_t bytes = 0;
    const char* selector = "";
};

/// The model as one JSON object (--json).
void printModelJson(const Model& model, const ModelFileFacts& file) {
    const std::string& modelPath = file.path;
    const unsigned version = file.version;
    const auto bytes = file.bytes;
    const char* selector = file.selector;
    nlohmann::ordered_json j;
    j["file"] = modelPath;
    j["format_version"] = version;
    j["bytes"] = bytes;
    j["points"] = model.points;
    j["channels"] = model.channels;
    j["shared_channels"] = model.sharedChannels;
    j["train_frames"] = model.trainFrames;
    j["basis"] = model.basisSize();
    j["key_points"] = model.keyCount();
    j["selector"] = selector;
    j["energy_captured"] = model.energyCaptured();
    j["total_energy"] = model.totalEnergy;
    j["singular_values"] = std::vector<double>(model.singularValues.data(),
                                               model.singularValues.data() + model.singularValues.size());
    j["eps_min"] = model.epsMin;
    j["eps_max"] = model.epsMax;
    j["key_error"] = toString(model.keyErrorNorm);
    if (model.keyErrorNorm == KeyErrorNorm::Predicted)
        j["key_error_parts_eps"] = {{"rms", model.partEps.rms}, {"loo", model.partEps.loo}};
    j["tolerance"] = model.tolerance;
    j["train_max_point_residual"] = model.trainMaxPointResidual;
    j["key_indices"] = std::vector<long long>(model.keyPoints.begin(), model.keyPoints.end());
    if (model.regions) {
        nlohmann::ordered_json regions = nlohmann::ordered_json::array();
        for (const Region& g : model.regions->regions)
            regions.push_back({{"points", g.points.size()},
                               {"keys", g.keys.size()},
                               {"basis", g.basisSize()},
                               {"eps_min", g.epsMin},
                               {"eps_max", g.epsMax},
                               {"ratio", g.ratio}});
        j["feather_width"] = model.regions->featherWidth;
        j["max_local_fraction"] = model.regions->maxLocalFraction;
        j["region_key_points"] = model.regions->extraKeyPoints;
        j["regions"] = std::move(regions);
    }
    if (model.keyNeighbours)
        j["key_neighbours"] = {{"per_key", model.keyNeighbours->perKey},
                               {"positions", model.keyNeighbours->fromMean ? "mean" : "given"}};
    if (model.sentinels)
        j["sentinels"] = {{"count", model.sentinels->points.size()},
                          {"covering_radius", model.sentinels->coveringRadius},
                          {"neighbours", model.sentinels->perSentinel},
                          {"positions", toString(model.sentinels->source)}};
    j["non_negative"] = model.nonNegative;
    if (model.learning)
        j["learning"] = {{"rank", model.learning->maxRank},
                         {"stored_vectors", model.basisSize() + model.learning->extraBasis.cols()},
                         {"updates", model.learning->updates},
                         {"discarded_energy", model.learning->discardedEnergy}};
    if (model.calibrationRecord)
        j["calibration"] = {{"rule", toString(model.calibrationRecord->rule)},
                            {"coverage", model.calibrationRecord->coverage},
                            {"held_out_frames", model.calibrationRecord->keyRms.size()}};
    if (model.cross)
        j["cross"] = {{"control_points", model.cross->controlPoints},
                      {"target_points", model.points - model.cross->controlPoints},
                      {"coverage", model.cross->coverage},
                      {"quantile", model.cross->quantile},
                      {"scale", model.cross->scale},
                      {"held_out_pairs", model.cross->keyRms.size()}};
    std::cout << j.dump(2) << "\n";
}

/// The model as text: sizes, energy, keys, thresholds, and the optional sections.
void printModelText(const Model& model, const ModelFileFacts& file) {
    const std::string& modelPath = file.path;
    const unsigned version = file.version;
    const auto bytes = file.bytes;
    const char* selector = file.selector;
    std::cout << modelPath << ": pmsc model, format version " << version << ", " << bytes << " bytes\n";
    std::cout << "  points        N = " << model.points << ", channels C = " << model.channels
              << (model.sharedChannels ? " (sharing one basis)" : "") << ", trained on " << model.trainFrames
              << " frames\n";
    std::cout << "  basis         M = " << model.basisSize() << ", captures "
              << fmt("%.4f", 100 * model.energyCaptured()) << "% of the training energy (total "
              << fmt("%.6g", model.totalEnergy) << ")\n";
    std::cout << "  energy by M  ";
    for (Index m : {Index{1}, Index{2}, Index{5}, Index{10}, Index{20}, Index{50}, Index{100}, Index{200}})
        if (m < model.basisSize())
            std::cout << " " << m << ":" << fmt("%.4f", 100 * capturedBy(model, m)) << "%";
    std::cout << " " << model.basisSize() << ":" << fmt("%.4f", 100 * capturedBy(model, model.basisSize()))
              << "%\n";
    std::cout << "  singular values";
    for (Index i = 0; i < model.singularValues.size(); ++i) {
        if (i % 8 == 0) std::cout << "\n   ";
        std::cout << " " << fmt("%.5g", model.singularValues[i]);
    }
    std::cout << "\n  key points    K = " << model.keyCount() << " (" << selector << "), in selection order:";
    for (std::size_t i = 0; i < model.keyPoints.size(); ++i) {
        if (i % 12 == 0) std::cout << "\n   ";
        std::cout << " " << model.keyPoints[i];
    }
    std::cout << "\n  eps           [" << fmt("%.6g", model.epsMin) << ", " << fmt("%.6g", model.epsMax)
              << "] " << describe(model.keyErrorNorm) << " (data units)\n";
    if (model.keyErrorNorm == KeyErrorNorm::Predicted)
        std::cout << "  parts         key RMS error at or under " << fmt("%.6g", model.partEps.rms)
                  << " or largest leave-one-out key error at or under " << fmt("%.6g", model.partEps.loo)
                  << ": a hit\n";
    std::cout << "  tolerance     "
              << (model.tolerance > 0 ? fmt("%.6g", model.tolerance) + " (eps calibrated for it)"
                                      : std::string("none (eps from the training frames)"))
              << "\n";
    std::cout << "  residual      largest point error of PM on the training frames: "
              << fmt("%.6g", model.trainMaxPointResidual) << "\n";
    if (model.keyNeighbours)
        std::cout << "  neighbours    " << model.keyNeighbours->perKey << " per key (from the "
                  << (model.keyNeighbours->fromMean ? "training mean" : "positions given to train")
                  << "): a hit one part of the key error alone certifies is checked near its worst keys\n";
    if (model.sentinels)
        std::cout << "  sentinels     " << model.sentinels->points.size() << " (from the "
                  << describe(model.sentinels->source) << "), "
                  << (model.sentinels->source == SentinelSource::PointOrder
                          ? "one in each run of " + fmt("%.0f", model.sentinels->coveringRadius) +
                                " moving points (train with --positions for a covering radius)"
                          : "every moving point within " + fmt("%.6g", model.sentinels->coveringRadius) +
                                " of one")
                  << ": computed beside every hit, which stands where PM is within "
                  << fmt("%g", kSentinelShare) << " T of each"
                  << (model.sentinels->perSentinel > 0
                          ? " and the slope to each one's " + std::to_string(model.sentinels->perSentinel) +
                                " nearest, carried " + fmt("%g", kSentinelSlopeShare) +
                                " of the covering radius, stays within T"
                          : std::string())
                  << "\n";
    if (model.nonNegative)
        std::cout
            << "  output        clamped at 0 (every training value was >= 0; pmsc train --no-clamp keeps it "
               "linear)\n";
    if (model.regions) {
        const LocalRegions& lr = *model.regions;
        std::cout << "  regions       R = " << lr.regionCount() << " (local fail-through), feather width "
                  << fmt("%.6g", lr.featherWidth) << ", whole frame above "
                  << fmt("%.3g", 100 * lr.maxLocalFraction) << "% of the points, " << lr.extraKeyPoints.size()
                  << " region keys (evaluated for frames that miss as a whole, and for checked hits)\n";
        std::cout << "    region   points  keys  basis     eps_min     eps_max\n";
        for (Index r = 0; r < lr.regionCount(); ++r) {
            const Region& g = lr.regions[size_t(r)];
            std::cout << "    " << fmt("%6.0f", double(r)) << " " << fmt("%8.0f", double(g.points.size()))
                      << " " << fmt("%5.0f", double(g.keys.size())) << " "
                      << fmt("%6.0f", double(g.basisSize())) << " " << fmt("%11.5g", g.epsMin) << " "
                      << fmt("%11.5g", g.epsMax) << "\n";
        }
    }
    if (model.learning)
        std::cout << "  learning      state of rank " << model.learning->maxRank << " ("
                  << model.basisSize() + model.learning->extraBasis.cols() << " vectors stored), "
                  << model.learning->updates << " updates by pmsc learn\n";
    if (model.calibrationRecord)
        std::cout << "  calibration   " << toString(model.calibrationRecord->rule) << " rule"
                  << (model.calibrationRecord->rule != CalibrationRule::MaxRatio
                          ? " at coverage " + fmt("%.3g", model.calibrationRecord->coverage)
                          : std::string())
                  << ", " << model.calibrationRecord->keyRms.size() << " held-out frames stored\n";
    if (model.cross)
        std::cout << "  cross         points 0.." << model.cross->controlPoints - 1 << " are the control, "
                  << model.points - model.cross->controlPoints
                  << " target points follow; no fail-through; bound " << fmt("%.6g", model.cross->quantile)
                  << " x (key RMS + " << fmt("%.6g", model.cross->scale) << ") at coverage "
                  << fmt("%.3g", model.cross->coverage) << " (" << model.cross->keyRms.size()
                  << " held-out pairs)\n";
}

}  // namespace

int runInspect(const std::vector<std::string>& args) {
    const std::optional<InspectArgs> a = parseInspectArgs(args);
    if (!a) return kExitOk;
    const Model model = readModel(a->modelPath);
    ModelFileFacts file;
    file.path = a->modelPath;
    // The version the file holds (a model without sections is written as version 1).
    file.version = modelFormatVersion(model);
    file.bytes = std::filesystem::file_size(a->modelPath);
    file.selector = model.selector == Selector::QDeim ? "qdeim" : "teleconnection";
    if (a->json)
        printModelJson(model, file);
    else
        printModelText(model, file);
    return kExitOk;
}

}  // namespace pmsc::cli
