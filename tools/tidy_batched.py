#!/usr/bin/env python3
"""clang-tidy on many translation units, several of them at once in one batch.

    tools/tidy_batched.py --build BUILD [--jobs J] [--clang-tidy EXE] FILE.cpp ...

Why: clang-tidy's matchers walk every declaration a translation unit parses, Eigen's and the
standard library's as well as the file's own, and on this code base that walk is most of its
time (pmsc/Training.cpp: 3.5 s to parse, 14 s in all). Files of one target share their flags and
most of their headers, so one translation unit that includes all of them (what CMake's unity
builds do) pays for the headers once: the 36 files of pmsc/ take 22 s instead of about 6 minutes.
The files' own code is checked as before: the header filter keeps .clang-tidy's headers and names
each batch's files exactly.

Two files of one batch may define the same name in their anonymous namespaces (a helper `bad` in
two readers). Clang reports the redefinition and goes on, so the rest of the batch is checked;
the files it names are checked again in a batch of their own (and again, until none clashes).
A file that fails alone fails the check (the build compiles it, so it is a clang-only error worth
seeing).

A build in unity batches (PMSC_UNITY_BUILD) lists its batches, not its files, in
compile_commands.json: each file a batch includes is checked with its batch's command.

Exit status: 0 when every batch is clean, 1 on any warning or error (the config makes every
warning an error), 2 on bad arguments.
"""
import argparse
import collections
import concurrent.futures
import json
import os
import re
import shlex
import subprocess
import sys

REDEFINITION = re.compile(r"^(/[^:]+\.cpp):\d+:\d+: error: (redefinition|conflicting declaration|"
                          r"reference to '[^']+' is ambiguous|call to '[^']+' is ambiguous)")


def compile_key(entry):
    """The entry's command without its source and object: files with equal keys share a batch."""
    args = shlex.split(entry["command"]) if "command" in entry else list(entry["arguments"])
    if os.path.basename(args[0]) == "ccache":
        args = args[1:]
    out, skip = [], False
    for a in args:
        if skip:
            skip = False
            continue
        if a == "-o":
            skip = True
            continue
        if a in ("-c", entry["file"]):
            continue
        out.append(a)
    return entry["directory"], tuple(out)


UNITY_SOURCE = re.compile(r"/Unity/unity_\d+_(c|cxx)\.(c|cxx)$")
UNITY_INCLUDE = re.compile(r'^#include "(/[^"]+)"\s*$')


def with_unity_sources(database):
    """`database` plus one entry per file a CMake unity batch includes, with the batch's command."""
    expanded = list(database)
    for entry in database:
        if not UNITY_SOURCE.search(entry["file"]):
            continue
        try:
            with open(entry["file"]) as f:
                sources = [m.group(1) for m in map(UNITY_INCLUDE.match, f) if m]
        except OSError:
            continue  # a batch not generated yet: its files are checked alone
        for source in sources:
            copy = dict(entry, file=source)
            if "command" in copy:
                copy["command"] = copy["command"].replace(entry["file"], source)
            else:
                copy["arguments"] = [source if a == entry["file"] else a for a in copy["arguments"]]
            expanded.append(copy)
    return expanded


def header_filter(config):
    """.clang-tidy's HeaderFilterRegex: the headers whose diagnostics count."""
    with open(config) as f:
        for line in f:
            m = re.match(r"^HeaderFilterRegex:\s*'(.*)'\s*$", line)
            if m:
                return m.group(1)
    raise ValueError("%s has no HeaderFilterRegex" % config)


def run_batch(tidy, build, workdir, index, key, files, headers):
    """clang-tidy on one translation unit that includes `files`; returns (status, output, clashing files)."""
    directory, args = key
    if directory is None:  # a file the build does not compile: alone, with the build's database
        proc = subprocess.run([tidy, "-p", build, "-quiet", files[0]], capture_output=True, text=True)
        return proc.returncode, proc.stdout + proc.stderr, []
    unity = os.path.join(workdir, "batch_%d.cpp" % index)
    with open(unity, "w") as f:
        f.write("".join('#include "%s"\n' % path for path in files))
    db = os.path.join(workdir, "batch_%d" % index)
    os.makedirs(db, exist_ok=True)
    command = " ".join(shlex.quote(a) for a in args) + " -c %s -o %s.o" % (shlex.quote(unity), unity)
    with open(os.path.join(db, "compile_commands.json"), "w") as f:
        json.dump([{"directory": directory, "file": unity, "command": command}], f)
    # The batch's own files count as the main file would: the header filter names them exactly.
    keep = "|".join([headers] + ["^%s$" % re.sub(r"([.^$*+?()\[\]{}|\\])", r"\\\1", path) for path in files])
    # bugprone-suspicious-include would flag the batch's own includes of .cpp files; the files
    # themselves include none (the build would not link them twice).
    proc = subprocess.run([tidy, "-p", db, "-quiet", "--checks=-bugprone-suspicious-include",
                           "--header-filter=" + keep, unity],
                          capture_output=True, text=True)
    output = proc.stdout + proc.stderr
    clashing = sorted({m.group(1) for m in map(REDEFINITION.match, output.splitlines()) if m} & set(files))
    return proc.returncode, output, clashing


def without_files(output, files):
    """`output` without the diagnostics located in `files` (each with its source lines and notes)."""
    kept, skipping = [], False
    for line in output.splitlines(keepends=True):
        m = re.match(r"^(/[^:]+):\d+:\d+: (warning|error|note): ", line)
        if m and m.group(2) != "note":
            skipping = m.group(1) in files
        if not skipping:
            kept.append(line)
    return "".join(kept)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--build", required=True, help="build folder with compile_commands.json")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--clang-tidy", default="clang-tidy-14")
    parser.add_argument("--batch", type=int, default=16, help="files in one translation unit at most")
    parser.add_argument("--config", default=".clang-tidy", help="its HeaderFilterRegex is kept")
    parser.add_argument("files", nargs="+")
    opts = parser.parse_args()

    db_path = os.path.join(opts.build, "compile_commands.json")
    try:
        with open(db_path) as f:
            database = json.load(f)
    except (OSError, ValueError) as e:
        print("tidy_batched.py: cannot read %s: %s" % (db_path, e), file=sys.stderr)
        return 2
    try:
        headers = header_filter(opts.config)
    except (OSError, ValueError) as e:
        print("tidy_batched.py: %s" % e, file=sys.stderr)
        return 2
    by_file = {os.path.realpath(e["file"]): e for e in with_unity_sources(database)}
    groups = collections.defaultdict(list)
    for name in opts.files:
        path = os.path.realpath(name)
        if not os.path.isfile(path):
            print("tidy_batched.py: no such file: %s" % name, file=sys.stderr)
            return 2
        # A file this configuration does not build (cli/mpi/NoMpi.cpp beside MPI) is checked
        # alone, with the flags clang-tidy infers from its neighbours, as run-clang-tidy would.
        groups[compile_key(by_file[path]) if path in by_file else (None, path)].append(path)

    workdir = os.path.join(os.path.realpath(opts.build), "tidy-batches")
    os.makedirs(workdir, exist_ok=True)
    # A group's files in as many batches as there are jobs, at most BATCH files each.
    pending = []
    for key, files in groups.items():
        size = min(opts.batch, -(-len(files) // opts.jobs))
        pending += [(key, files[i:i + size]) for i in range(0, len(files), size)]
    failed, counter = False, 0
    with concurrent.futures.ThreadPoolExecutor(max_workers=opts.jobs) as pool:
        while pending:
            futures = []
            for key, files in pending:
                futures.append((key, files, pool.submit(run_batch, opts.clang_tidy, opts.build, workdir, counter, key, files, headers)))
                counter += 1
            pending = []
            for key, files, future in futures:
                code, output, clashing = future.result()
                if clashing and len(clashing) == len(files):
                    clashing = files[len(files) // 2:]  # cannot happen with one file: it would not clash
                if clashing:
                    # The rest of the batch was checked (clang recovers from a redefinition); the
                    # clashing files are checked again in a batch of their own.
                    pending.append((key, clashing))
                    output = without_files(output, clashing)
                    code = 0
                diagnostics = [line for line in output.splitlines() if ": warning: " in line or ": error: " in line]
                if code != 0 or diagnostics:
                    failed = True
                    sys.stdout.write(output)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
