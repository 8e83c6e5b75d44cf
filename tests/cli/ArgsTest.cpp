#include "cli/Args.h"

#include "tests/common/TempDir.h"

#include <gtest/gtest.h>

#include <fstream>

namespace {

using pmsc::cli::ArgParser;
using pmsc::cli::UsageError;

std::string usageMessage(ArgParser& parser, const std::vector<std::string>& args) {
    try {
        parser.parse(args);
    } catch (const UsageError& e) {
        return e.what();
    }
    return "NO ERROR";
}

TEST(Args, ParsesBothValueFormsFlagsAndPositionals) {
    std::string model, out;
    pmsc::Index keys = 0;
    bool json = false;
    ArgParser p("inspect", "MODEL", "d");
    p.positional("MODEL", "m", model);
    p.option("--out", "F", "o", out);
    p.option("--keys", "K", "k", [&](const std::string& v) { keys = pmsc::cli::parseIndex("--keys", v, 1); });
    p.flag("--json", "j", json);
    EXPECT_TRUE(p.parse({"a.pmsc", "--out=x.json", "--keys", "17", "--json"}));
    EXPECT_EQ(model, "a.pmsc");
    EXPECT_EQ(out, "x.json");
    EXPECT_EQ(keys, 17);
    EXPECT_TRUE(json);
    EXPECT_TRUE(p.given("--keys"));
}

TEST(Args, EveryMistakeNamesTheCommandAndTheOption) {
    std::string a;
    ArgParser p("train", "", "");
    p.option("--frames", "F", "f", a, true);
    EXPECT_EQ(usageMessage(p, {"--nope"}), "train: unknown option '--nope' (see 'pmsc train --help')");
    ArgParser q("train", "", "");
    q.option("--frames", "F", "f", a, true);
    EXPECT_EQ(usageMessage(q, {"--frames"}), "train: missing value for --frames (see 'pmsc train --help')");
    ArgParser r("train", "", "");
    r.option("--frames", "F", "f", a, true);
    EXPECT_EQ(usageMessage(r, {}), "train: missing --frames (see 'pmsc train --help')");
    ArgParser s("train", "", "");
    s.option("--frames", "F", "f", a, true);
    EXPECT_EQ(usageMessage(s, {"--frames", "a", "--frames", "b"}),
              "train: --frames given twice (see 'pmsc train --help')");
    ArgParser t("train", "", "");
    t.option("--frames", "F", "f", a, true);
    EXPECT_EQ(usageMessage(t, {"--frames", "a", "extra"}),
              "train: unexpected argument 'extra' (see 'pmsc train --help')");
}

TEST(Args, NumbersAreStrict) {
    using pmsc::cli::parseDouble;
    using pmsc::cli::parseIndex;
    EXPECT_EQ(parseIndex("--k", "42"), 42);
    EXPECT_THROW(parseIndex("--k", "42x"), UsageError);
    EXPECT_THROW(parseIndex("--k", ""), UsageError);
    EXPECT_THROW(parseIndex("--k", " 4"), UsageError);
    EXPECT_THROW(parseIndex("--k", "4.0"), UsageError);
    EXPECT_THROW(parseIndex("--k", "99999999999999999999"), UsageError);
    EXPECT_THROW(parseIndex("--k", "-1", 0), UsageError);
    EXPECT_THROW(parseIndex("--k", "5", 0, 4), UsageError);
    EXPECT_EQ(parseDouble("--x", "1e-3"), 1e-3);
    EXPECT_EQ(parseDouble("--x", "-2.5"), -2.5);
    EXPECT_THROW(parseDouble("--x", "nan"), UsageError);
    EXPECT_THROW(parseDouble("--x", "inf"), UsageError);
    EXPECT_THROW(parseDouble("--x", "1,5"), UsageError);
    EXPECT_THROW(parseDouble("--x", "2", 0, 1), UsageError);
    EXPECT_EQ(pmsc::cli::parseIndexList("--f", "3,1,2"), (std::vector<pmsc::Index>{3, 1, 2}));
    EXPECT_THROW(pmsc::cli::parseIndexList("--f", "3,,2"), UsageError);
    EXPECT_THROW(pmsc::cli::parseIndexList("--f", "3,-2"), UsageError);
    EXPECT_EQ(pmsc::cli::parseDoublePair("--eps", "0.1,0.15"), std::make_pair(0.1, 0.15));
    EXPECT_THROW(pmsc::cli::parseDoublePair("--eps", "0.1"), UsageError);
    EXPECT_THROW(pmsc::cli::parseDoublePair("--eps", "0.1,0.2,0.3"), UsageError);
}

TEST(Args, NegativeNumbersAreValuesNotOptions) {
    double x = 0;
    ArgParser p("c", "", "");
    p.option("--x", "X", "x", [&](const std::string& v) { x = pmsc::cli::parseDouble("--x", v); });
    EXPECT_TRUE(p.parse({"--x", "-0.5"}));
    EXPECT_EQ(x, -0.5);
}

TEST(Args, HelpListsEveryOption) {
    std::string a;
    bool f = false;
    ArgParser p("replay", "--model M", "Replays.");
    p.option("--model", "MODEL.pmsc", "the model", a, true);
    p.flag("--quiet", "no progress", f);
    const std::string help = p.help();
    EXPECT_NE(help.find("usage: pmsc replay --model M"), std::string::npos);
    EXPECT_NE(help.find("--model MODEL.pmsc"), std::string::npos);
    EXPECT_NE(help.find("the model (required)"), std::string::npos);
    EXPECT_NE(help.find("--quiet"), std::string::npos);
    EXPECT_NE(help.find("--help"), std::string::npos);
}

/// A `train`-like parser over `o`, for the --config tests.
struct ConfigCase {
    std::vector<std::string> frames;
    std::string out;
    double tolerance = 0;
    bool quiet = false;
    ArgParser parser{"train", "", ""};
    ConfigCase() {
        parser.option(
            "--frames", "F", "f", [this](const std::string& v) { frames.push_back(v); }, true);
        parser.repeatable("--frames");
        parser.option("--out", "F", "o", out, true);
        parser.option("--tolerance", "T", "t", [this](const std::string& v) {
            tolerance = pmsc::cli::parseDouble("--tolerance", v, 0);
        });
        parser.flag("--quiet", "q", quiet);
    }
};

std::string writeFile(const pmsc::test::TempDir& dir, const std::string& name, const std::string& text) {
    const std::string path = (dir.path() / name).string();
    std::ofstream(path) << text;
    return path;
}

TEST(ArgsConfig, TopLevelAndTheCommandsSectionApplyOtherSectionsAreLeftToTheirCommands) {
    pmsc::test::TempDir dir;
    const std::string toml =
        writeFile(dir, "job.toml",
                  "quiet = true\n[train]\nframes = [\"a.npy\", \"b.npy\"]\ntolerance = 0.02\n"
                  "[run]\nmodel = \"m.pmsc\"\n");
    ConfigCase c;
    ASSERT_TRUE(c.parser.parse({"--config", toml, "--out", "m.pmsc"}));
    EXPECT_EQ(c.frames, (std::vector<std::string>{"a.npy", "b.npy"}));
    EXPECT_EQ(c.out, "m.pmsc");
    EXPECT_DOUBLE_EQ(c.tolerance, 0.02);
    EXPECT_TRUE(c.quiet);
}

TEST(ArgsConfig, TheCommandLineWinsOptionByOption) {
    pmsc::test::TempDir dir;
    const std::string toml = writeFile(
        dir, "job.toml", "[train]\nframes = [\"a.npy\", \"b.npy\"]\nout = \"file.pmsc\"\ntolerance = 0.02\n");
    ConfigCase c;
    ASSERT_TRUE(c.parser.parse({"--frames", "c.npy", "--config=" + toml, "--tolerance", "0.5"}));
    EXPECT_EQ(c.frames, (std::vector<std::string>{"c.npy"}));  // the list is replaced, not appended to
    EXPECT_EQ(c.out, "file.pmsc");
    EXPECT_DOUBLE_EQ(c.tolerance, 0.5);
}

TEST(ArgsConfig, AnIniFileReadsTheSame) {
    pmsc::test::TempDir dir;
    const std::string ini =
        writeFile(dir, "job.ini", "; a farm job\n[train]\nframes = a.npy\nout = m.pmsc\nquiet = true\n");
    ConfigCase c;
    ASSERT_TRUE(c.parser.parse({"--config", ini}));
    EXPECT_EQ(c.frames, (std::vector<std::string>{"a.npy"}));
    EXPECT_TRUE(c.quiet);
}

TEST(ArgsConfig, EveryMistakeInTheFileIsOneLineNamingTheFileAndTheKey) {
    pmsc::test::TempDir dir;
    const auto message = [&](const std::string& text) {
        const std::string path = writeFile(dir, "bad.toml", text);
        ConfigCase c;
        return usageMessage(c.parser, {"--config", path, "--frames", "a.npy", "--out", "m.pmsc"});
    };
    const std::string bad = (dir.path() / "bad.toml").string();
    EXPECT_EQ(
        message("tolerence = 0.1\n"),
        "train: --config " + bad + ": 'tolerence' is not an option of pmsc train (see 'pmsc train --help')");
    EXPECT_EQ(message("quiet = maybe\n"),
              "train: --config " + bad + ": quiet is a flag: true or false (see 'pmsc train --help')");
    EXPECT_EQ(message("tolerance = [1, 2]\n"),
              "train: --config " + bad + ": tolerance takes one value, got 2 (see 'pmsc train --help')");
    EXPECT_EQ(message("tolerance = \"ten\"\n"),
              "train: --tolerance: 'ten' is not a number (see 'pmsc train --help')");
    EXPECT_EQ(
        message("config = \"other.toml\"\n"),
        "train: --config " + bad + ": 'config' is not an option of pmsc train (see 'pmsc train --help')");
    ConfigCase c;
    const std::string missing = (dir.path() / "missing.toml").string();
    EXPECT_NE(usageMessage(c.parser, {"--config", missing}).find("--config " + missing + ": "),
              std::string::npos);
    ConfigCase twice;
    EXPECT_EQ(usageMessage(twice.parser, {"--config", "a.toml", "--config", "b.toml"}),
              "train: --config given twice (see 'pmsc train --help')");
    ConfigCase noValue;
    EXPECT_EQ(usageMessage(noValue.parser, {"--config"}),
              "train: missing value for --config (see 'pmsc train --help')");
}

}  // namespace
