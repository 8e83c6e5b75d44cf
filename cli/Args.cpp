#include "cli/Args.h"

#include <CLI/Config.hpp>
#include <CLI/ConfigFwd.hpp>
#include <CLI/Error.hpp>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <regex>
#include <sstream>

namespace pmsc::cli {

ArgParser::ArgParser(std::string command, std::string synopsis, std::string description)
    : command_(std::move(command)), synopsis_(std::move(synopsis)), description_(std::move(description)) {}

void ArgParser::option(std::string name, std::string valueName, std::string help,
                       std::function<void(const std::string&)> apply, bool required) {
    options_.push_back({std::move(name), std::move(valueName), std::move(help), std::move(apply), required});
}

void ArgParser::option(std::string name, std::string valueName, std::string help, std::string& target,
                       bool required) {
    option(
        std::move(name), std::move(valueName), std::move(help),
        [&target](const std::string& v) { target = v; }, required);
}

void ArgParser::flag(std::string name, std::string help, bool& target) {
    Option o{std::move(name), "", std::move(help), [&target](const std::string&) { target = true; }};
    o.isFlag = true;
    options_.push_back(std::move(o));
}

void ArgParser::positional(std::string name, std::string help, std::string& target, bool required) {
    Option o{std::move(name), "", std::move(help), [&target](const std::string& v) { target = v; }, required};
    o.positional = true;
    options_.push_back(std::move(o));
}

void ArgParser::repeatable(const std::string& name) {
    if (Option* o = find(name)) o->repeatable = true;
}

ArgParser::Option* ArgParser::find(const std::string& name) {
    for (auto& o : options_)
        if (!o.positional && o.name == name) return &o;
    return nullptr;
}

void ArgParser::fail(const std::string& what) const {
    throw UsageError(command_ + ": " + what + " (see 'pmsc " + command_ + " --help')");
}

bool ArgParser::given(const std::string& name) const {
    for (const auto& g : given_)
        if (g == name) return true;
    return false;
}

namespace {

/// The value of --config in `args` (before any "--"), "" when not given; removes it from `args`.
std::string takeConfigPath(std::vector<std::string>& args, const ArgParser& parser) {
    std::string path;
    for (std::size_t i = 0; i < args.size(); ++i) {
        if (args[i] == "--") break;
        const bool inline_ = args[i].rfind("--config=", 0) == 0;
        if (args[i] != "--config" && !inline_) continue;
        if (!path.empty()) parser.fail("--config given twice");
        if (inline_) {
            path = args[i].substr(9);
            args.erase(args.begin() + static_cast<std::ptrdiff_t>(i));
        } else {
            if (i + 1 >= args.size()) parser.fail("missing value for --config");
            path = args[i + 1];
            args.erase(args.begin() + static_cast<std::ptrdiff_t>(i),
                       args.begin() + static_cast<std::ptrdiff_t>(i) + 2);
        }
        if (path.empty()) parser.fail("--config: empty file name");
        --i;
    }
    return path;
}

/// The items of a TOML file (or an INI file: .ini, .cfg, with ';' comments), read by CLI11.
std::vector<CLI::ConfigItem> readConfig(const std::string& path, const ArgParser& parser) {
    const auto dot = path.rfind('.');
    const std::string ext = dot == std::string::npos ? "" : path.substr(dot);
    try {
        if (ext == ".ini" || ext == ".cfg") return CLI::ConfigINI().from_file(path);
        return CLI::ConfigTOML().from_file(path);
    } catch (const CLI::Error& e) {
        parser.fail("--config " + path + ": " + e.what());
    }
}

}  // namespace

void ArgParser::applyConfig(const std::string& path) {
    // Decision: a farm job keeps its options in one file for every command it runs. Top-level keys
    // must be options of this command (a typo fails, as on the command line); a section named
    // after a command ([train], [run], [demo.cornell]) holds that command's own; other sections are
    // left to their commands. The command line wins over the file, option by option.
    std::string section = command_;
    for (char& c : section)
        if (c == ' ') c = '.';
    for (const CLI::ConfigItem& item : readConfig(path, *this)) {
        if (item.name == "++" || item.name == "--") continue;  // CLI11's marks of a section's start and end
        std::string parents;
        for (const auto& p : item.parents) parents += (parents.empty() ? "" : ".") + p;
        if (!parents.empty() && parents != section) continue;
        const std::string name = "--" + item.name;
        Option* o = find(name);
        if (!o || name == "--config")
            fail("--config " + path + ": '" + item.name + "' is not an option of pmsc " + command_);
        if (given(name)) continue;  // the command line's value
        if (o->isFlag) {
            if (item.inputs.size() != 1 || (item.inputs[0] != "true" && item.inputs[0] != "false"))
                fail("--config " + path + ": " + item.name + " is a flag: true or false");
            if (item.inputs[0] == "true") applyValue(*o, "");
            continue;
        }
        if (item.inputs.empty()) fail("--config " + path + ": " + item.name + " has no value");
        if (item.inputs.size() > 1 && !o->repeatable)
            fail("--config " + path + ": " + item.name + " takes one value, got " +
                 std::to_string(item.inputs.size()));
        for (const std::string& value : item.inputs) applyValue(*o, value);
    }
}

void ArgParser::applyValue(Option& o, const std::string& value) {
    try {
        o.apply(value);
    } catch (const UsageError& e) {
        fail(e.what());
    }
    given_.push_back(o.name);
}

bool ArgParser::parse(const std::vector<std::string>& commandLine) {
    for (const auto& arg : commandLine) {
        if (arg == "--") break;
        if (arg == "--help" || arg == "-h") {
            std::cout << help();
            return false;
        }
    }
    std::vector<std::string> args = commandLine;
    const std::string configPath = takeConfigPath(args, *this);
    std::size_t nextPositional = 0;
    const auto positionalAt = [&](std::size_t i) -> Option* {
        std::size_t seen = 0;
        for (auto& o : options_)
            if (o.positional && seen++ == i) return &o;
        return nullptr;
    };
    const auto apply = [&](Option& o, const std::string& value) { applyValue(o, value); };
    bool onlyPositionals = false;
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& arg = args[i];
        if (!onlyPositionals && arg == "--") {
            onlyPositionals = true;
            continue;
        }
        if (!onlyPositionals && arg.size() > 1 && arg[0] == '-' &&
            !(std::isdigit(static_cast<unsigned char>(arg[1])) || arg[1] == '.')) {
            const auto eq = arg.find('=');
            const std::string name = arg.substr(0, eq);
            Option* o = find(name);
            if (!o) fail("unknown option '" + name + "'");
            if (given(name) && !o->repeatable) fail(name + " given twice");
            if (o->isFlag) {
                if (eq != std::string::npos) fail(name + " takes no value");
                apply(*o, "");
                continue;
            }
            if (eq != std::string::npos) {
                apply(*o, arg.substr(eq + 1));
            } else {
                if (i + 1 >= args.size()) fail("missing value for " + name);
                apply(*o, args[++i]);
            }
            continue;
        }
        Option* p = positionalAt(nextPositional++);
        if (!p) fail("unexpected argument '" + arg + "'");
        apply(*p, arg);
    }
    if (!configPath.empty()) applyConfig(configPath);
    for (const auto& o : options_)
        if (o.required && !given(o.name)) fail("missing " + o.name);
    return true;
}

std::string ArgParser::help() const {
    std::ostringstream out;
    out << "usage: pmsc " << command_ << " " << synopsis_ << "\n\n" << description_ << "\n";
    std::size_t width = 6;
    const auto label = [](const Option& o) {
        return o.positional ? o.name : o.name + (o.isFlag ? "" : " " + o.valueName);
    };
    for (const auto& o : options_) width = std::max(width, label(o).size());
    out << "\noptions:\n";
    for (const auto& o : options_) {
        const std::string l = label(o);
        out << "  " << l << std::string(width - l.size() + 2, ' ') << o.help
            << (o.required ? " (required)" : "") << "\n";
    }
    out << "  --config FILE" << std::string(width > 13 ? width - 13 + 2 : 2, ' ')
        << "options from a TOML or INI file: name = value, without the dashes (flags true/false, lists\n"
        << std::string(width + 4, ' ') << "for repeated options); section [" << command_
        << "] or the top level; the command line wins\n";
    out << "  --help" << std::string(width - 6 + 2, ' ') << "this help\n";
    return out.str();
}

Index parseIndex(const std::string& option, const std::string& text, Index min, Index max) {
    errno = 0;
    char* end = nullptr;
    const long long v = std::strtoll(text.c_str(), &end, 10);
    if (text.empty() || end != text.c_str() + text.size() ||
        std::isspace(static_cast<unsigned char>(text[0])))
        throw UsageError(option + ": '" + text + "' is not an integer");
    if (errno == ERANGE || v < min || v > max) {
        std::string range = "at least " + std::to_string(min);
        if (max != std::numeric_limits<Index>::max())
            range = "in [" + std::to_string(min) + ", " + std::to_string(max) + "]";
        throw UsageError(option + ": " + text + " is out of range (must be " + range + ")");
    }
    return static_cast<Index>(v);
}

double parseDouble(const std::string& option, const std::string& text, double min, double max) {
    errno = 0;
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || end != text.c_str() + text.size() ||
        std::isspace(static_cast<unsigned char>(text[0])))
        throw UsageError(option + ": '" + text + "' is not a number");
    if (!std::isfinite(v)) throw UsageError(option + ": " + text + " is not a finite number");
    if (v < min || v > max) {
        std::ostringstream range;
        range << "in [" << min << ", " << max << "]";
        throw UsageError(option + ": " + text + " is out of range (must be " + range.str() + ")");
    }
    return v;
}

std::vector<Index> parseIndexList(const std::string& option, const std::string& text) {
    std::vector<Index> out;
    std::size_t start = 0;
    for (;;) {
        const auto comma = text.find(',', start);
        out.push_back(parseIndex(option, text.substr(start, comma - start)));
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    return out;
}

std::pair<double, double> parseDoublePair(const std::string& option, const std::string& text) {
    const auto comma = text.find(',');
    if (comma == std::string::npos || text.find(',', comma + 1) != std::string::npos)
        throw UsageError(option + ": '" + text + "' is not two numbers 'A,B'");
    return {parseDouble(option, text.substr(0, comma)), parseDouble(option, text.substr(comma + 1))};
}

NpyDtype parseDtype(const std::string& option, const std::string& text) {
    if (text == "float64") return NpyDtype::Float64;
    if (text == "float32") return NpyDtype::Float32;
    throw UsageError(option + ": expected float64 or float32, got '" + text + "'");
}

app::FrameSpan parseFrameSpan(const std::string& option, const std::string& text) {
    static const std::regex pattern(R"(^(\d+)(?:-(\d+))?(?::(\d+))?$)");
    std::smatch m;
    if (!std::regex_match(text, m, pattern))
        throw UsageError(option + ": expected FIRST-LAST[:STEP] (for example 0-99 or 0-99:2), got '" + text +
                         "'");
    app::FrameSpan s;
    s.first = parseIndex(option, m[1].str());
    s.last = m[2].matched ? parseIndex(option, m[2].str()) : s.first;
    s.step = m[3].matched ? parseIndex(option, m[3].str(), 1) : 1;
    if (s.last < s.first) throw UsageError(option + ": the range " + text + " ends before it starts");
    // Keep `last` on the grid, so count() and text() agree with what runs.
    s.last = s.first + (s.last - s.first) / s.step * s.step;
    return s;
}

}  // namespace pmsc::cli
