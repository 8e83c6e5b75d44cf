// libFuzzer target: the text the command line takes apart: frame ranges ("A-B[:STEP]",
// cli/Args), evaluator specs ("NAME[:ARGS]", evaluators/EvaluatorRegistry, and the skin
// evaluator's "ASSET[:fps=F][:animation=A]"), and the option parser with its number converters
// (cli/Args). The first byte picks the parser; the rest is the text. The contract: a parser
// returns a value that meets its documented invariants or throws the documented exception type.
#include "cli/Args.h"
#include "evaluators/EvaluatorRegistry.h"
#include "evaluators/SkinEvaluator.h"
#include "pmsc/Errors.h"

#include <cmath>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

using namespace pmsc;

namespace {

void frameRange(const std::string& text) {
    app::FrameSpan s;
    try {
        s = cli::parseFrameSpan("--frames", text);
    } catch (const cli::UsageError&) {
        return;
    }
    if (s.first < 0 || s.last < s.first || s.step < 1 || (s.last - s.first) % s.step != 0 || s.count() < 1)
        std::abort();
    // What text() prints parses back to the same range.
    const app::FrameSpan again = cli::parseFrameSpan("--frames", s.text());
    if (again.first != s.first || again.last != s.last || again.step != s.step) std::abort();
}

/// A registry of kinds that make nothing real: the spec's split into NAME and ARGS is under test.
struct Stub final : PointEvaluator {
    explicit Stub(std::string a) : args(std::move(a)) {}
    std::string name() const override { return "stub"; }
    Index pointCount() const override { return 1; }
    Index channelCount() const override { return 1; }
    Index frameCount() const override { return 1; }
    void evaluate(Index, std::span<const Index>, double* out) const override { out[0] = 0; }
    std::string args;
};

void evaluatorSpec(const std::string& spec) {
    static const evaluators::EvaluatorRegistry registry = [] {
        evaluators::EvaluatorRegistry r;
        r.add({"replay", "FILE.npy", "", [](const std::string& a) -> std::unique_ptr<PointEvaluator> {
                   return std::make_unique<Stub>(evaluators::requireArgs("replay", "FILE.npy", a));
               }});
        r.add({"skin", "ASSET", "", [](const std::string& a) -> std::unique_ptr<PointEvaluator> {
                   const auto o = evaluators::parseSkinArgs(evaluators::requireArgs("skin", "ASSET", a));
                   if (o.path.empty() || !(o.fps > 0) || !std::isfinite(o.fps)) std::abort();
                   return std::make_unique<Stub>(o.path);
               }});
        r.add({"cornell", "", "", [](const std::string& a) -> std::unique_ptr<PointEvaluator> {
                   return std::make_unique<Stub>(a);
               }});
        return r;
    }();
    try {
        const auto e = registry.make(spec);
        if (!e) std::abort();
    } catch (const std::invalid_argument&) {  // unknown name, missing ARGS
    } catch (const InputError&) {             // the skin arguments
    }
}

void skinArgs(const std::string& text) {
    try {
        const auto o = evaluators::parseSkinArgs(text);
        if (o.path.empty() || !(o.fps > 0) || !std::isfinite(o.fps)) std::abort();
    } catch (const InputError&) {
    }
}

/// A command line of NUL-separated words through an ArgParser with every kind of option.
void commandLine(const std::string& text) {
    std::vector<std::string> args;
    std::size_t start = 0;
    for (;;) {
        const auto nul = text.find('\0', start);
        args.push_back(text.substr(start, nul - start));
        if (nul == std::string::npos) break;
        start = nul + 1;
    }
    Index threads = 0;
    double tolerance = 0;
    std::vector<Index> keys;
    std::pair<double, double> eps;
    NpyDtype dtype = NpyDtype::Float64;
    bool json = false;
    std::string model, frames;
    cli::ArgParser p("fuzz", "[options] MODEL", "");
    p.option("--threads", "T", "",
             [&](const std::string& v) { threads = cli::parseIndex("--threads", v, 1, 256); });
    p.option("--tolerance", "E", "",
             [&](const std::string& v) { tolerance = cli::parseDouble("--tolerance", v, 0); });
    p.option("--keys", "LIST", "", [&](const std::string& v) { keys = cli::parseIndexList("--keys", v); });
    p.option("--eps", "A,B", "", [&](const std::string& v) { eps = cli::parseDoublePair("--eps", v); });
    p.option("--dtype", "T", "", [&](const std::string& v) { dtype = cli::parseDtype("--dtype", v); });
    p.option("--frames", "FILE", "", frames);
    p.repeatable("--frames");
    p.flag("--json", "", json);
    p.positional("MODEL", "", model, false);
    try {
        if (!p.parse(args)) return;
    } catch (const cli::UsageError&) {
        return;
    }
    if (p.given("--threads") && (threads < 1 || threads > 256)) std::abort();
    if (p.given("--tolerance") && !(tolerance >= 0 && std::isfinite(tolerance))) std::abort();
    for (Index k : keys)
        if (k < 0) std::abort();
    if (!std::isfinite(eps.first) || !std::isfinite(eps.second)) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size == 0) return 0;
    const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
    switch (data[0] % 4) {
        case 0:
            frameRange(text);
            break;
        case 1:
            evaluatorSpec(text);
            break;
        case 2:
            skinArgs(text);
            break;
        default:
            commandLine(text);
            break;
    }
    return 0;
}
