// `pmsc run`: a render-farm task. One frame range of an evaluator through the soft-caching engine,
// one atomic file per frame, resumable, with a JSON stats file and documented exit codes.
#include "app/Run.h"

#include "app/CrossRun.h"
#include "app/ExitCodes.h"
#include "app/MemoryLimit.h"
#include "engine/Engine.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/KeptFrames.h"
#include "pmsc/Training.h"  // pmsc::Cancelled

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <memory>
#include <optional>
#include <sstream>

#include <unistd.h>

namespace fs = std::filesystem;

namespace pmsc::app {

namespace {

using Clock = std::chrono::steady_clock;

double unixSeconds() {
    return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

std::string isoTime(double unix) {
    const std::time_t t = static_cast<std::time_t>(unix);
    std::tm tm{};
    ::gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf;
}

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// One record per frame of the range, in range order.
struct FrameRecord {
    Index frame = 0;
    std::string state = "pending";  // "hit", "blend", "miss", "skipped", "pending" (not reached)
    double weight = 0;
    double keyRms = 0;
    bool keysFinite = true;
    double writeSeconds = 0;
};

/// The engine's consumer: writes each finished frame to its file, in order, and records it.
class FileSink : public engine::FrameSink {
public:
    FileSink(const FrameOutput& output, std::vector<FrameRecord>& records, const FrameSpan& span,
             const PointEvaluator& evaluator, KeptFrames* keep)
        : output_(output), records_(records), span_(span), evaluator_(evaluator), keep_(keep) {}

    void write(const engine::FrameResult& r) override {
        const auto start = Clock::now();
        output_.write(r.frame, r.values.data());
        FrameRecord& rec = records_[static_cast<std::size_t>((r.frame - span_.first) / span_.step)];
        rec.state = std::string(toString(r.state));
        rec.weight = r.weight;
        rec.keyRms = r.keyError;
        rec.keysFinite = r.keysFinite;
        rec.writeSeconds = since(start);
        writeSeconds += rec.writeSeconds;
        ++written;
        if (keep_ && !r.failed && r.state != CacheState::Hit) {
            if (r.state == CacheState::Miss) {
                keep_->add(r.frame, r.state, r.keyError, r.values.data());
            } else {
                // A blend's output mixes in PM; the full values it was blended with are not kept by
                // the engine, so they are evaluated again (blends are the rare frames in the band).
                full_.resize(r.values.size());
                evaluator_.evaluateAll(r.frame, full_.data());
                keep_->add(r.frame, r.state, r.keyError, full_.data());
            }
        }
    }

    double writeSeconds = 0;
    Index written = 0;

private:
    const FrameOutput& output_;
    std::vector<FrameRecord>& records_;
    const FrameSpan& span_;
    const PointEvaluator& evaluator_;
    KeptFrames* keep_;
    std::vector<double> full_;
};

}  // namespace

BasisPrecision runBasisPrecision(const RunOptions& options) {
    if (options.basisPrecision) return *options.basisPrecision;
    const bool storedInFloat =
        options.format == "vdb" || (options.format == "npy" && options.dtype == NpyDtype::Float32);
    return storedInFloat ? BasisPrecision::Single : BasisPrecision::Double;
}

std::string defaultStatsPath(const std::string& outDir, const FrameSpan& frames) {
    std::string name = "pmsc-run." + std::to_string(frames.first) + "-" + std::to_string(frames.last);
    if (frames.step != 1) name += "_by" + std::to_string(frames.step);
    return (fs::path(outDir) / (name + ".json")).string();
}

namespace {

// runFrames() in named steps: check, scan what is done, run the engine, account, write the stats.

/// Every check that can fail on bad input, before any work or any file.
void checkEvaluatorFitsModel(const Model& model, const PointEvaluator& evaluator, const RunOptions& options) {
    if (evaluator.pointCount() != model.points || evaluator.channelCount() != model.channels)
        throw InputError("evaluator '" + options.evaluatorSpec + "' has " +
                         std::to_string(evaluator.pointCount()) + " points x " +
                         std::to_string(evaluator.channelCount()) + " channels, but the model " +
                         options.modelPath + " was trained on " + std::to_string(model.points) +
                         " points x " + std::to_string(model.channels) + " channels");
    checkFramesInside(options.frames, evaluator, options.evaluatorSpec);
}

/// Resume: which frames of the span already have a valid output (skipped), which are to do.
struct ResumeScan {
    std::vector<FrameRecord> records;  // one per frame of the span, in order
    std::vector<Index> toDo;
    double seconds = 0;
};

ResumeScan scanOutputs(const FrameOutput& output, const FrameSpan& span, bool force, RunReport& report) {
    const auto scanStart = Clock::now();
    ResumeScan scan;
    scan.records.resize(static_cast<std::size_t>(span.count()));
    for (Index i = 0; i < span.count(); ++i) {
        const Index f = span.frame(i);
        FrameRecord& record = scan.records[static_cast<std::size_t>(i)];
        record.frame = f;
        const bool exists = fs::exists(output.path(f));
        if (exists && !force && output.isValid(f)) {
            record.state = "skipped";
            ++report.skipped;
            continue;
        }
        if (exists && !force) ++report.replaced;
        scan.toDo.push_back(f);
    }
    report.staleTemporaries = output.removeStaleTemporaries(scan.toDo);
    scan.seconds = since(scanStart);
    return scan;
}

/// How the engine's runs ended: their stats, and the error that stopped them, if any.
struct EngineOutcome {
    nlohmann::json runs = nlohmann::json::array();
    std::string status = "ok", error;
    int exitCode = kExitOk;
    std::exception_ptr failure;
    double seconds = 0;
};

/// The engine, once per contiguous run of the frames to do; adds its counters to `report`. An
/// error (interrupt, evaluator failure, a write that failed) ends the runs and is returned, not
/// thrown, so the caller can still commit kept frames and write the stats file.
EngineOutcome runEngineGroups(const Model& model, const PointEvaluator& evaluator, const RunOptions& options,
                              const std::vector<Index>& toDo, FileSink& sink, RunReport& report,
                              Clock::time_point wallStart) {
    engine::EngineOptions engineOptions;
    engineOptions.threads = options.threads;
    engineOptions.cancel = options.cancel;
    engineOptions.localFailThrough = !options.wholeFrameFailThrough;
    engineOptions.memoryLimit = options.memoryLimit;
    engineOptions.basisPrecision = runBasisPrecision(options);
    Index doneBefore = 0;
    auto lastShown = Clock::now() - std::chrono::seconds(1);
    const Index total = static_cast<Index>(toDo.size());
    engineOptions.progress = [&](const engine::Progress& p) {
        const Index done = doneBefore + p.framesDone;
        const auto now = Clock::now();
        if (done < total && std::chrono::duration<double>(now - lastShown).count() < 0.1) return;
        lastShown = now;
        const double elapsed = since(wallStart);
        const Index decided = report.hits + report.blends + report.misses + p.hits + p.blends + p.misses;
        char stage[160];
        std::snprintf(
            stage, sizeof stage, "%lld/%lld frames, %.1f frames/s, hits %.0f%%", static_cast<long long>(done),
            static_cast<long long>(total), elapsed > 0 ? static_cast<double>(done) / elapsed : 0.0,
            decided > 0 ? 100.0 * static_cast<double>(report.hits + p.hits) / static_cast<double>(decided)
                        : 0.0);
        if (options.progress) options.progress(stage, static_cast<double>(done), static_cast<double>(total));
    };

    EngineOutcome outcome;
    const auto engineStart = Clock::now();
    const Index step = options.frames.step;
    try {
        engine::Engine engine(model, evaluator, engineOptions);
        for (std::size_t i = 0; i < toDo.size();) {
            std::size_t j = i + 1;
            while (j < toDo.size() && toDo[j] == toDo[j - 1] + step) ++j;
            engine::FrameRange range{toDo[i], static_cast<Index>(j - i), step};
            try {
                engine.run(range, sink);
            } catch (...) {
                outcome.runs.push_back(nlohmann::json::parse(engine.lastStats().toJson(-1)));
                throw;
            }
            const engine::RunStats& s = engine.lastStats();
            outcome.runs.push_back(nlohmann::json::parse(s.toJson(-1)));
            report.hits += s.hits;
            report.blends += s.blends;
            report.misses += s.misses;
            doneBefore += s.framesDelivered;
            i = j;
        }
    } catch (...) {
        const ExitReason reason = exitReason(std::current_exception());
        outcome.status = reason.status, outcome.error = reason.what, outcome.exitCode = reason.code;
        outcome.failure = std::current_exception();
    }
    outcome.seconds = since(engineStart);
    return outcome;
}

/// After a failure the counters of the failed group are only in the records' states.
void recountFromRecords(const std::vector<FrameRecord>& records, RunReport& report) {
    report.hits = report.blends = report.misses = 0;
    for (const auto& r : records) {
        report.hits += r.state == "hit";
        report.blends += r.state == "blend";
        report.misses += r.state == "miss";
    }
}

/// The stats file: what a wrangler reads after the farm ran.
nlohmann::json statsJson(const Model& model, const RunOptions& options, const FrameOutput& output,
                         const RunReport& report, const ResumeScan& scan, EngineOutcome& outcome,
                         const FileSink& sink, double startedUnix) {
    const FrameSpan& span = options.frames;
    nlohmann::json j;
    j["pmsc_run_stats"] = 1;
    j["status"] = outcome.status;
    j["exit_code"] = outcome.exitCode;
    if (!outcome.error.empty()) j["error"] = outcome.error;
    j["command"] = options.commandLine;
    j["host"] = hostName();
    j["pid"] = static_cast<long long>(::getpid());
    j["started_at"] = isoTime(startedUnix);
    j["started_unix"] = startedUnix;
    j["finished_unix"] = unixSeconds();
    j["model"] = options.modelPath;
    j["evaluator"] = options.evaluatorSpec;
    j["points"] = model.points;
    j["channels"] = model.channels;
    j["frames"] = {{"range", span.text()},
                   {"first", span.first},
                   {"last", span.last},
                   {"step", span.step},
                   {"count", span.count()}};
    j["out"] = options.outDir;
    j["format"] = output.extension().substr(1);
    j["threads"] = options.threads;
    j["basis_precision"] = runBasisPrecision(options) == BasisPrecision::Single ? "single" : "double";
    j["frame_buffer_budget_bytes"] = options.memoryLimit;
    j["force"] = options.force;
    j["frames_evaluated"] = report.evaluated;
    j["frames_skipped"] = report.skipped;
    j["frames_replaced_invalid"] = report.replaced;
    j["stale_temporaries_removed"] = report.staleTemporaries;
    j["hits"] = report.hits;
    j["blends"] = report.blends;
    j["misses"] = report.misses;
    if (!options.keepMisses.empty())
        j["kept_misses"] = {{"path", options.keepMisses}, {"frames", report.kept}};
    j["hit_rate"] =
        report.evaluated > 0 ? static_cast<double>(report.hits) / static_cast<double>(report.evaluated) : 0.0;
    j["seconds"] = {{"wall", report.seconds},
                    {"scan", scan.seconds},
                    {"engine", outcome.seconds},
                    {"write", sink.writeSeconds}};
    j["frames_per_second"] =
        outcome.seconds > 0 ? static_cast<double>(report.evaluated) / outcome.seconds : 0.0;
    j["engine_runs"] = std::move(outcome.runs);
    nlohmann::json perFrame = nlohmann::json::array();
    for (const auto& r : scan.records) {
        nlohmann::json f = {{"frame", r.frame}, {"state", r.state}};
        if (r.state == "hit" || r.state == "blend" || r.state == "miss") {
            f["weight"] = r.weight;
            f["key_rms"] = r.keysFinite ? nlohmann::json(r.keyRms) : nlohmann::json(nullptr);
            f["write_seconds"] = r.writeSeconds;
        }
        perFrame.push_back(std::move(f));
    }
    j["per_frame"] = std::move(perFrame);
    return j;
}

}  // namespace

RunReport runFrames(const Model& model, const PointEvaluator& evaluator, const RunOptions& options) {
    const auto wallStart = Clock::now();
    const double startedUnix = unixSeconds();
    const FrameSpan& span = options.frames;

    checkEvaluatorFitsModel(model, evaluator, options);
    // Only another format asks the evaluator for its writers (an exec child's asks for positions).
    FrameOutput output(options.outDir, options.format,
                       options.format == "npy" ? std::vector<std::shared_ptr<const FrameWriter>>{}
                                               : offeredWriters(evaluator),
                       model.points, model.channels, options.dtype);
    ensureWritableFolder(options.outDir);
    std::optional<KeptFrames> keep;
    if (!options.keepMisses.empty())
        keep.emplace(options.keepMisses, model.points, model.channels, options.dtype,
                     "model=" + options.modelPath + " evaluator=" + options.evaluatorSpec);

    RunReport report;
    report.frames = span.count();
    report.statsPath = options.statsPath.empty() ? defaultStatsPath(options.outDir, span) : options.statsPath;
    ResumeScan scan = scanOutputs(output, span, options.force, report);

    FileSink sink(output, scan.records, span, evaluator, keep ? &*keep : nullptr);
    EngineOutcome outcome = runEngineGroups(model, evaluator, options, scan.toDo, sink, report, wallStart);
    // The frames kept before a failure are real frames: keep them too (learning needs no order).
    if (keep) {
        try {
            keep->commit();
            report.kept = keep->count();
        } catch (const IoError&) {
            if (!outcome.failure) throw;
        }
    }
    report.evaluated = sink.written;
    if (outcome.failure) recountFromRecords(scan.records, report);
    report.seconds = since(wallStart);

    const std::exception_ptr failure = outcome.failure;
    const nlohmann::json stats = statsJson(model, options, output, report, scan, outcome, sink, startedUnix);
    try {
        writeFileAtomically(report.statsPath, stats.dump(2) + "\n");
    } catch (const IoError&) {
        if (!failure) throw;  // the run's own error matters more than its stats
    }
    if (failure) std::rethrow_exception(failure);
    return report;
}

}  // namespace pmsc::app
