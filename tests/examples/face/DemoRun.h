// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// What the face demos' end-to-end tests share: a temporary folder removed whatever the test's
// outcome, the real `pmsc` program run in it with stdout and stderr to files, and a file's text.
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace pmsc::face::test {

/// A new folder under the temporary directory, removed with everything in it at the end.
struct DemoFolder {
    std::filesystem::path path;
    explicit DemoFolder(const std::string& prefix = "pmsc-face-demo") {
        std::string pattern = (std::filesystem::temp_directory_path() / (prefix + "-XXXXXX")).string();
        if (!::mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed");
        path = pattern;
    }
    ~DemoFolder() {
        std::error_code ignored;
        std::filesystem::remove_all(path, ignored);
    }
    DemoFolder(const DemoFolder&) = delete;
    DemoFolder& operator=(const DemoFolder&) = delete;
};

/// The whole of a file, "" if it cannot be read.
inline std::string slurp(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

/// Runs `pmsc ARGUMENTS` (PMSC_BINARY) with stdout and stderr to the folder's files; its exit code,
/// -1 if it did not exit.
inline int runPmsc(const std::string& arguments, const DemoFolder& folder) {
    const std::string command = std::string("'") + PMSC_BINARY + "' " + arguments + " >'" +
                                (folder.path / "stdout").string() + "' 2>'" +
                                (folder.path / "stderr").string() + "'";
    const int status = std::system(command.c_str());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace pmsc::face::test
