// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/FarmFrames.h"
#include "pmsc/FrameSet.h"
#include "pmsc/NpyIO.h"

#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace pmsc::cli {

/// A mistake on the command line (unknown option, missing or malformed value).
/// Derives from std::invalid_argument, which main() maps to exit code 2.
struct UsageError : std::invalid_argument {
    using std::invalid_argument::invalid_argument;
};

/// The small argument parser every subcommand shares: `--name VALUE`,
/// `--name=VALUE`, flags, positionals, `--help`, and `--config FILE` (the options from a TOML or
/// INI file, read by CLI11; the command line wins). Every mistake becomes one
/// UsageError line naming the command and the option, e.g.
/// "train: --basis: 'ten' is not an integer (see 'pmsc train --help')".
class ArgParser {
public:
    /// @param command     the subcommand as typed ("train", "demo cornell")
    /// @param synopsis    one usage line without "pmsc <command>"
    /// @param description a short paragraph for --help
    ArgParser(std::string command, std::string synopsis, std::string description);

    /// An option with a value. `apply` converts and stores it; it may throw
    /// UsageError (the helpers below do) and the parser adds the command.
    void option(std::string name, std::string valueName, std::string help,
                std::function<void(const std::string&)> apply, bool required = false);
    /// A string option.
    void option(std::string name, std::string valueName, std::string help, std::string& target,
                bool required = false);
    /// Lets an option be given more than once (each value is applied in order), e.g. several
    /// `--frames` files.
    void repeatable(const std::string& name);
    /// A flag without value (--json).
    void flag(std::string name, std::string help, bool& target);
    /// A positional argument, in the order declared.
    void positional(std::string name, std::string help, std::string& target, bool required = true);

    /// Parses `args` (everything after the subcommand).
    /// @return false when --help was asked for (the help is then printed on stdout).
    /// @throws UsageError for an unknown option, a missing value or a missing required argument.
    bool parse(const std::vector<std::string>& args);

    /// True if the option (with its dashes, "--basis") was given.
    bool given(const std::string& name) const;

    /// Throws a UsageError for this command: "<command>: <what> (see 'pmsc <command> --help')".
    [[noreturn]] void fail(const std::string& what) const;

    /// The --help text.
    std::string help() const;
    const std::string& command() const { return command_; }

private:
    struct Option {
        std::string name, valueName, help;
        std::function<void(const std::string&)> apply;
        bool required = false;
        bool isFlag = false;
        bool positional = false;
        bool repeatable = false;
    };
    Option* find(const std::string& name);
    void applyValue(Option& o, const std::string& value);
    void applyConfig(const std::string& path);

    std::string command_, synopsis_, description_;
    std::vector<Option> options_;
    std::vector<std::string> given_;
};

/// Value converters for options; they throw UsageError("--name: ...").
/// An integer in [min, max], whole string, decimal.
Index parseIndex(const std::string& option, const std::string& text, Index min = 0,
                 Index max = std::numeric_limits<Index>::max());
/// A finite number in [min, max].
double parseDouble(const std::string& option, const std::string& text,
                   double min = -std::numeric_limits<double>::max(),
                   double max = std::numeric_limits<double>::max());
/// Comma-separated integers, each >= 0: "12,40,7".
std::vector<Index> parseIndexList(const std::string& option, const std::string& text);
/// Two comma-separated finite numbers "A,B".
std::pair<double, double> parseDoublePair(const std::string& option, const std::string& text);
/// An .npy element type: "float64" or "float32".
NpyDtype parseDtype(const std::string& option, const std::string& text);

/// Parses "A-B", "A-B:STEP" or a single frame "A" (A <= B, STEP >= 1, all >= 0).
/// @throws UsageError naming `option`.
app::FrameSpan parseFrameSpan(const std::string& option, const std::string& text);

}  // namespace pmsc::cli
