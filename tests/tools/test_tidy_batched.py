#!/usr/bin/env python3
"""tools/tidy_batched.py keeps every diagnostic clang-tidy gives file by file.

Three small files share one target's flags: a.cpp and b.cpp define the same helper in their
anonymous namespaces (they share a batch, where b.cpp's is the redefinition), c.cpp goes to a batch
of its own. Each file and a header they all include hold a use after move. The batched run must report all three and fail; with the
faults removed it must pass. Bad arguments give one line and exit code 2.
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
TOOL = os.path.join(HERE, "..", "..", "tools", "tidy_batched.py")
TIDY = "clang-tidy-14"
CONFIG = """Checks: '-*,bugprone-use-after-move'
WarningsAsErrors: '*'
HeaderFilterRegex: '(^|/)lib/[^/]+\\.h$'
"""
MOVE = "inline std::string {name}(std::string s) {{ std::string t = std::move(s); return s + t; }}\n"
FILES = {
    "lib/shared.h": "#pragma once\n#include <string>\n#include <utility>\n",
    "src/a.cpp": '#include "lib/shared.h"\nnamespace { int helper() { return 1; } }\nint a() { return helper(); }\n',
    "src/b.cpp": '#include "lib/shared.h"\nnamespace { int helper() { return 2; } }\nint b() { return helper(); }\n',
    "src/c.cpp": '#include "lib/shared.h"\nint c() { return 3; }\n',
}


# Under CI (set to anything but "", "false" or "0", as every pmsc test reads it) a missing clang-tidy fails.
@unittest.skipIf(shutil.which(TIDY) is None and os.environ.get("CI", "") in ("", "false", "0"),
                 TIDY + " is not installed")
class TidyBatched(unittest.TestCase):
    def setUp(self):
        self.root = tempfile.mkdtemp(prefix="pmsc-tidy-")
        self.addCleanup(shutil.rmtree, self.root)
        for name, text in FILES.items():
            self.write(name, text)
        self.write(".clang-tidy", CONFIG)
        self.sources = [os.path.join(self.root, "src", n) for n in ("a.cpp", "b.cpp", "c.cpp")]
        db = [{"directory": self.root, "file": f,
               "command": "/usr/bin/c++ -I%s -std=c++20 -c %s -o %s.o" % (self.root, f, f)} for f in self.sources]
        self.write("build/compile_commands.json", json.dumps(db))

    def write(self, name, text, mode="w"):
        path = os.path.join(self.root, name)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, mode) as f:
            f.write(text)

    def run_tool(self, *extra):
        return subprocess.run([sys.executable, TOOL, "--build", os.path.join(self.root, "build"), "--jobs", "2",
                               "--clang-tidy", TIDY, "--config", os.path.join(self.root, ".clang-tidy"), *extra],
                              capture_output=True, text=True, cwd=self.root)

    def test_clean_files_pass_though_two_of_them_clash_in_a_batch(self):
        proc = self.run_tool(*self.sources)
        self.assertEqual(proc.returncode, 0, proc.stdout + proc.stderr)

    def test_every_fault_is_reported_in_clashing_and_other_files_and_headers(self):
        for name in ("a", "b", "c"):
            self.write("src/%s.cpp" % name, MOVE.format(name="in_" + name), "a")
        with open(os.path.join(self.root, "lib/shared.h"), "a") as f:
            f.write(MOVE.format(name="inHeader"))
        proc = self.run_tool(*self.sources)
        self.assertEqual(proc.returncode, 1, proc.stdout + proc.stderr)
        # a.cpp from the batch that clashed, b.cpp from its second run, c.cpp from the other batch.
        for where in ("src/a.cpp:4:", "src/b.cpp:4:", "src/c.cpp:3:", "lib/shared.h:4:"):
            self.assertRegex(proc.stdout, r"%s\d+: error: 's' used after it was moved" % where)
        self.assertNotIn("redefinition", proc.stdout)

    def test_bad_arguments_are_one_line_and_exit_code_2(self):
        cases = [(["--build", os.path.join(self.root, "nowhere"), self.sources[0]], "cannot read"),
                 ([os.path.join(self.root, "src", "missing.cpp")], "no such file")]
        for args, message in cases:
            if args[0] == "--build":
                proc = subprocess.run([sys.executable, TOOL, "--config", os.path.join(self.root, ".clang-tidy"), *args],
                                      capture_output=True, text=True)
            else:
                proc = self.run_tool(*args)
            self.assertEqual(proc.returncode, 2, proc.stderr)
            self.assertIn(message, proc.stderr)
            self.assertEqual(len(proc.stderr.strip().splitlines()), 1, proc.stderr)


if __name__ == "__main__":
    unittest.main()
