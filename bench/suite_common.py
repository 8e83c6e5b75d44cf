"""What the novelty suites share (bench/novelty_suite.py, light_novelty.py, mocap_suite.py,
learn_novelty.py): one-line failures, running pmsc's commands, --variant and --clean, and a replay
report's summary against the tolerance."""
import json
import os
import subprocess
import sys


def fail(message):
    """One line naming the suite, exit 2."""
    print(os.path.splitext(os.path.basename(sys.argv[0]))[0] + ": " + message, file=sys.stderr)
    sys.exit(2)


def under_ci():
    """CI is set to anything but "", "false" or "0" (the rule of tests/common/MissingData.h)."""
    return os.environ.get("CI", "") not in ("", "false", "0")


def skip_or_fail(message):
    """What a suite does without data it needs: exit 77 (a skip) unless under CI, then fail() (a
    test that needs data it cannot find fails under CI)."""
    if not under_ci():
        print(os.path.splitext(os.path.basename(sys.argv[0]))[0] + ": " + message + ": skipped", file=sys.stderr)
        sys.exit(77)
    fail(message)


def require_folder(path):
    """A data folder the suite reads: when it is missing, exit 77 (a skip) unless CI is set, then
    fail() (a test that needs data it cannot find fails under CI)."""
    if not os.path.isdir(path):
        skip_or_fail("no folder " + path)


def add_variant_arguments(parser):
    """--variant (pmsc train options of a model beside the defaults, repeatable) and --no-variants,
    as the face and motion-capture suites take them; models_of() reads them."""
    parser.add_argument("--variant", action="append", default=None,
                        help="pmsc train options of a model beside the defaults (repeatable; "
                             "default: '--energy 0.99999')")
    parser.add_argument("--no-variants", action="store_true", help="the defaults alone")


def add_clean_argument(parser):
    """--clean: discard() deletes what a set made once its rows are printed."""
    parser.add_argument("--clean", action="store_true",
                        help="delete each set's frames and models once its rows are printed (the reports stay), "
                             "so the suite holds one set on disk at a time; without it the work folder is reused")


def discard(args, paths):
    """With --clean, delete the files named (frames, models) that exist; the reports stay."""
    if not args.clean:
        return
    for path in paths:
        if os.path.exists(path):
            os.remove(path)


def models_of(args):
    """The pmsc train options of each model add_variant_arguments() asked for, the defaults ("") first."""
    if args.no_variants:
        return [""]
    return [""] + (args.variant if args.variant is not None else ["--energy 0.99999"])


def run(cmd):
    """A command's output; fail() with its last lines when it exits non-zero."""
    done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if done.returncode != 0:
        fail("'" + " ".join(cmd) + "' exited " + str(done.returncode) + ": " + done.stdout.strip()[-400:])
    return done.stdout


def summarise(report_path, tolerance):
    """A `pmsc replay --report` against T: hits, frames over T (whatever their route; whole-frame hits
    and local frames among them), the worst frame over T, the share of points computed in full."""
    with open(report_path) as f:
        frames = json.load(f)["frames"]
    over = [f for f in frames if f["soft_max_point_error"] > tolerance]
    return {
        "frames": len(frames),
        "hits": sum(1 for f in frames if f["state"] == "hit"),
        "over": len(over),
        "over_hits": sum(1 for f in over if f["state"] == "hit"),
        "over_local": sum(1 for f in over if f.get("local")),
        "worst": max(f["soft_max_point_error"] for f in frames) / tolerance,
        "evaluated": sum(f.get("points_evaluated_fraction", 1.0 if f["state"] != "hit" else 0.0)
                         for f in frames) / len(frames),
    }
