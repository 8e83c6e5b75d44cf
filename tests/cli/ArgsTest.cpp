#include "cli/Args.h"

#include <gtest/gtest.h>

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

}  // namespace
