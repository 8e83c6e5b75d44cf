#include "cli/Args.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <iostream>
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

bool ArgParser::parse(const std::vector<std::string>& args) {
    std::size_t nextPositional = 0;
    const auto positionalAt = [&](std::size_t i) -> Option* {
        std::size_t seen = 0;
        for (auto& o : options_)
            if (o.positional && seen++ == i) return &o;
        return nullptr;
    };
    const auto apply = [&](Option& o, const std::string& value) {
        try {
            o.apply(value);
        } catch (const UsageError& e) {
            fail(e.what());
        }
        given_.push_back(o.name);
    };
    bool onlyPositionals = false;
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& arg = args[i];
        if (!onlyPositionals && (arg == "--help" || arg == "-h")) {
            std::cout << help();
            return false;
        }
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

}  // namespace pmsc::cli
