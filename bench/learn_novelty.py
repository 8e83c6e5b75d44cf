#!/usr/bin/env python3
"""`pmsc learn` on a take whose second half moves what its first half left still, against
retraining from scratch on both halves.

Each split is four ICT controls and a seed: the first half is frames 0-299 of take SEED with the
four held at 0 (`pmsc_ict_frames --without`), the second half frames 300-599 of the same take with
them free; the test take is 200 frames of seed SEED + 1, every control free. `pmsc train
--tolerance T` (1% of the head diagonal) on the first half, `pmsc learn` with the second, and
`pmsc train` on both halves, each with its defaults; both models replayed on the test take. The
table gives M, the p99.5 over frames of PM's largest point error and of the soft-cached error
(learned / scratch), hits, frames over T, and the wall times of `pmsc learn` and of the scratch
`pmsc train` (one run each). docs/results/learning.md has the figures.

    /usr/bin/python3 bench/learn_novelty.py --data ICT-FaceKit/FaceXModel --bin build/bin \\
        --work /tmp/learn-novelty

Needs numpy (the system python3). Exits 2 with one line on bad arguments or a failed command, 77
when the face folder is missing and CI is not set (a skip; under CI it is exit 2), and 1 when any
replayed frame comes back over T.
"""
import argparse
import json
import os
import sys
import time

from suite_common import add_clean_argument, discard, fail, require_folder, run

SPLITS = [
    (1, "mouthPucker,cheekPuff_L,jawLeft,eyeWide_R"),
    (9, "mouthSmile_L,browDown_R,mouthShrugUpper,jawRight"),
]


def ict(args, out, frames, seed, without=None):
    if not os.path.exists(out):
        cmd = [os.path.join(args.bin, "pmsc_ict_frames"), "--data", args.data, "--out", out, "--frames",
               str(frames), "--seed", str(seed), "--dtype", "float32"]
        run(cmd + (["--without", without] if without else []))
    return out


def timed(cmd):
    start = time.monotonic()
    run(cmd)
    return time.monotonic() - start


def replay(args, model, take, tolerance):
    report = model + ".json"
    run([os.path.join(args.bin, "pmsc"), "replay", "--model", model, "--frames", take, "--report", report,
         "--quiet"])
    with open(report) as f:
        r = json.load(f)
    s = r["summary"]
    return {"pm": s["pm_max_point_error"]["p995"], "soft": s["soft_max_point_error"]["p995"],
            "hit": s["hit_rate"], "M": s["basis"],
            "over": sum(1 for f in r["frames"] if f["soft_max_point_error"] > tolerance)}


def measure(args, np, seed, controls, tolerance):
    w = lambda name: os.path.join(args.work, "s%d-%s" % (seed, name))
    held = np.load(ict(args, w("held.npy"), 600, seed, controls), mmap_mode="r")
    free = np.load(ict(args, w("free.npy"), 600, seed), mmap_mode="r")
    test = ict(args, w("test.npy"), 200, seed + 1)
    if not os.path.exists(w("union.npy")):
        np.save(w("first.npy"), held[:300])
        np.save(w("second.npy"), free[300:])
        np.save(w("union.npy"), np.concatenate([held[:300], free[300:]]))
    pmsc = os.path.join(args.bin, "pmsc")
    t = ["--tolerance", "%.6g" % tolerance, "--quiet"]
    run([pmsc, "train", "--frames", w("first.npy"), "--out", w("day1.pmsc")] + t)
    learn_s = timed([pmsc, "learn", "--model", w("day1.pmsc"), "--frames", w("second.npy"), "--out",
                     w("learned.pmsc"), "--quiet"])
    scratch_s = timed([pmsc, "train", "--frames", w("union.npy"), "--out", w("scratch.pmsc")] + t)
    result = (replay(args, w("learned.pmsc"), test, tolerance), replay(args, w("scratch.pmsc"), test, tolerance),
              learn_s, scratch_s)
    del held, free
    discard(args, [w(name) for name in ("held.npy", "free.npy", "test.npy", "first.npy", "second.npy", "union.npy",
                                         "day1.pmsc", "learned.pmsc", "scratch.pmsc")])
    return result


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", required=True, help="ICT-FaceKit's FaceXModel folder")
    p.add_argument("--bin", default="build/bin", help="folder of pmsc and pmsc_ict_frames")
    p.add_argument("--work", required=True, help="folder for frames, models and reports (reused)")
    p.add_argument("--tolerance-percent", type=float, default=1.0, help="T in %% of the head diagonal")
    add_clean_argument(p)
    args = p.parse_args()
    try:
        import numpy as np
    except ImportError:
        fail("needs numpy (run it with the system python3)")
    require_folder(args.data)
    os.makedirs(args.work, exist_ok=True)
    out = run([os.path.join(args.bin, "pmsc_ict_frames"), "--data", args.data, "--out",
               os.path.join(args.work, "part.npy"), "--frames", "1", "--seed", "0"])
    tolerance = args.tolerance_percent / 100 * float(out.split("head bounding-box diagonal ")[1].split()[0])
    print("| split | M learned / scratch | PM p99.5 learned / scratch (ratio) | soft-cached p99.5 (ratio) | "
          "hits learned / scratch | over T | learn / scratch time |")
    print("|---|---|---|---|---|---|---|")
    any_over = False
    for seed, controls in SPLITS:
        l, s, learn_s, scratch_s = measure(args, np, seed, controls, tolerance)
        any_over = any_over or l["over"] > 0 or s["over"] > 0
        print("| seed %d, %s | %d / %d | %.4f / %.4f (%.2fx) | %.4f / %.4f (%.2fx) | %.1f%% / %.1f%% | %d / %d | "
              "%.1f s / %.1f s |" % (seed, controls.replace(",", ", "), l["M"], s["M"], l["pm"], s["pm"],
                                      l["pm"] / s["pm"], l["soft"], s["soft"], l["soft"] / s["soft"],
                                      100 * l["hit"], 100 * s["hit"], l["over"], s["over"], learn_s, scratch_s),
              flush=True)
    return 1 if any_over else 0


if __name__ == "__main__":
    sys.exit(main())
