// Runs the built `pmsc` program and captures what it did.
#pragma once

#include "tests/common/TempDir.h"

#include <cstdlib>
#include <string>
#include <vector>

#include <sys/wait.h>

namespace pmsc::test {

struct RunResult {
    int exitCode = -1;
    std::string out, err;
    /// stderr split into lines (without the newlines).
    std::vector<std::string> errLines() const {
        std::vector<std::string> lines;
        std::size_t start = 0;
        while (start < err.size()) {
            const auto nl = err.find('\n', start);
            lines.push_back(err.substr(start, nl - start));
            if (nl == std::string::npos) break;
            start = nl + 1;
        }
        return lines;
    }
};

inline std::string shellQuote(const std::string& s) {
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

/// Runs `<pmsc> args...` (each argument quoted) with stdout and stderr captured in files of `dir`.
/// `prefix` goes before the program (e.g. "timeout -s INT 0.3").
inline RunResult runPmsc(const TempDir& scratch, const std::vector<std::string>& args,
                         const std::string& prefix = "") {
    std::string command = prefix + (prefix.empty() ? "" : " ") + shellQuote(PMSC_BINARY);
    for (const auto& a : args) {  // appended in steps: GCC 12 warns falsely (-Wrestrict) on " " + string&&
        command += ' ';
        command += shellQuote(a);
    }
    const std::string out = scratch.file("stdout.txt"), err = scratch.file("stderr.txt");
    command += " >" + shellQuote(out) + " 2>" + shellQuote(err) + " </dev/null";
    const int status = std::system(command.c_str());
    RunResult r;
    r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    r.out = readBytes(out);
    r.err = readBytes(err);
    return r;
}

}  // namespace pmsc::test
