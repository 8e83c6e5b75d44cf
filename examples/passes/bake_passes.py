#!/usr/bin/env python3
"""Drive `pmsc reconstruct` pass by pass, the way a renderer that bakes values at given points would.

The "renderer" here reads the values it is asked for from recorded full frames (a shot already
computed), so the result can be checked against `pmsc replay` on the same frames; a studio's
bake script has the same loop with its renderer in place of `recorded[frame, points]`:

  1. bake every frame at the model's key points (`pmsc inspect MODEL --json`: key_indices);
  2. run `pmsc reconstruct` with the keys and every answer so far;
  3. if the report says a frame `needs` points, bake those, save them as the next answer, go to 2.

Usage:
  python3 examples/passes/bake_passes.py --pmsc build/bin/pmsc --model M.pmsc --frames SHOT.npy \
      --work DIR [--compare-replay] [-- extra pmsc reconstruct options]

Prints the number of passes, the share of points baked beyond the keys, and with --compare-replay
whether OUT.npy and the states equal `pmsc replay`'s. Exit code 0 on success, 1 if the comparison
fails, 2 for bad input (one line on stderr). Needs numpy.
"""

import argparse
import json
import os
import subprocess
import sys

import numpy as np


def run(cmd):
    """Runs a pmsc command; its one error line becomes this script's."""
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.stderr.write(r.stderr if r.stderr.endswith("\n") else r.stderr + "\n")
        sys.exit(r.returncode)
    return r.stdout


def bake(recorded, report):
    """The renderer: values at the points each frame needs; NaN where nothing was asked."""
    answer = np.full(recorded.shape, np.nan, dtype=recorded.dtype)
    for row in report["frames"]:
        if row["needs"]:
            answer[row["frame"], row["needs"], :] = recorded[row["frame"], row["needs"], :]
    return answer


def fail(message):
    """Bad input: one line on stderr, exit code 2."""
    sys.stderr.write(f"bake_passes.py: {message}\n")
    sys.exit(2)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pmsc", required=True, help="the pmsc program")
    parser.add_argument("--model", required=True)
    parser.add_argument("--frames", required=True, help="recorded full frames (frames, points, channels)")
    parser.add_argument("--work", required=True, help="folder for keys, answers, output and reports")
    parser.add_argument("--compare-replay", action="store_true")
    parser.add_argument("extra", nargs="*", help="options passed on to pmsc reconstruct and replay")
    a = parser.parse_args()
    try:
        recorded = np.load(a.frames, mmap_mode="r")
    except (OSError, ValueError) as e:
        fail(f"{a.frames}: {e}")
    if recorded.ndim != 3:
        fail(f"{a.frames}: shape {recorded.shape}, expected (frames, points, channels)")
    os.makedirs(a.work, exist_ok=True)
    model = json.loads(run([a.pmsc, "inspect", a.model, "--json"]))
    keys_path = os.path.join(a.work, "keys.npy")
    np.save(keys_path, np.ascontiguousarray(recorded[:, model["key_indices"], :]))

    out, report_path, answers = os.path.join(a.work, "out.npy"), os.path.join(a.work, "passes.json"), []
    baked = 0
    while True:
        cmd = [a.pmsc, "reconstruct", "--model", a.model, "--keys", keys_path, "--out", out,
               "--report", report_path] + a.extra
        for path in answers:
            cmd += ["--full", path]
        run(cmd)
        with open(report_path) as f:
            report = json.load(f)
        if report["summary"]["complete"]:
            break
        answers.append(os.path.join(a.work, f"answer{len(answers) + 1}.npy"))
        baked += report["summary"]["points_needed"]
        np.save(answers[-1], bake(recorded, report))

    frames, points = recorded.shape[0], recorded.shape[1]
    s = report["summary"]
    print(f"passes beyond the keys: {len(answers)}")
    print(f"hit / blend / miss: {s['hit_rate']:.1%} / {s['blend_rate']:.1%} / {s['miss_rate']:.1%}")
    print(f"points baked: keys {s['key_fraction']:.2%} of every frame, beyond the keys "
          f"{baked / (frames * points):.2%} of all points of all frames")
    if not a.compare_replay:
        return 0
    replay_out, replay_report = os.path.join(a.work, "replay.npy"), os.path.join(a.work, "replay.json")
    run([a.pmsc, "replay", "--model", a.model, "--frames", a.frames, "--out", replay_out,
         "--report", replay_report, "--quiet"] + a.extra)
    with open(replay_report) as f:
        replay = json.load(f)
    same_bytes = open(out, "rb").read() == open(replay_out, "rb").read()
    same_states = [r["state"] for r in replay["frames"]] == [r["state"] for r in report["frames"]]
    print(f"output equals pmsc replay's byte for byte: {same_bytes}; states equal: {same_states}")
    return 0 if same_bytes and same_states else 1


if __name__ == "__main__":
    sys.exit(main())
