// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>

namespace pmsc::app {

/// How a front end spells an option in its messages: `--region-keys` on the command line,
/// `region_keys` in Python. The rules are written once, with the command line's names.
enum class Spelling { CommandLine, Python };

/// "region-keys" -> "--region-keys" or "region_keys".
std::string optionName(std::string_view name, Spelling spelling);

/// An option, or a combination of options, that training cannot take. A std::invalid_argument:
/// exit code 2 on the command line, ValueError in Python.
struct OptionError : std::invalid_argument {
    using std::invalid_argument::invalid_argument;
};

}  // namespace pmsc::app
